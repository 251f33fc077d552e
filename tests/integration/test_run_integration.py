"""`bench run` and `bench plant` as a user runs them: report folder, log contents, determinism,
two processes over udp_multicast, and crash safety (SIGKILL, SIGINT)."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap.stream_reader import StreamReader

from tests.child import Child
from tests.fakes import ipv4_group
from tests.reference import COUNTER_VALUES, counter_of, crc8_j1850_p11, intact
from tests.repo import ROOT

CASES = ROOT / "tests" / "fixtures" / "cases"
BENCH = [sys.executable, "-m", "bench"]


def bench_run(out: Path, *extra: str, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run([*BENCH, "run", str(CASES / "test_mini.py"), "--out", str(out), *extra],
                          cwd=ROOT, capture_output=True, text=True, timeout=timeout)


def frames_of(path: Path) -> list[tuple[int, int, bytes, str]]:
    """(bench time ns, id, data, direction) of every raw frame, read with the mcap reader itself. Log times are
    epoch times (the run's wall-clock start + bench time); metadata `bench.sim.clock` gives the start."""
    out = []
    with open(path, "rb") as f:
        origin = next(int(m.metadata["origin_ns"]) for m in make_reader(f).iter_metadata() if m.name == "bench.clock")
        f.seek(0)
        for _schema, _channel, message in make_reader(f).iter_messages(topics=["/can/frames"]):
            body = json.loads(message.data)
            out.append((message.log_time - origin, body["id"], bytes(body["data"][: body["dlc"]]), body["direction"]))
    return out


@pytest.fixture(scope="module")
def first_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("run1")
    result = bench_run(out)
    assert result.returncode == 0, result.stdout + result.stderr
    return out


def test_run_writes_the_report_folder(first_run: Path) -> None:
    for name in ("report.html", "run.mcap", "junit.xml"):
        assert (first_run / name).stat().st_size > 0, name
    html = (first_run / "report.html").read_text()
    assert "test_pivot_reaches_the_commanded_angle" in html and "PASS" in html


def test_every_logged_frame_has_a_valid_checksum_and_counter(first_run: Path) -> None:
    assert crc8_j1850_p11(b"123456789") == 0x37
    frames = frames_of(first_run / "run.mcap")
    assert len(frames) > 1000
    last_counter: dict[int, int] = {}
    for _, frame_id, data, _ in frames:
        assert len(data) == 8
        assert intact(frame_id, data), hex(frame_id)     # the Profile 11 CRC in byte 6 (DataID = identifier)
        counter = counter_of(data)
        if frame_id in last_counter:
            assert counter == (last_counter[frame_id] + 1) % COUNTER_VALUES, hex(frame_id)
        last_counter[frame_id] = counter
    assert {0x100, 0x102, 0x110, 0x120, 0x130, 0x680, 0x690} <= set(last_counter)


def test_two_runs_give_the_same_frame_sequence(first_run: Path, tmp_path: Path) -> None:
    result = bench_run(tmp_path)
    assert result.returncode == 0, result.stdout + result.stderr
    assert frames_of(first_run / "run.mcap") == frames_of(tmp_path / "run.mcap")


@pytest.mark.realtime
def test_plant_and_runner_in_two_processes_over_udp_multicast(tmp_path: Path) -> None:
    # An administratively scoped group, random per test run; hop limit 0 keeps it on this host.
    group = ipv4_group()
    plant = Child([*BENCH, "plant", "--interface", "udp_multicast", "--channel", group, "--duration", "120"], ROOT)
    try:
        plant.wait_for("simulating", 60)      # its bus is open: the runner's first frame finds it listening
        result = bench_run(tmp_path, "--interface", "udp_multicast", "--channel", group, "--external", "all",
                           timeout=120)
        assert result.returncode == 0, result.stdout + result.stderr
        junit = (tmp_path / "junit.xml").read_text()
        assert 'failures="0"' in junit and 'errors="0"' in junit
    finally:
        output = plant.stop()
    assert plant.returncode == 0, output
    assert "stopped" in output


def _start_long_run(out: Path) -> subprocess.Popen:
    return subprocess.Popen([*BENCH, "run", str(CASES / "test_long.py"), "--out", str(out)], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def _wait_for_frames(path: Path, seconds: float) -> None:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        if path.exists() and path.stat().st_size > 500_000:   # frames are flowing
            return
        time.sleep(0.1)
    raise AssertionError(f"{path} did not grow within {seconds} s")


def test_sigkill_leaves_a_readable_log(tmp_path: Path) -> None:
    run = _start_long_run(tmp_path)
    _wait_for_frames(tmp_path / "run.mcap", 60)
    time.sleep(2.0)
    run.kill()
    run.wait(timeout=30)
    frames = 0
    with open(tmp_path / "run.mcap", "rb") as f:
        try:
            for record in StreamReader(f, skip_magic=False).records:
                frames += type(record).__name__ == "Message"
        except Exception:
            pass   # the file ends mid-record where the kill cut it; everything before must read
    assert frames > 1000


def test_sigint_writes_an_aborted_report_and_a_complete_log(tmp_path: Path) -> None:
    run = _start_long_run(tmp_path)
    _wait_for_frames(tmp_path / "run.mcap", 60)
    run.send_signal(signal.SIGINT)
    output, _ = run.communicate(timeout=60)
    assert run.returncode != 0, output
    html = (tmp_path / "report.html").read_text()
    assert "ABORTED" in html and "aborted" in html
    with open(tmp_path / "run.mcap", "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None and summary.statistics.message_count > 1000
    junit = (tmp_path / "junit.xml").read_text()
    assert "aborted" in junit


def test_parallel_workers_merge_into_one_report(tmp_path: Path) -> None:
    result = bench_run(tmp_path, "-n", "2")
    assert result.returncode == 0, result.stdout + result.stderr
    logs = sorted(p.name for p in tmp_path.glob("run-*.mcap"))
    assert logs == ["run-gw0.mcap", "run-gw1.mcap"]
    assert not (tmp_path / "parts").exists()
    html = (tmp_path / "report.html").read_text()
    for name in ("test_pivot_reaches_the_commanded_angle", "test_normal_mode_drives_straight",
                 "test_timer_runs_a_closed_loop", "run-gw0.mcap", "run-gw1.mcap"):
        assert name in html, name
    junit = (tmp_path / "junit.xml").read_text()
    assert 'tests="3"' in junit and 'failures="0"' in junit
    assert sum(len(frames_of(tmp_path / log)) for log in logs) > 1000
