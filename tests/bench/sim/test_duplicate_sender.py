"""Issue 16, finding 10: two senders of one identifier are one finding per message, with the identifier and
the evidence, not only thousands of "counter 0, expected 7" lines; one broken sender never is. In process: the
monitor, the station, the run's findings table and the screens; tests/integration/test_duplicate_sender.py runs
`bench plant` and `bench run` as processes."""

from __future__ import annotations

import random
import re

import pytest

from bench import e2e
from bench.checks.monitor import Monitor
from bench.database.codec import Codebook
from bench.faults.plan import FRAME_KINDS, Fault, FaultPlan
from bench.sim.restbus import Restbus
from tests.reference import COUNTER_VALUES

MESSAGE = "VCU_WheelCmd_FL"
CYCLE = 0.01   # s, VCU_WheelCmd_FL's GenMsgCycleTime (checked below)
M = COUNTER_VALUES       # Profile 11's counter: 0 ... 14
STREAM_FRAMES = M + 1    # docs/spec/e2e.md: two streams are two senders once each carried at least 16 frames


def _frame(codebook: Codebook, counter: int, angle: float = 5.0) -> bytes:
    """One frame of MESSAGE with the given counter, protected as the contract says (docs/spec/e2e.md)."""
    codec = codebook[MESSAGE]
    assert codec.protection is not None
    data = bytearray(codec.encode({**{s: 0.0 for s in codec.signal_names}, "SteerAngleCmd": angle}))
    codec.protection.protect(data, counter)
    return bytes(data)


def _feed(monitor: Monitor, codebook: Codebook, frames: list[tuple[float, int, float]]) -> None:
    frame_id = codebook[MESSAGE].frame_id
    for t, counter, angle in frames:
        monitor.on_frame(t, frame_id, _frame(codebook, counter, angle), "rx")


def test_cycle_of_the_message(codebook: Codebook) -> None:
    assert codebook[MESSAGE].cycle_time == pytest.approx(CYCLE)


@pytest.mark.parametrize("same_payload", [False, True], ids=["other values", "same values"])
@pytest.mark.parametrize("offset", range(M))
def test_two_interleaved_senders_are_one_finding(codebook: Codebook, offset: int, same_payload: bool) -> None:
    """Sender A alone, then B at the same rate half a cycle before each frame of A, its counter `offset` ahead
    of A's next (docs/spec/e2e.md, "two interleaved senders"): one finding naming 0x120 and both streams."""
    a = [(i * CYCLE, i % M, 5.0) for i in range(10)]
    both = []
    for i in range(40):
        t = (10 + i) * CYCLE
        both += [(t - CYCLE / 2, (10 + offset + i) % M, 5.0 if same_payload else -3.0), (t, (10 + i) % M, 5.0)]
    monitor = Monitor(codebook)
    _feed(monitor, codebook, a + both)
    frame_id = codebook[MESSAGE].frame_id
    assert list(monitor.duplicates) == [frame_id]
    found = monitor.duplicates[frame_id]
    text = found.describe()
    assert text.startswith(f"two senders of 0x{frame_id:03X} ({MESSAGE}): counters ")
    assert e2e.SenderTracker(CYCLE, M).frames_needed == STREAM_FRAMES
    assert found.t <= both[2 * STREAM_FRAMES][0], "shown once each stream carried 16 frames"
    streams = re.fullmatch(r".*counters ([\d,]+) and ([\d,]+) interleaved", text)
    assert streams, text
    for stream in streams.groups():          # each stream advances by 1
        counters = [int(c) for c in stream.split(",")]
        assert len(counters) >= 3 and all((b - a) % M == 1 for a, b in zip(counters, counters[1:])), text
    assert found.frames > 40, "the later frames count to the same finding"


def test_two_senders_at_different_rates(codebook: Codebook) -> None:
    """A every 10 ms, B every 30 ms (a real ECU of another variant): still two streams taking turns."""
    frames = [(i * CYCLE, i % M, 5.0) for i in range(100)] + [(0.1 + i * 0.03 + 0.003, (7 + i) % M, 1.0)
                                                              for i in range(25)]
    monitor = Monitor(codebook)
    _feed(monitor, codebook, sorted(frames))
    assert list(monitor.duplicates) == [codebook[MESSAGE].frame_id]


def _one_sender(counters: list[int], step: float = CYCLE) -> list[tuple[float, int, float]]:
    return [(i * step, c % M, 5.0) for i, c in enumerate(counters)]


