"""The vcan lane: `bench plant` as its own process on a SocketCAN vcan0, and the lane script's own checks.

The plant test runs where the kernel has vcan0: in the vcan lane (scripts/vcan-lane --command, which .ci/run runs
in a User-mode Linux guest on machines without SocketCAN) and on any Linux host with vcan0 up. Elsewhere it
skips, except inside the lane (VCAN_CHANNEL set), where a missing vcan0 is a failure: the lane must never pass
by skipping. What it checks, from the kernel's receive timestamps of a receiver that only collects (and judges
after): every frame of the plant keeps the contract (docs/spec/k-matrix.md: AliveCounter +1 per frame,
the Profile 11 CRC over DataID and data, tests/reference.py), every message of the vehicle's network is there
at its DBC cycle time (p50 within 5 %, as Case.check_cycle_times), no frame of another vehicle's network is on
the bus, and the plant's own status line reports no invalid frame.

The other tests run on the host (not in the lane): the lanes' selections name cases, and the report check
(scripts/vcan-lane check_report) accepts the invalid frames of a fault case and flags them anywhere else.
"""

from __future__ import annotations

import os
import signal
import statistics
import subprocess
import sys
from pathlib import Path

import can
import pytest

from bench.config import load_config
from bench.database.codec import load_codebook
from plant.factory import messages_of, vehicles
from tests.integration.vcan import CHANNEL, IN_LANE, has_vcan, load_lane_script
from tests.reference import COUNTER_VALUES, counter_of, intact
from tests.repo import ROOT

WARM_UP_S = 2.0     # s after the plant's first frame before judging (its BCM tasks start after 3 cycles)
WINDOW_S = 6.0      # s of bus judged


if IN_LANE and not has_vcan():
    raise RuntimeError(f"the vcan lane set VCAN_CHANNEL={CHANNEL}, but this kernel has no such SocketCAN interface")

needs_vcan = pytest.mark.skipif(not has_vcan(), reason=f"needs SocketCAN and {CHANNEL} (the vcan lane runs it: "
                                                        "scripts/vcan-lane)")
on_host = pytest.mark.skipif(IN_LANE, reason="the lane script's host-side logic; not run inside the lane")


