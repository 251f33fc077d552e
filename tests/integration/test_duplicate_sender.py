"""Issue 16, finding 10, as a user meets it: two `bench plant` processes on one bus, and `bench run` of a case with
a second VCU, each name the second sender once (the monitor's rules: tests/bench/sim/test_duplicate_sender.py)."""

from __future__ import annotations

import math
import subprocess
import sys
import threading
import time

import can
import pytest

from bench import canid
from bench.checks.monitor import Monitor
from bench.database.codec import Codebook
from tests.child import Child
from tests.fakes import ipv4_group
from tests.reference import COUNTER_VALUES
from tests.repo import ROOT

MESSAGE = "VCU_WheelCmd_FL"
CYCLE = 0.01   # s, VCU_WheelCmd_FL's GenMsgCycleTime (checked below)
M = COUNTER_VALUES       # Profile 11's counter: 0 ... 14
STREAM_FRAMES = M + 1    # docs/spec/e2e.md: two streams are two senders once each carried at least 16 frames


@pytest.mark.realtime
def test_two_plant_processes_on_udp_multicast(codebook: Codebook) -> None:
    """Two `bench plant` on one udp_multicast group (hop limit 0, loopback only): each says which
    identifiers have a second sender, and a listener's monitor (as `bench monitor` runs it) finds them by the
    counters alone."""
    group = ipv4_group()
    command = [sys.executable, "-m", "bench", "plant", "--interface", "udp_multicast", "--channel", group]
    listener = can.Bus(interface="udp_multicast", channel=group, receive_own_messages=False)
    watcher = Monitor(codebook)
    stop = threading.Event()

    def listen() -> None:
        t0 = time.monotonic()
        while not stop.is_set():
            msg = listener.recv(0.1)
            if msg is not None:
                watcher.on_frame(time.monotonic() - t0, canid.of_message(msg), bytes(msg.data), "rx")

    thread = threading.Thread(target=listen, daemon=True)
    thread.start()
    # The first sends from before the second starts until after it ends: the second's 4 s overlap it whatever
    # either's start-up takes (both ran 4 s from a 0.7 s head start before; under load they overlapped 0.16 s).
    first = Child([*command, "--duration", "120"], ROOT)
    try:
        first.wait_for("simulating", 60)
        second = subprocess.run([*command, "--duration", "4"], cwd=ROOT, capture_output=True, text=True, timeout=60)
    finally:
        first_output = first.stop()
        stop.set()
        thread.join(timeout=2)
        listener.shutdown()
    frame_id = codebook[MESSAGE].frame_id
    for output in (first_output, second.stdout + second.stderr):
        assert f"two senders of 0x{frame_id:03X} ({MESSAGE})" in output, output[-3000:]
        lines = [line for line in output.splitlines() if f"two senders of 0x{frame_id:03X}" in line]
        assert len(lines) == 1, "one line per message, not one per frame"
    assert frame_id in watcher.duplicates, watcher.invalid_log[:5]
    assert "interleaved" in watcher.duplicates[frame_id].describe()
    assert not math.isnan(watcher.duplicates[frame_id].t)


SECOND_VCU_CASE = '''
from bench.transport import VirtualTimeBus
from bench import canid
from bench.checks.monitor import Monitor
from bench.sim.restbus import Restbus
from bench.sim.station import Station


def test_a_second_vcu_joins(bench):
    """A second VCU on the bench's own virtual bus (a real ECU plugged in while its node is simulated)."""
    session = bench.session
    second = Station("vcu-2", VirtualTimeBus(channel=session.channel), Restbus(session.codebook, {"VCU"}),
                     Monitor(session.codebook), session.now)
    for slot in second.restbus.slots.values():
        slot.counter = 9
    bench.every(0.001, lambda t: second.tick(round(t / 0.001), t, 0.001))
    bench.run(1.0)
    second.bus.shutdown()
'''


def test_the_run_report_names_the_second_sender(tmp_path) -> None:
    """`bench run` of a case with a second VCU on the virtual bus: the report names
    "two senders of 0x110 (VCU_WheelCmd_FL)" once, first among the report's tables."""
    case = tmp_path / "cases" / "test_second_vcu.py"
    case.parent.mkdir()
    case.write_text(SECOND_VCU_CASE)
    out = tmp_path / "report"
    done = subprocess.run([sys.executable, "-m", "bench", "run", str(case), "--out", str(out)], cwd=ROOT,
                          capture_output=True, text=True, timeout=300)
    html = (out / "report.html").read_text()
    assert "Findings: two senders of one identifier" in html, done.stdout[-2000:] + done.stderr[-2000:]
    assert html.count("two senders of 0x110 (VCU_WheelCmd_FL)") == 1
    assert html.index("Findings: two senders") < html.index("Databases: the messages")
