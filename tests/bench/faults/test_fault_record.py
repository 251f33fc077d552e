"""Faults on the record (issue 16, findings 3, 4, 7 and 11): a bad --fault is stopped before the first
case; every injected fault shows in the report (header, its case, shaded on the case's plots), in JUnit
and in the MCAP log; windows can count from each case's start; plots break where frames stop, and a
value of a message that never came reads "no frames"; the invalid frames of a run are explained; the
log's times are epoch times.

One small run (two cases on the virtual bus, ~2 s of bench time) is shared by the tests of this module.
"""

from __future__ import annotations

import re
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import pytest

from bench.case import NoFrames
from bench.config import RunSettings, load_config
from bench.database.codec import Codebook
from bench.errors import ConfigError
from bench.faults.plan import CASE, FaultPlan, parse_fault, validate
from bench.log.logread import read_decoded, summarise
from bench.results.model import RunResult
from bench.run import BenchRun
from tests import repo

ROOT = repo.ROOT
DROPPED, CORRUPTED = "VCU_WheelCmd_FL", "VCU_WheelCmd_FR"
CYCLE = 0.010                      # s, both messages (dbc/chassis.dbc GenMsgCycleTime 10)
DROP_SPEC = f"drop:{DROPPED}@case+0.5-1"
SILENCE_SPEC = "silence:IMU@0-"    # IMU_Motion never comes


# -- finding 3: a bad spec is one line before any case --------------------------------------------------
def test_validate_names_each_bad_spec(codebook: Codebook) -> None:
    good = ["drop:VCU_WheelCmd_FL@1-2", "silence:WHL_FR@case+0.5-", "flood:0x000:8@run+1-2",
            "checksum_offset:IMU_Motion:1@case+0-0.2"]
    assert validate(good, codebook) == []
    bad = {"drop:NoSuchMsg@1-2": "unknown message 'NoSuchMsg'",
           "silence:NOBODY@1-": "unknown node 'NOBODY'",
           "drop:VCU_WheelCmd_FL@3-2": "0 <= START < END",
           "drop:VCU_WheelCmd_FL@case+-1-2": "START is missing",
           "smash:VCU_WheelCmd_FL@1-2": "unknown kind 'smash'",
           "bitflip:VCU_WheelCmd_FL:70@1-2": "bit index",
           "flood:VCU@1-2": "TARGET must be an identifier"}
    problems = validate(list(bad), codebook)
    assert len(problems) == len(bad)
    for (spec, why), line in zip(bad.items(), problems):
        assert line.startswith(f"--fault {spec!r}: ") and why in line and "\n" not in line, line


@pytest.mark.parametrize(("spec", "why"), [
    ("drop:WHL_Status_FL@case+1-case+1.5", "END 'case+1.5' is not a number: case+ goes once, at the front of the "
                                           "window, and makes both times count from each case's start "
                                           "(e.g. drop:WHL_Status_FL@case+1-1.5)"),
    ("drop:WHL_Status_FL@x-2", "START 'x' is not a number (s)"),
    ("delay:WHL_Status_FL:0.1s@1-2", "PARAM '0.1s' is not a number"),
])
def test_a_spec_that_is_not_a_number_says_which_part(spec: str, why: str) -> None:
    """Issue 27, finding 3: "PARAM, START and END must be numbers" did not say which, nor where case+ goes."""
    with pytest.raises(ConfigError) as raised:
        parse_fault(spec)
    assert str(raised.value) == f"--fault {spec!r}: {why}"


