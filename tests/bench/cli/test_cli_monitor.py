"""`bench monitor` against a running `bench plant`, as a user sees it: in a terminal (tmux, fixed size).

Issue 7, acceptance 4: the live view shows the message table with measured rates. Also the parts that
need no terminal: the sliding-window statistics and the clear errors.
"""

from __future__ import annotations

import math
import os
import random
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from bench.checks.monitor import Monitor
from bench.cli import main
from bench.cli.monitor import TimeBase, window_stats
from bench.database.codec import Codebook
from tests.fakes import ipv4_group
from tests.repo import ROOT

WIDTH, HEIGHT = 200, 50
SCREEN_TIMEOUT = 30.0   # s to wait for a screen with the expected row (plant and monitor start-up included)


def tmux() -> str:
    path = shutil.which("tmux")
    if path is None:
        if os.environ.get("CI"):
            pytest.fail("tmux not found, but CI is set (.ci/run installs tmux)")
        pytest.skip("tmux not installed")
    return path


def table_rows(screen: str) -> list[dict[str, str]]:
    """The monitor's table as dicts (column header -> cell), from the lines that use its "│" separators."""
    lines = [line for line in screen.splitlines() if "│" in line]
    header = next((line for line in lines if "Rate Hz" in line), None)
    if header is None:
        return []
    names = [cell.strip() for cell in header.split("│")]
    rows = []
    for line in lines:
        if line is header:
            continue
        cells = [cell.strip() for cell in line.split("│")]
        if len(cells) == len(names):
            rows.append(dict(zip(names, cells)))
    return rows


def _kept_cycle(row: dict[str, str]) -> bool:
    """The row shows a 10 ms message that came at its cycle within the window: 90-110 Hz and p50 8-12 ms."""
    try:
        return 90.0 <= float(row["Rate Hz"]) <= 110.0 and 8.0 <= float(row["p50 ms"]) <= 12.0
    except (KeyError, ValueError):      # "–": no interval in the window yet
        return False


@pytest.mark.realtime
def test_monitor_shows_the_plant_messages_with_their_rates(tmp_path: Path) -> None:
    binary = tmux()
    group = ipv4_group()
    env = {**os.environ, "LANG": "C.UTF-8", "LC_ALL": "C.UTF-8", "TERM": "xterm-256color"}
    for name in ("TMUX", "COLUMNS", "LINES"):   # the screen's size is tmux's (an xdist worker has COLUMNS=80)
        env.pop(name, None)
    plant_log = (tmp_path / "plant.txt").open("w")
    plant = subprocess.Popen([sys.executable, "-m", "bench", "plant", "--interface", "udp_multicast",
                              "--channel", group, "--duration", "60"], cwd=ROOT, stdout=plant_log,
                             stderr=subprocess.STDOUT)
    tmux_cmd = [binary, "-S", str(tmp_path / "tmux.sock"), "-f", "/dev/null", "-u"]   # a server of our own
    monitor_cmd = (f"{sys.executable} -m bench monitor --interface udp_multicast --channel {group} "
                   f"--duration 40; echo monitor exited $?; sleep 60")
    screen = ""
    row: dict[str, str] | None = None
    try:
        subprocess.run([*tmux_cmd, "new-session", "-d", "-s", "monitor", "-x", str(WIDTH), "-y", str(HEIGHT),
                        monitor_cmd], cwd=ROOT, env=env, check=True, timeout=10)
        deadline = time.monotonic() + SCREEN_TIMEOUT
        while time.monotonic() < deadline:
            time.sleep(0.5)
            screen = subprocess.run([*tmux_cmd, "capture-pane", "-p", "-t", "monitor"], env=env,
                                    capture_output=True, text=True, timeout=10).stdout
            rows = {r["Message"]: r for r in table_rows(screen)}
            row = rows.get("WHL_Status_FL")
            # the plant runs in real time on a shared host: wait for a screen where it kept its cycle over the
            # monitor's window, by rate and by median interval (a plant that ran late replays its ticks at once:
            # the rate stays about 100 Hz while the median falls, 0.85 ms and 5.9 ms seen at load 6-8)
            if row is not None and _kept_cycle(row):
                break
    finally:
        subprocess.run([*tmux_cmd, "kill-server"], env=env, capture_output=True, timeout=10)
        plant.send_signal(signal.SIGINT)
        try:
            plant.wait(timeout=30)
        except subprocess.TimeoutExpired:
            plant.kill()
            plant.wait()
        plant_log.close()
    assert row is not None, f"no WHL_Status_FL row on the screen:\n{screen}"
    # The DBC says 10 ms; the plant sends at that cycle in real time, so about 100 Hz measured.
    assert row["DBC ms"] == "10" and row["DBC Hz"] == "100.0", row
    assert 90.0 <= float(row["Rate Hz"]) <= 110.0, f"{row}\n{screen}"
    assert 8.0 <= float(row["p50 ms"]) <= 12.0, row
    assert row["Sender"] == "WHL_FL" and row["ID"] == "0x120", row
    assert "SteerAngle=" in row["Values"], row
    assert "bench monitor udp_multicast" in screen and "frames" in screen and "invalid" in screen
    assert plant.returncode == 0, (tmp_path / "plant.txt").read_text()