SINGLE_SENDER_PATTERNS = {   # docs/spec/e2e.md "Counter patterns": one sender each, however broken
    "stuck": list(range(10)) + [10] * 50 + list(range(13, 40)),
    "skip 1 again and again": [c for c in range(200) if c % 5],          # OKSOMELOST: applied
    "skip 2 again and again": [c for c in range(300) if c % 6 not in (0, 1)],
    "skip 2": list(range(6)) + list(range(8, 40)),
    "one step back": [6, 7, 8, 7, 8, 9, 10, 11],
    "counting down": [5, 6, 7] + [6 - i for i in range(40)],
    "stale frame now and then": sum(([c, c + 1, c + 2, c + 3, c - 1] for c in range(0, 100, 4)), []),
    "restart with a jump, twice": list(range(20)) + list(range(5, 30)) + list(range(11, 40)),
    "each frame twice, 2 ms apart": [c for c in range(40) for _ in range(2)],
}


@pytest.mark.parametrize("name", SINGLE_SENDER_PATTERNS)
def test_one_broken_sender_is_no_second_sender(codebook: Codebook, name: str) -> None:
    counters = SINGLE_SENDER_PATTERNS[name]
    if name.startswith("each frame twice"):
        frames = [(i // 2 * CYCLE + (i % 2) * 0.002, c % M, 5.0) for i, c in enumerate(counters)]
    else:
        frames = _one_sender(counters)
    monitor = Monitor(codebook)
    _feed(monitor, codebook, frames)
    rejected = monitor.invalid_frames              # (the first frame is valid, only not applied: NODATA -> INIT)
    if name == "skip 1 again and again":
        assert rejected == 0, "one lost frame at a time is OKSOMELOST, applied (MaxDeltaCounter 2)"
    else:
        assert rejected > 0, "the pattern is a fault the receiver rejects"
    assert monitor.duplicates == {}, name


@pytest.mark.parametrize("kind, param", [(k, {"bitflip": 3, "counter_jump": 5, "checksum_value": 7,
                                                "checksum_offset": 1}.get(k, 0.0)) for k in FRAME_KINDS if k != "delay"]
                         + [("delay", d) for d in (0.015, 0.05, 0.1, 0.15)])
def test_injected_faults_are_no_second_sender(codebook: Codebook, kind: str, param: float) -> None:
    """Every frame fault the bench injects acts on one sender's frames: none is reported as two senders. A
    delay that ends interleaves the held-back frames with the new ones (testcases/ev4wis/test_faults.py delays
    DRV_MotionRequest by 0.1 s), but only for as many frames as were held back (here up to 15)."""
    plan = FaultPlan(codebook)
    plan.add(Fault(kind, MESSAGE, 0.2, 0.6, param))
    restbus = Restbus(codebook, codebook[MESSAGE].senders)
    slot = restbus.slots[MESSAGE]
    monitor = Monitor(codebook)
    frame_id = codebook[MESSAGE].frame_id
    delayed: list[tuple[float, bytes]] = []
    for i in range(100):
        t = i * CYCLE
        ready = [d for d in delayed if d[0] <= t + 1e-9]
        delayed = [d for d in delayed if d[0] > t + 1e-9]
        for _, data in ready:
            monitor.on_frame(t, frame_id, data, "rx")
        for delay, data in plan.apply(t, frame_id, restbus.build(slot)):
            if delay > 0:
                delayed.append((t + delay, data))
            else:
                monitor.on_frame(t, frame_id, data, "rx")
    assert monitor.duplicates == {}, kind


def test_a_frame_of_an_identifier_this_station_sends(codebook: Codebook) -> None:
    """The station knows what it sends: a received frame of one of its own identifiers is a second sender,
    whatever its counter (here the very counter the station sends next)."""
    monitor = Monitor(codebook)
    frame_id = codebook[MESSAGE].frame_id
    for i in range(5):
        monitor.on_frame(i * CYCLE, frame_id, _frame(codebook, i), "tx")
    assert monitor.duplicates == {}
    monitor.on_frame(4.5 * CYCLE, frame_id, _frame(codebook, 5, angle=-1.0), "rx")
    found = monitor.duplicates[frame_id]
    assert "received while this station sends it" in found.describe() and found.t == pytest.approx(0.045)
    # a node the bench stopped simulating long ago (its frames now come from a real ECU) is no finding
    other = Monitor(codebook)
    other.on_frame(0.0, frame_id, _frame(codebook, 0), "tx")
    other.on_frame(1.0, frame_id, _frame(codebook, 9), "rx")
    assert other.duplicates == {}


def test_the_echo_of_the_stations_own_frame_is_no_second_sender(codebook: Codebook) -> None:
    """On socketcan the kernel loops every frame back; when the broadcast manager hands a message back to the
    tick scheduler, echoes of its frames can reach the station's bus socket as received frames (seen in the vcan
    lane: 13 messages flagged at a scenario change). A copy of one of the station's own last 16 frames is its
    echo; a different payload within 3 cycles is still a second sender."""
    monitor = Monitor(codebook)
    frame_id = codebook[MESSAGE].frame_id
    for i in range(5):
        monitor.on_frame(i * CYCLE, frame_id, _frame(codebook, i), "tx")
    monitor.on_frame(4.2 * CYCLE, frame_id, _frame(codebook, 4), "rx")      # the echo of the frame at 0.04 s
    monitor.on_frame(4.3 * CYCLE, frame_id, _frame(codebook, 2), "rx")      # a late echo of an older own frame
    assert monitor.duplicates == {}
    monitor.on_frame(4.6 * CYCLE, frame_id, _frame(codebook, 4, angle=-1.0), "rx")   # same counter, other data
    assert "received while this station sends it" in monitor.duplicates[frame_id].describe()


def test_two_senders_on_the_virtual_bus(codebook: Codebook) -> None:
    """In process: the bench's VCU and a second VCU on one virtual bus. The runner's monitor (which sends
    neither) shows it by the counters, the first VCU's station by a frame of its own identifier."""
    from bench.sim.station import Station
    from bench.transport import VirtualTimeBus

    channel = f"dup-{random.randint(0, 1 << 30)}"
    buses = [VirtualTimeBus(channel=channel) for _ in range(3)]
    clock = {"t": 0.0}
    stations = []
    for name, bus, start in (("vcu-1", buses[0], 0), ("vcu-2", buses[1], 9)):
        restbus = Restbus(codebook, {"VCU"})
        for slot in restbus.slots.values():
            slot.counter = start       # the second VCU's counters 9 ahead
        stations.append(Station(name, bus, restbus, Monitor(codebook), lambda: clock["t"]))
    watcher = Monitor(codebook)
    try:
        for tick in range(200):
            clock["t"] = tick * 0.001
            for i, station in enumerate(stations):
                if tick >= 20 * i:    # the second VCU starts 20 ms later
                    station.tick(tick, clock["t"], 0.001)
            msg = buses[2].recv(0.0)
            while msg is not None:
                watcher.on_frame(clock["t"], msg.arbitration_id, bytes(msg.data), "rx")
                msg = buses[2].recv(0.0)
    finally:
        for bus in buses:
            bus.shutdown()
    frame_id = codebook[MESSAGE].frame_id
    assert frame_id in watcher.duplicates, watcher.invalid_log[:5]
    assert frame_id in stations[0].monitor.duplicates
    assert "received while this station sends it" in stations[0].monitor.duplicates[frame_id].describe()


def test_duplicates_table_is_one_row_per_identifier(codebook: Codebook) -> None:
    """The run's report gets the findings as its first table; a finding both monitors made is one row."""
    from bench.run import duplicates_table

    monitors = [Monitor(codebook), Monitor(codebook)]
    frame_id = codebook[MESSAGE].frame_id
    for monitor in monitors:
        monitor.on_frame(0.0, frame_id, _frame(codebook, 0), "tx")
        monitor.on_frame(0.005, frame_id, _frame(codebook, 7), "rx")
    assert duplicates_table([Monitor(codebook)]) is None
    table = duplicates_table(monitors)
    assert table is not None and table.title.startswith("Findings: two senders")
    assert table.rows == [[f"0x{frame_id:03X}", MESSAGE, monitors[0].duplicates[frame_id].describe(), "0.005", "1"]]


def test_bench_monitor_and_plant_status_say_it_once(codebook: Codebook) -> None:
    """`bench monitor`'s screen names the finding above the last invalid frames; `bench plant`'s status lines
    say it once and no longer list that message's counter errors one by one."""
    from rich.console import Console

    from bench.cli.monitor import LiveMonitor, render
    from bench.cli.plant import _report_duplicates, _report_invalid

    monitor = Monitor(codebook)
    a = [(i * CYCLE, i % M, 5.0) for i in range(10)]
    both = [f for i in range(40) for f in (((10 + i) * CYCLE - CYCLE / 2, (13 + i) % M, -3.0),
                                            ((10 + i) * CYCLE, (10 + i) % M, 5.0))]
    _feed(monitor, codebook, a + both)
    frame_id = codebook[MESSAGE].frame_id
    console = Console(record=True, width=240)
    console.print(render(LiveMonitor(monitor, 2.0), 0.5, "test", 0.5))
    screen = console.export_text()
    assert f"two senders of 0x{frame_id:03X} ({MESSAGE}): counters" in screen
    assert screen.index("two senders") < screen.index("last invalid")
    shown: set[int] = set()
    _report_duplicates(console, monitor, shown)
    _report_duplicates(console, monitor, shown)
    _report_invalid(console, monitor, 0)
    status = console.export_text()
    assert status.count(f"two senders of 0x{frame_id:03X}") == 1
    assert "counter" not in status.replace("counters", "")      # no "counter 3, expected 7" lines
    assert f"and {monitor.invalid_frames} of messages with two senders" in status