def test_case_relative_windows(codebook: Codebook) -> None:
    fault = parse_fault("drop:VCU_WheelCmd_FL@case+0.5-1")
    assert (fault.relative, fault.start, fault.end, fault.describe()) == (CASE, 0.5, 1.0,
                                                                          "drop:VCU_WheelCmd_FL@case+0.5-1")
    plan = FaultPlan(codebook)
    plan.add(fault)
    frame_id = codebook[DROPPED].frame_id
    assert plan.apply(0.7, frame_id, b"\0" * 8) != []          # a template acts in no case of its own
    plan.begin_case(10.0)
    assert plan.apply(10.49, frame_id, b"\0" * 8) != [] and plan.apply(10.5, frame_id, b"\0" * 8) == []
    plan.end_case(10.8)                                       # the case ends inside the window: it closes
    assert plan.apply(10.9, frame_id, b"\0" * 8) != []
    plan.begin_case(20.0)
    assert plan.apply(20.6, frame_id, b"\0" * 8) == []
    assert fault.frames == 2 and [r.spec for r in plan.records()] == ["drop:VCU_WheelCmd_FL@case+0.5-1"]


def test_cli_stops_a_fault_on_an_unknown_message(tmp_path: Path) -> None:
    out = tmp_path / "out"
    result = subprocess.run([sys.executable, "-m", "bench", "run", "-k", "sbw_step", "--fault", "drop:NoSuchMsg@1-2",
                             "--out", str(out)], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert result.returncode == 2, result.stdout + result.stderr
    assert "NoSuchMsg" in result.stderr and "Traceback" not in result.stdout + result.stderr
    assert not (out / "report.html").exists()   # stopped at the door: no case ran


# -- one small run with three faults ------------------------------------------------------------------
@dataclass
class Recorded:
    run: RunResult
    out: Path
    wall_before: float
    no_frames: float
    inject_spec: str


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> Recorded:
    out = tmp_path_factory.mktemp("fault_record")
    wall_before = time.time()
    run = BenchRun(load_config(ROOT / "bench.toml"), RunSettings(), out)
    run.start()
    assert run.session is not None
    run.session.faults.extend([parse_fault(SILENCE_SPEC), parse_fault(DROP_SPEC)])   # as --fault gives them
    try:
        case = run.begin_case("t.py::test_a", "test_a")
        injected = case.inject("checksum_offset", CORRUPTED, after=0.2, duration=0.2, param=1)
        case.run(1.5)
        no_frames = case.value("IMU_Motion", "YawRate")
        case.expect("yaw rate", no_frames, 0.0, abs_tol=1.0, unit="deg/s")
        case.plot("wheel commands",
                  [(DROPPED, "SteerAngleCmd"), (CORRUPTED, "SteerAngleCmd"), ("IMU_Motion", "YawRate")])
        case.close()
        case.result.outcome = "failed"
        case.result.sim_time = run.session.now() - case.result.sim_start
        other = run.begin_case("t.py::test_b", "test_b")
        other.start_scenario(Vehicle="EV4WIS")   # a new scenario must not end the case's record
        other.run(0.3)
        other.close()
        other.result.outcome = "passed"
        other.result.sim_time = run.session.now() - other.result.sim_start
    finally:
        result = run.finish()
    return Recorded(result, out, wall_before, no_frames, injected.describe())


def test_faults_in_the_run_record(recorded: Recorded) -> None:
    faults = {f.spec: f for f in recorded.run.faults}
    assert list(faults) == [SILENCE_SPEC, DROP_SPEC, recorded.inject_spec]
    assert faults[SILENCE_SPEC].source == "command line" and faults[recorded.inject_spec].source == "t.py::test_a"
    # the drop acted in case a only (case b ends before 0.5 s): 0.5 s of a 10 ms message
    assert abs(faults[DROP_SPEC].frames - 0.5 / CYCLE) <= 1
    assert abs(faults[recorded.inject_spec].frames - 0.2 / CYCLE) <= 1
    assert faults[SILENCE_SPEC].frames > 0


def test_faults_in_the_case_where_they_acted(recorded: Recorded) -> None:
    a, b = recorded.run.cases
    assert [f.spec for f in a.faults] == [SILENCE_SPEC, recorded.inject_spec, DROP_SPEC]
    drop = a.faults[2]
    assert abs(drop.start - (a.sim_start + 0.5)) < 1e-9 and abs(drop.end - (a.sim_start + 1.0)) < 1e-9
    assert [f.spec for f in b.faults] == [SILENCE_SPEC]
    assert b.faults[0].frames > 0 and b.faults[0].frames < a.faults[0].frames   # counted per case


def test_faults_in_the_report(recorded: Recorded) -> None:
    html = (recorded.out / "report.html").read_text(encoding="utf-8")
    header = html[:html.index('<h3>Summary</h3>')]
    for spec in (SILENCE_SPEC, DROP_SPEC, recorded.inject_spec):
        assert f'<span class="mono">{spec}</span>' in header
    case_a = html[html.index('id="case-1"'):html.index('id="case-2"')]
    assert "Faults during this case" in case_a and '<span class="tag">fault</span>' in case_a
    shaded = re.findall(r'<rect class="fault" x="([\d.]+)" y="\d+" width="([\d.]+)"[^>]*><title>([^<]*)</title>',
                        case_a)
    assert {t.split(" (")[0] for _, _, t in shaded} == {SILENCE_SPEC, DROP_SPEC, recorded.inject_spec}
    # the drop's window is 0.5 s of the 1.5 s case: about a third of the plot's width
    drop_x, drop_w = next((float(x), float(w)) for x, w, t in shaded if t.startswith(DROP_SPEC))
    full_w = next(float(w) for x, w, t in shaded if t.startswith(SILENCE_SPEC))
    assert abs(drop_w / full_w - 0.5 / 1.5) < 0.03


def test_faults_in_junit(recorded: Recorded) -> None:
    root = ET.parse(recorded.out / "junit.xml").getroot()
    suite = root.find("testsuite")
    assert suite is not None
    values = [p.get("value", "") for p in suite.findall("properties/property[@name='fault']")]
    assert [v.split(" from ")[0] for v in values] == [SILENCE_SPEC, DROP_SPEC, recorded.inject_spec]
    cases = {tc.get("name"): [p.get("value", "") for p in tc.findall("properties/property[@name='fault']")]
             for tc in suite.findall("testcase")}
    assert len(cases["test_a"]) == 3 and [v.split(" from ")[0] for v in cases["test_b"]] == [SILENCE_SPEC]


def test_faults_and_epoch_times_in_the_mcap_log(recorded: Recorded) -> None:
    summary = summarise(recorded.out / "run.mcap")
    added = [m["spec"] for name, m in summary.metadata if name == "bench.fault"]
    assert added == [SILENCE_SPEC, DROP_SPEC, recorded.inject_spec]
    final = [m for name, m in summary.metadata if name == "bench.faults"]
    assert len(final) == 1 and any(v.startswith(f"{DROP_SPEC} from command line: ") for v in final[0].values())
    # log time = the run's wall-clock start + bench time (Foxglove shows the date, not 1970)
    assert summary.origin is not None and recorded.wall_before - 1 <= summary.origin <= time.time()
    assert summary.start is not None and summary.origin <= summary.start <= summary.origin + 1.0
    assert summary.end is not None and summary.end - summary.origin == pytest.approx(recorded.run.sim_time, abs=0.01)
    t, _, _ = next(read_decoded(recorded.out / "run.mcap", DROPPED))   # readers give bench time back
    assert 0.0 <= t < 0.1


# -- finding 7: no frames, gaps -------------------------------------------------------------------------
def test_no_frames_instead_of_nan(recorded: Recorded) -> None:
    assert isinstance(recorded.no_frames, NoFrames) and str(recorded.no_frames) == "no frames of IMU_Motion"
    step = next(s for s in recorded.run.cases[0].steps if s.name == "yaw rate")
    assert step.measured == "no frames of IMU_Motion" and step.verdict == "fail"
    html = (recorded.out / "report.html").read_text(encoding="utf-8")
    assert "no frames of IMU_Motion" in html and ">NaN<" not in html
    assert "IMU_Motion.YawRate (no frames)" in html           # the silent series stays in the legend


def test_plot_breaks_where_frames_stop(recorded: Recorded) -> None:
    plot = recorded.run.cases[0].plots[0]
    dropped = plot.series[0]
    assert dropped.gap == pytest.approx(2.5 * CYCLE)
    html = (recorded.out / "report.html").read_text(encoding="utf-8")
    svg = re.search(r'<svg[^>]*>.*?</svg>', html[html.index('id="case-1"'):], re.S).group(0)  # type: ignore[union-attr]
    paths = re.findall(r'<path class="s" stroke="[^"]+" d="([^"]*)"', svg)
    assert paths[0].count("M") == 2       # before and after the 0.5 s drop: two lines, no ramp across
    assert paths[1].count("M") == 2       # its 0.2 s of corrupted frames were rejected: a gap too
    assert len(paths) == 2                # IMU_Motion never came: no line, but a legend entry (no frames)


# -- finding 11: invalid frames explained -----------------------------------------------------------------
def test_invalid_frames_are_explained(recorded: Recorded) -> None:
    a, b = recorded.run.cases
    rows = {(m, r): int(n) for m, r, n in a.invalid}
    corrupted = {k: n for k, n in rows.items() if k[0] == CORRUPTED}
    errors = sum(n for (_, reason), n in corrupted.items() if reason.startswith("E2E ERROR"))
    assert abs(errors - 0.2 / CYCLE) <= 1
    # after a burst of bad CRCs the receiver needs two frames in sequence (docs/spec/e2e.md "CRC burst"), and the
    # message's first frame of the run is never applied
    assert sum(corrupted.values()) - errors <= 3, corrupted
    assert a.invalid_frames >= sum(rows.values()) and b.invalid_frames == 0
    html = (recorded.out / "report.html").read_text(encoding="utf-8")
    section = html[html.index('<section id="invalid">'):]
    section = section[:section.index("</section>")]
    assert f'<td class="mono">{CORRUPTED}</td>' in section
    assert '<a href="#case-1">test_a</a><span class="tag">fault</span>' in section
    assert '<a href="#invalid">where they come from</a>' in html


def test_faults_survive_the_workers_hand_over(recorded: Recorded, tmp_path: Path) -> None:
    """-n N: each worker's part goes through JSON; a command-line fault acts in every worker and is one
    record of the merged run, its frames summed."""
    from bench.results import store as results_io

    results_io.dump(recorded.run, tmp_path / "gw0.json")
    part = results_io.load(tmp_path / "gw0.json")
    assert part.faults == recorded.run.faults and part.cases[0].faults == recorded.run.cases[0].faults
    assert part.cases[0].invalid == recorded.run.cases[0].invalid
    merged = results_io.merge([("gw0", part), ("gw1", results_io.load(tmp_path / "gw0.json"))], 1.0)
    frames = {f.spec: f.frames for f in merged.faults}
    assert list(frames) == [f.spec for f in recorded.run.faults]
    assert frames[DROP_SPEC] == 2 * next(f.frames for f in recorded.run.faults if f.spec == DROP_SPEC)


def test_real_time_log_times_are_the_receive_stamps() -> None:
    """In real time the log's origin is the wall clock's own start: origin + bench time of a frame is the
    epoch time the kernel stamped it with (within the stamp's rounding)."""
    from bench.sim.clock import WallClock

    clock = WallClock()
    clock.start()
    assert abs(clock.epoch_ns - time.time_ns()) < 50_000_000
    time.sleep(0.05)
    stamp = time.time()
    t = clock.stamp(stamp, clock.now())
    assert abs((clock.epoch_ns + round(t * 1e9)) - stamp * 1e9) < 2_000   # ns
