"""`bench log export`: a run log's raw frames through python-can's writers, read back by python-can's readers.

Issue 7, acceptance 3 (second half): a BLF exported from a run is read back by `can.BLFReader` with the
same frames. BLF stores each frame's time in 1 ns steps (python-can writes TIME_ONE_NANS objects) relative
to the file's start time, a SYSTEMTIME of 1 ms resolution to which python-can truncates the first frame's
time, so nothing is lost beyond the writer's truncation to whole ns: the frames come back within 1 µs (in
fact within a few ns). Bench time (the embedded default counts from 0) is not a Unix time; BLF then has
no start time and the export writes the frames relative to 0, so they come back unchanged too.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import can
import pytest

from bench.cli import main
from bench.log.logread import LoggedFrame, read_frames
from bench.log.recorder import Recorder
from tests.repo import ROOT

CASES = ROOT / "tests" / "fixtures" / "cases"
NS = 1e-9


@pytest.fixture(scope="module")
def run_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The MCAP log of a real (short) bench run on the embedded default."""
    out = tmp_path_factory.mktemp("run")
    result = subprocess.run([sys.executable, "-m", "bench", "run", str(CASES / "test_mini.py"), "--out", str(out)],
                            cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout + result.stderr
    return out / "run.mcap"


def key(frame: LoggedFrame) -> tuple[int, bool, bytes, bool]:
    return frame.arbitration_id, frame.is_extended, frame.data, frame.direction == "rx"


def message_key(msg: can.Message) -> tuple[int, bool, bytes, bool]:
    return msg.arbitration_id, msg.is_extended_id, bytes(msg.data), msg.is_rx


def export(source: Path, fmt: str, output: Path) -> None:
    assert main(["log", "export", str(source), "--format", fmt, "--output", str(output)]) == 0


def test_blf_of_a_run_reads_back_with_the_same_frames(run_log: Path, tmp_path: Path) -> None:
    frames = list(read_frames(run_log))
    assert len(frames) > 1000 and {f.direction for f in frames} == {"tx", "rx"}
    blf = tmp_path / "run.blf"
    export(run_log, "blf", blf)
    with can.BLFReader(blf) as reader:
        back = list(reader)
    assert [message_key(m) for m in back] == [key(f) for f in frames]       # ids, data, Rx/Tx, in order
    worst = max(abs(m.timestamp - f.t) for m, f in zip(back, frames))
    assert worst < 1e-6, worst
    assert worst <= 2 * NS, worst                 # BLF's 1 ns steps: only the writer's truncation to whole ns


def test_blf_of_a_unix_time_log_keeps_its_times(tmp_path: Path) -> None:
    """A log recorded by python-can's logger has Unix times: BLF's header then carries the start (1 ms)."""
    log = tmp_path / "unix.mcap"
    t0 = 1_763_700_000.123456
    with Recorder(log, []) as recorder:
        for i in range(200):
            recorder.frame(t0 + i * 0.0012345, 0x100 + i % 4, bytes([i % 256] * (i % 9)), channel="vcan0",
                           direction="tx" if i % 3 else "rx")
    frames = list(read_frames(log))
    blf = tmp_path / "unix.blf"
    export(log, "blf", blf)
    with can.BLFReader(blf) as reader:
        back = list(reader)
    assert [message_key(m) for m in back] == [key(f) for f in frames]
    assert max(abs(m.timestamp - f.t) for m, f in zip(back, frames)) < 1e-6


@pytest.mark.parametrize(("fmt", "reader", "direction", "resolution"), [
    ("asc", can.ASCReader, True, 1e-6),             # "%9.6f" s since the measurement start
    ("candump", can.CanutilsLogReader, True, 1e-6),  # "(%f)" absolute s; python-can's R/T suffix
    ("csv", can.CSVReader, False, 1e-12),           # repr() of the float: exact
])
def test_text_formats_read_back(run_log: Path, tmp_path: Path, fmt: str, reader: type, direction: bool,
                                resolution: float) -> None:
    frames = list(read_frames(run_log))[:3000]
    short = tmp_path / "short.mcap"
    with Recorder(short, []) as recorder:
        for f in frames:
            recorder.frame(f.t, f.arbitration_id, f.data, channel=f.channel, direction=f.direction)
    out = tmp_path / f"short.{fmt}"
    export(short, fmt, out)
    back = list(reader(out))
    assert [(m.arbitration_id, bytes(m.data)) for m in back] == [(f.arbitration_id, f.data) for f in frames]
    if direction:
        assert [m.is_rx for m in back] == [f.direction == "rx" for f in frames]
    # ASC counts from the first frame (its start is in the header), the others are absolute
    origin = frames[0].t if fmt == "asc" else 0.0
    assert max(abs(m.timestamp - (f.t - origin)) for m, f in zip(back, frames)) <= resolution


def test_default_output_and_clear_errors(run_log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    copy = tmp_path / "copy.mcap"
    copy.write_bytes(run_log.read_bytes())
    assert main(["log", "export", str(copy), "--format", "candump"]) == 0
    assert (tmp_path / "copy.log").read_text().startswith("(")
    assert main(["log", "export", str(copy), "--format", "csv", "--output", str(copy)]) == 2
    assert "overwrite the run log" in capsys.readouterr().err
    assert main(["log", "export", str(tmp_path / "missing.mcap"), "--format", "blf"]) == 2
    err = capsys.readouterr().err
    assert "missing.mcap" in err and "Traceback" not in err
    assert not (tmp_path / "missing.blf").exists()


# -- issue 27, finding 8: the ASC header's date is the run's start, not the export's time ------------------------
def asc_date(t: float) -> str:
    """An epoch time as python-can writes ASC dates (local time, milliseconds)."""
    from datetime import datetime

    moment = datetime.fromtimestamp(t)
    return moment.strftime(can.ASCWriter.FORMAT_DATE.format(moment.microsecond // 1000 % 1000))


def test_asc_date_is_the_start_of_the_run(tmp_path: Path) -> None:
    log = tmp_path / "run.mcap"
    origin_ns = 1_732_482_000_250_000_000                # 2024-11-24T21:00:00.25Z: not today, whenever this runs
    with Recorder(log, []) as recorder:
        recorder.set_origin(origin_ns, "virtual")
        for i in range(5):
            recorder.frame(0.5 + i * 0.01, 0x100, bytes(8), channel="virtual:bench", direction="rx")
    asc = tmp_path / "run.asc"
    export(log, "asc", asc)
    lines = asc.read_text().splitlines()
    assert lines[0] == f"date {asc_date(origin_ns / 1e9)}", lines[:4]             # bench time 0, the run's start
    assert lines[3] == f"Begin Triggerblock {asc_date(origin_ns / 1e9 + 0.5)}"    # the first frame, as before


def test_asc_date_of_a_log_without_origin_is_its_first_frame(tmp_path: Path) -> None:
    """A log recorded by python-can's logger (Unix times, no bench clock): its first frame is its start."""
    log = tmp_path / "unix.mcap"
    t0 = 1_763_700_000.125
    with Recorder(log, []) as recorder:
        recorder.frame(t0, 0x100, bytes(8), channel="vcan0", direction="rx")
    asc = tmp_path / "unix.asc"
    export(log, "asc", asc)
    assert asc.read_text().splitlines()[0] == f"date {asc_date(t0)}"