# -- without a terminal ------------------------------------------------------------------------------------
def test_window_stats_measure_the_last_window_only(codebook: Codebook) -> None:
    monitor = Monitor(codebook)
    state = monitor.state("WHL_Status_FL")
    # frames every 20 ms until t = 1.0, then every 10 ms until t = 2.0 (known intervals)
    times = [i * 0.02 for i in range(51)] + [1.0 + i * 0.01 for i in range(1, 101)]
    state.intervals = [b - a for a, b in zip(times, times[1:])]
    state.last_seen = times[-1]
    rate, p50, worst = window_stats(state, now=2.0, window=0.5)
    assert rate == pytest.approx(100.0) and p50 == pytest.approx(0.01) and worst == pytest.approx(0.01)
    rate, p50, worst = window_stats(state, now=2.0, window=1.5)        # both parts
    assert worst == pytest.approx(0.02) and p50 == pytest.approx(0.01)
    assert 50.0 < rate < 100.0
    assert all(math.isnan(v) for v in window_stats(state, now=5.0, window=0.5))   # silent for 3 s


def test_time_base_maps_the_host_clock_onto_frame_stamps() -> None:
    base = TimeBase()
    # interface stamps 1000 s ahead of the host clock; frames read 1 ms to 5 ms after their stamp
    for i, delay in enumerate([0.005, 0.001, 0.003]):
        t = base.stamp(1000.0 + i * 0.01, i * 0.01 + delay)
        assert t == pytest.approx(i * 0.01)
    assert base.now(0.10) == pytest.approx(0.10 - 0.001)    # host clock minus the smallest offset (1 ms)
    no_stamps = TimeBase()
    assert no_stamps.stamp(0.0, 3.0) == 0.0 and no_stamps.stamp(0.0, 3.5) == pytest.approx(0.5)


@pytest.mark.parametrize(("argv", "needle"), [
    (["--interface", "embedded"], "embedded bus"),
    (["--duration", "-1"], "--duration"),
    (["--window", "nan"], "--window"),
])
def test_bad_options_are_one_line_errors(argv: list[str], needle: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["monitor", *argv]) == 2
    err = capsys.readouterr().err
    assert needle in err and "Traceback" not in err