@pytest.mark.realtime
@needs_vcan
def test_plant_process_keeps_the_contract_on_vcan() -> None:
    codebook = load_codebook(load_config().databases)
    receiver = can.Bus(interface="socketcan", channel=CHANNEL, receive_own_messages=False)
    plant = subprocess.Popen([sys.executable, "-m", "bench", "plant", "--interface", "socketcan", "--channel", CHANNEL,
                              "--vehicle", "EV4WIS", "--duration", str(WARM_UP_S + WINDOW_S + 30)],
                             cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    frames: list[can.Message] = []
    try:
        first = receiver.recv(120.0)        # the plant imports and starts (slow in an emulated guest)
        assert first is not None, "no frame from bench plant within 120 s"
        start = first.timestamp + WARM_UP_S
        while True:
            msg = receiver.recv(5.0)
            assert msg is not None, "bench plant went quiet"
            if msg.timestamp >= start + WINDOW_S:
                break
            if msg.timestamp >= start:
                frames.append(msg)
    finally:
        receiver.shutdown()
        plant.send_signal(signal.SIGINT)
        output, _ = plant.communicate(timeout=60)
    assert plant.returncode == 0, output
    assert "invalid 0" in output and "invalid at" not in output, output

    by_id: dict[int, list[can.Message]] = {}
    for msg in frames:
        by_id.setdefault(msg.arbitration_id, []).append(msg)
    network = messages_of("EV4WIS")
    others = frozenset().union(*(messages_of(v) for v in vehicles())) - network
    seen = {codebook.by_id[i].name for i in by_id if i in codebook.by_id}
    assert network <= seen, f"missing from the bus: {sorted(network - seen)}"
    assert not seen & others, f"another vehicle's messages on the bus: {sorted(seen & others)}"
    for frame_id, msgs in by_id.items():
        codec = codebook.by_id[frame_id]
        if codec.e2e:
            for a, b in zip(msgs, msgs[1:]):
                assert counter_of(b.data) == (counter_of(a.data) + 1) % COUNTER_VALUES, f"{codec.name}: counter"
            bad = [m for m in msgs if not intact(frame_id, bytes(m.data))]
            assert not bad, f"{codec.name}: {len(bad)} frames with a wrong checksum"
        if codec.cycle_time:
            intervals = [b.timestamp - a.timestamp for a, b in zip(msgs, msgs[1:])]
            p50 = statistics.median(intervals)
            assert abs(p50 - codec.cycle_time) <= 0.05 * codec.cycle_time, \
                f"{codec.name}: p50 {p50 * 1000:.2f} ms, DBC {codec.cycle_time * 1000:g} ms"
            assert len(msgs) >= 0.9 * WINDOW_S / codec.cycle_time, f"{codec.name}: {len(msgs)} frames"


@on_host
def test_every_lane_selects_test_files() -> None:
    """Each lane's selection (globs, in one place of the script) names test files: a moved campaign fails here,
    not as an empty lane."""
    lane = load_lane_script()
    assert set(lane.LANES) == {"in-process", "plant-process", "example-vcu", "example-epb"}
    for name, spec in lane.LANES.items():
        assert (lane.ROOT / spec.project / "bench.toml").is_file(), name
        assert not spec.example or (lane.ROOT / spec.example).is_file(), name
        paths = lane.lane_selection(spec)
        assert bool(paths) == bool(spec.selection), name
        for path in map(Path, paths):
            files = [path] if path.is_file() else list(path.rglob("test_*.py"))
            assert files, f"{name}: {path} holds no test file"


@on_host
def test_time_travel_kernel_config_is_checked_not_trusted() -> None:
    """The lane's UML kernel is built with time travel and CAN built in; a .config that lost one of them
    (olddefconfig drops an option whose dependencies are missing) is named, and a module (=m) does not count:
    the time-travel guest loads no modules."""
    lane = load_lane_script()
    assert {"UML_TIME_TRAVEL_SUPPORT", "CAN_RAW", "CAN_BCM", "CAN_VCAN", "HOSTFS"} <= set(lane.UML_TT_OPTIONS)
    complete = "".join(f"CONFIG_{name}=y\n" for name in lane.UML_TT_OPTIONS)
    assert lane.options_absent("# a comment\n" + complete) == []
    lost = complete.replace("CONFIG_CAN_BCM=y\n", "# CONFIG_CAN_BCM is not set\n") \
                   .replace("CONFIG_CAN_VCAN=y", "CONFIG_CAN_VCAN=m")
    assert lane.options_absent(lost) == ["CAN_BCM", "CAN_VCAN"]
    assert lane.parse_args(["--out", "unused"]).uml_clock == "time-travel"


@pytest.fixture(scope="module")
def fault_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A bench run (virtual bus) of one fault case: a counter jump on DRV_MotionRequest makes invalid frames."""
    out = tmp_path_factory.mktemp("lane") / "fault-run"
    result = subprocess.run([sys.executable, "-m", "bench", "run", "-k", "counter_jump", "--out", str(out)],
                            cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    return out


@on_host
def test_report_check_accepts_the_invalid_frames_of_a_fault_case(fault_run: Path) -> None:
    lane = load_lane_script()
    facts = lane.read_log_facts(fault_run / "run.mcap")
    assert facts.complete and facts.cases == 1
    assert sum(facts.invalid.values()) > 0, "the counter jump made no invalid frame"
    assert set(facts.invalid) <= facts.fault_cases
    assert lane.check_report(fault_run) == []


@on_host
def test_report_check_flags_invalid_frames_outside_fault_cases(fault_run: Path,
                                                               monkeypatch: pytest.MonkeyPatch) -> None:
    """The same log read as if no case had injected a fault: each of its invalid frames is then a problem."""
    lane = load_lane_script()
    facts = lane.read_log_facts(fault_run / "run.mcap")
    facts.fault_cases.clear()
    monkeypatch.setattr(lane, "read_log_facts", lambda path: facts)
    problems = lane.check_report(fault_run)
    (case, count), = facts.invalid.items()
    assert problems == [f"{count} invalid frames in {case} (no fault injected there; first: {facts.first[case]})"]


@on_host
def test_report_check_lists_missing_reports(tmp_path: Path) -> None:
    assert load_lane_script().check_report(tmp_path) == [
        "missing or empty report.html", "missing or empty run.mcap", "missing or empty junit.xml"]


def _running(pid: int) -> bool:
    """A process that exists and is not a zombie (a container's init may leave orphans unreaped)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except (FileNotFoundError, ProcessLookupError, IndexError):
        return False
    return fields[0] != "Z"


@on_host
def test_a_build_step_that_times_out_stops_with_its_children(tmp_path: Path) -> None:
    """Issue 27, finding 8: the kernel build's timeout killed make alone (subprocess.run kills its direct child);
    the compilers make had started went on for minutes. The step now runs in its own process group, and the
    whole group is stopped: here a shell that waits on a child of its own, as make on its compilers."""
    lane = load_lane_script()
    pid_file = tmp_path / "child.pid"
    with open(tmp_path / "build.log", "w", encoding="utf-8") as out:
        code = lane.run_group(["/bin/sh", "-c", f"sleep 300 & echo $! > {pid_file}; wait"], cwd=tmp_path, stdout=out,
                              timeout=1.0, grace=2.0)
    child = int(pid_file.read_text())
    try:
        assert code == 124
        assert not _running(child), "the build step's child outlived the timeout"
    finally:
        if _running(child):
            os.kill(child, signal.SIGKILL)


@on_host
def test_a_build_step_that_finishes_gives_its_exit_code(tmp_path: Path) -> None:
    lane = load_lane_script()
    with open(tmp_path / "build.log", "w", encoding="utf-8") as out:
        assert lane.run_group(["/bin/sh", "-c", "echo made; exit 3"], cwd=tmp_path, stdout=out, timeout=30.0) == 3
    assert (tmp_path / "build.log").read_text() == "made\n"