def test_the_view_shows_e2e_errors_unknown_ids_and_timeouts(codebook: Codebook) -> None:
    """Without a terminal: frames into the live monitor, the view rendered to text."""
    import can
    from rich.console import Console

    from bench.cli.monitor import LiveMonitor, render
    from bench.sim.restbus import Restbus

    restbus = Restbus(codebook, ["WHL_FL"])
    restbus.set("WHL_Status_FL", SteerAngle=12.5)
    slot = restbus.slots["WHL_Status_FL"]
    frame_id = codebook["WHL_Status_FL"].frame_id
    live = LiveMonitor(Monitor(codebook), window=2.0)
    for i in range(100):                                  # 1 s of frames every 10 ms, stamped 1000 s + t
        data = bytearray(restbus.build(slot))
        if i == 50:
            data[6] ^= 0xFF                               # one bad CRC (byte 6 in the contract's Profile 11)
        live.feed(0.0005 + i * 0.01, can.Message(timestamp=1000.0 + i * 0.01, arbitration_id=frame_id, data=data,
                                                 is_extended_id=False))
    live.feed(1.0, can.Message(timestamp=1000.995, arbitration_id=0x7FF, data=b"\x00", is_extended_id=False))
    console = Console(record=True, width=220)
    console.print(render(live, live.tick(1.0), "udp_multicast 239.1.2.3", 1.0))
    text = console.export_text()
    rows = {r["Message"]: r for r in table_rows(text)}
    row = rows["WHL_Status_FL"]
    assert float(row["Rate Hz"]) == pytest.approx(100.0, abs=0.5) and row["p50 ms"] == "10.00"
    # the profile and its state, then the AUTOSAR statuses other than OK: the bad frame (ERROR) and the next one
    # (one counter step after the last good frame: OKSOMELOST, not applied while the state machine is INVALID)
    assert row["E2E"] == "P11 VALID ERROR 1 OKSOMELOST 1" and row["Timeout"] == "ok"
    assert "SteerAngle=12.5" in row["Values"]
    assert "unknown ids 1" in text and "0x7FF ×1" in text and "invalid 3" in text
    console = Console(record=True, width=220)
    console.print(render(live, live.tick(1.5), "udp_multicast 239.1.2.3", 1.5))   # 0.5 s of silence: timed out
    row = {r["Message"]: r for r in table_rows(console.export_text())}["WHL_Status_FL"]
    assert row["Timeout"].startswith("TIMEOUT")


def test_reception_queues_each_frame_with_its_arrival_time() -> None:
    """`bench monitor` reads the bus through python-can's Notifier into a BufferedReader: every frame comes out, in
    order, with the host time it arrived (taken in the Notifier's thread, not when the view drains the queue)."""
    import can

    from bench.cli.monitor import Reception

    channel = f"monitor-{random.randrange(1 << 30)}"
    clock = iter(range(1, 1000))
    with can.Bus(interface="virtual", channel=channel) as sender, can.Bus(interface="virtual", channel=channel) as bus:
        reception = Reception(bus, lambda: float(next(clock)), "virtual test")
        try:
            for i in range(5):
                sender.send(can.Message(arbitration_id=0x100 + i, data=[i], is_extended_id=False))
            got: list[tuple[float, can.Message]] = []
            deadline = time.monotonic() + 5.0
            while len(got) < 5 and time.monotonic() < deadline:
                got += reception.drain()
                time.sleep(0.01)
        finally:
            reception.stop()
    assert [msg.arbitration_id for _, msg in got] == [0x100 + i for i in range(5)]
    assert [host for host, _ in got] == [1.0, 2.0, 3.0, 4.0, 5.0]   # one clock read per frame, in arrival order


def test_a_failing_bus_is_one_monitor_error(monkeypatch: pytest.MonkeyPatch) -> None:
    """A bus that fails while read (python-can's virtual bus, its recv made to raise) ends the view with one line."""
    import can

    from bench.cli.monitor import MonitorError, Reception

    def pulled(timeout: float | None = None) -> can.Message | None:
        raise can.CanOperationError("cable pulled")

    with can.Bus(interface="virtual", channel=f"monitor-{random.randrange(1 << 30)}") as bus:
        monkeypatch.setattr(bus, "recv", pulled)
        reception = Reception(bus, time.monotonic, "broken0")
        try:
            deadline = time.monotonic() + 5.0
            with pytest.raises(MonitorError, match=r"^broken0: receiving failed: cable pulled$"):
                while time.monotonic() < deadline:
                    list(reception.drain())
                    time.sleep(0.01)
        finally:
            reception.stop()
