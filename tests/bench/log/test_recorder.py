"""The run log: what the recorder writes reads back exactly, opens with the mcap reader as valid
JSON with JSON schemas, survives being cut at any byte, and survives a SIGKILL of the writer."""

from __future__ import annotations

import io
import json
import math
import os
import random
import signal
import subprocess
import sys
import textwrap
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cantools
import pytest
from cantools.database.namedsignalvalue import NamedSignalValue
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader

from bench.errors import BenchError, LogError
from bench.log import logread
from bench.log.format import DECODED_PREFIX, FRAMES_TOPIC, STEPS_TOPIC
from bench.log.logread import LoggedFrame, read_decoded, read_frames, read_steps, summarise
from bench.log.recorder import Recorder
from tests.repo import BENCH_DBC, CHASSIS_DBC

FALLBACK_DBC = """VERSION ""
NS_ :
BS_:
BU_: ECU BENCH
BO_ 256 SteerCmd: 8 BENCH
 SG_ SteerAngle : 0|16@1- (0.1,0) [-780|780] "deg" ECU
 SG_ Mode : 16|2@1+ (1,0) [0|3] "" ECU
 SG_ Counter : 56|4@1+ (1,0) [0|15] "" ECU
BO_ 2147484160 WheelState: 8 ECU
 SG_ Speed : 0|16@1+ (0.01,0) [0|655.35] "km/h" BENCH
CM_ SG_ 256 SteerAngle "Requested steering angle";
VAL_ 256 Mode 0 "Off" 1 "Active" 2 "Fault" ;
"""


def dbc_files() -> list[Path]:
    return [path for path in (CHASSIS_DBC, BENCH_DBC) if path.exists()]


def load_databases(tmp: Path) -> tuple[list[cantools.database.can.Database], list[Path]]:
    """The project's DBC files once they exist, else a small stand-in, and the files to attach."""
    files = dbc_files()
    if not files:
        files = [tmp / "fallback.dbc"]
        files[0].write_text(FALLBACK_DBC)
    return [cantools.database.load_file(path) for path in files], files


@dataclass
class Written:
    """What a test wrote, as the reader should give it back."""

    frames: list[LoggedFrame] = field(default_factory=list)
    decoded: list[tuple[int, str, dict[str, Any]]] = field(default_factory=list)
    steps: list[dict[str, Any]] = field(default_factory=list)


def expected_signals(signals: dict[str, Any]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for name, value in signals.items():
        if isinstance(value, NamedSignalValue):
            value = value.value
        out[name] = None if isinstance(value, float) and not math.isfinite(value) else value
    return out


def write_log(path: Path, tmp: Path, count: int = 300, chunk_size: int = 1 << 20) -> Written:
    databases, files = load_databases(tmp)
    messages = [message for database in databases for message in database.messages]
    rng = random.Random(7)
    written = Written()
    with Recorder(path, databases, files, profile="test", chunk_size=chunk_size) as recorder:
        for i in range(count):
            message = messages[i % len(messages)]
            t = i * 0.0013 + rng.random() * 1e-4
            ns = round(t * 1e9)
            data = bytes(rng.getrandbits(8) for _ in range(message.length if i % 11 else 3))
            channel, direction = ("can0", "rx") if i % 3 else ("vcan1", "tx")
            valid = i % 7 != 0
            error = "" if valid else 'E2E "crc" mismatch ✗'
            recorder.frame(t, message.frame_id, data, channel=channel, direction=direction,
                           is_extended=message.is_extended_frame, is_remote=i == 5, is_error=i == 6,
                           valid=valid, error=error)
            written.frames.append(LoggedFrame(ns / 1e9, message.frame_id, data, channel, direction,
                                              message.is_extended_frame, i == 6, valid, error, i == 5, ns))
            if len(data) == message.length:
                signals = message.decode(data, decode_choices=i % 2 == 0)
                recorder.decoded(t, message.name, signals)
                written.decoded.append((ns, message.name, expected_signals(signals)))
            if i % 50 == 0:
                step = {"timestamp": {"sec": ns // 10**9, "nsec": ns % 10**9}, "level": 2 + i % 3,
                        "message": f"step {i}: \"ok\"", "name": f"case_{i}", "file": "tc.py", "line": i}
                recorder.step(t, step["level"], step["name"], step["message"], step["file"], step["line"])
                written.steps.append(step)
        first = messages[0]
        nan_signals = {signal.name: float("nan") for signal in first.signals}
        recorder.decoded(count * 0.0013, first.name, nan_signals)
        written.decoded.append((round(count * 0.0013 * 1e9), first.name, expected_signals(nan_signals)))
    return written


@pytest.fixture(scope="module")
def log(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Written]:
    tmp = tmp_path_factory.mktemp("log")
    path = tmp / "run.mcap"
    return path, write_log(path, tmp)


def test_frames_read_back_exactly(log: tuple[Path, Written]) -> None:
    path, written = log
    frames = list(read_frames(path))
    assert frames == written.frames
    assert [f.t_ns for f in frames] == [round(f.t * 1e9) for f in frames]


def test_decoded_and_steps_read_back_exactly(log: tuple[Path, Written]) -> None:
    path, written = log
    assert [(round(t * 1e9), name, signals) for t, name, signals in read_decoded(path)] == written.decoded
    name = written.decoded[0][1]
    assert [signals for _, _, signals in read_decoded(path, name)] == [s for _, n, s in written.decoded if n == name]
    assert list(read_steps(path)) == written.steps


def test_summary(log: tuple[Path, Written]) -> None:
    path, written = log
    summary = summarise(path)
    assert summary.complete
    assert summary.frames == len(written.frames) == summary.channels[FRAMES_TOPIC]
    assert summary.invalid_frames == sum(not f.valid for f in written.frames)
    assert summary.channels[STEPS_TOPIC] == len(written.steps)
    assert summary.start == written.frames[0].t and summary.end == written.decoded[-1][0] / 1e9
    assert summary.attachments == [p.name for p in dbc_files()] or summary.attachments == ["fallback.dbc"]


def test_mcap_reader_decodes_all_json_against_schemas(log: tuple[Path, Written]) -> None:
    jsonschema = pytest.importorskip("jsonschema")
    path, written = log
    databases, _ = load_databases(path.parent)
    with path.open("rb") as file:
        reader = make_reader(file)
        summary = reader.get_summary()
        assert summary is not None
        topics = {channel.topic for channel in summary.channels.values()}
        names = {message.name for database in databases for message in database.messages}
        assert topics == {FRAMES_TOPIC, STEPS_TOPIC} | {DECODED_PREFIX + name for name in names}
        validators = {}
        for schema in summary.schemas.values():
            assert schema.encoding == "jsonschema"
            document = json.loads(schema.data)
            jsonschema.Draft7Validator.check_schema(document)
            assert document["type"] == "object"
            validators[schema.id] = jsonschema.Draft7Validator(document)
        for database in databases:
            for message in database.messages:
                schema = next(s for s in summary.schemas.values() if s.name == message.name)
                properties = json.loads(schema.data)["properties"]
                assert set(properties) == {signal.name for signal in message.signals}
                for signal in message.signals:
                    assert properties[signal.name]["type"] == "number"
                    for value, choice in (signal.choices or {}).items():
                        assert f"{value} = {choice}" in properties[signal.name]["description"]
        count = 0
        for schema, channel, message in reader.iter_messages():
            assert channel.message_encoding == "json" and schema is not None
            document = json.loads(message.data)
            if None not in document.values():  # null marks a NaN signal (Foxglove rejects "type": ["number", "null"])
                validators[schema.id].validate(document)
            count += 1
        assert count == len(written.frames) + len(written.decoded) + len(written.steps)
        assert [a.name for a in reader.iter_attachments()] == summary_attachments(path)
        assert [m.name for m in reader.iter_metadata()] == ["bench", "bench.counts"]   # the counts at close


def summary_attachments(path: Path) -> list[str]:
    return summarise(path).attachments


def test_bad_input_raises_and_never_spoils_the_file(tmp_path: Path) -> None:
    databases, files = load_databases(tmp_path)
    message = databases[0].messages[0]
    path = tmp_path / "bad.mcap"
    with Recorder(path, databases, files) as recorder:
        with pytest.raises(LogError, match="NoSuchMessage"):
            recorder.decoded(0.0, "NoSuchMessage", {})
        with pytest.raises(LogError, match="NoSuchSignal"):
            recorder.decoded(0.0, message.name, {"NoSuchSignal": 1})
        with pytest.raises(LogError):
            recorder.decoded(0.0, message.name, {message.signals[0].name: "not a choice"})
        for t in (-1.0, float("nan"), float("inf")):
            with pytest.raises(LogError):
                recorder.frame(t, 1, b"", channel="can0", direction="rx")
        with pytest.raises(LogError):
            recorder.frame(0.0, 1, b"", channel="can0", direction="sideways")
        with pytest.raises(LogError):
            recorder.frame(0.0, 1 << 29, b"", channel="can0", direction="rx")
        with pytest.raises(LogError):
            recorder.frame(0.0, 1, bytes(65), channel="can0", direction="rx")
        with pytest.raises(LogError):
            recorder.step(0.0, 9, "x", "bad level")
        recorder.decoded(1.0, message.name, {message.signals[0].name: float("-inf")})
        recorder.frame(1.0, 1, b"\x01", channel="can0", direction="rx")
    recorder.close()  # idempotent
    assert [f.data for f in read_frames(path)] == [b"\x01"]
    assert [s for _, _, s in read_decoded(path)] == [{message.signals[0].name: None}]
    assert summarise(path).complete
    assert issubclass(LogError, BenchError)


def test_bad_files_raise_log_error(tmp_path: Path) -> None:
    with pytest.raises(LogError, match="missing.mcap"):
        summarise(tmp_path / "missing.mcap")
    (tmp_path / "text.mcap").write_text("not an mcap file at all")
    with pytest.raises(LogError, match="text.mcap"):
        list(read_frames(tmp_path / "text.mcap"))
    with pytest.raises(LogError, match="nope.dbc"):
        Recorder(tmp_path / "x.mcap", [], [tmp_path / "nope.dbc"])


@pytest.fixture(scope="module")
def small_chunks(tmp_path_factory: pytest.TempPathFactory) -> tuple[bytes, list[LoggedFrame], list[tuple[int, int]]]:
    """A log of many small chunks, its frames, and (end offset, last log time) of each chunk."""
    tmp = tmp_path_factory.mktemp("cut")
    path = tmp / "full.mcap"
    write_log(path, tmp, count=200, chunk_size=1500)
    with path.open("rb") as file:
        summary = make_reader(file).get_summary()
    assert summary is not None and len(summary.chunk_indexes) > 10
    ends = [(c.chunk_start_offset + c.chunk_length, c.message_end_time) for c in summary.chunk_indexes]
    return path.read_bytes(), list(read_frames(path)), ends


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(fraction=st.floats(0.0, 1.0))
def test_a_cut_file_gives_every_frame_of_its_whole_chunks(
    small_chunks: tuple[bytes, list[LoggedFrame], list[tuple[int, int]]], fraction: float, tmp_path: Path,
) -> None:
    full, frames, chunk_ends = small_chunks
    cut = int(fraction * len(full))
    path = tmp_path / "cut.mcap"
    path.write_bytes(full[:cut])
    got = list(read_frames(path))
    assert got == frames[: len(got)]
    last_time = max((end_time for end, end_time in chunk_ends if end <= cut), default=-1)
    assert got == [f for f in frames if f.t_ns <= last_time]
    summary = summarise(path)
    assert summary.complete == (cut == len(full))
    list(read_steps(path)), list(read_decoded(path))


def test_every_cut_of_the_head_is_tolerated(small_chunks: tuple[bytes, list[LoggedFrame], Any], tmp_path: Path) -> None:
    """Cuts inside the magic, header, attachments and metadata: an empty log, never an error."""
    full, _, chunk_ends = small_chunks
    path = tmp_path / "head.mcap"
    for cut in range(0, chunk_ends[0][0], 7):
        path.write_bytes(full[:cut])
        assert list(read_frames(path)) == [] and not summarise(path).complete


KILLED_WRITER = textwrap.dedent("""
    import sys, time
    from pathlib import Path
    import cantools
    from bench.log.recorder import Recorder
    databases = [cantools.database.load_string(sys.stdin.read(), "dbc")]
    recorder = Recorder(Path(sys.argv[1]), databases, flush_interval=0.2, chunk_size=1 << 30)  # time flushes only
    n = 0
    report = time.monotonic()
    while True:
        recorder.frame(n * 1e-4, 0x100, n.to_bytes(4, "little"), channel="can0", direction="tx")
        recorder.decoded(n * 1e-4, "SteerCmd", {"SteerAngle": n % 700, "Mode": 1, "Counter": n % 16})
        n += 1
        if time.monotonic() >= report:
            print(n, flush=True)  # n frames handed to the recorder so far
            report += 0.1
""")


@pytest.mark.skipif(sys.platform == "win32", reason="SIGKILL")
def test_a_killed_writer_leaves_a_readable_log(tmp_path: Path) -> None:
    """Every frame written more than flush_interval (0.2 s) + 0.1 s of slack before the kill is on disk.

    The child prints its count n at time t_n; the parent stamps the line when it reads it (never
    earlier than t_n). The chunk holding frame n is finalised and flushed at the first write after
    t_n + 0.2 s, so a count stamped 0.3 s before the kill must be on disk (95 % asked, 100 % expected).
    """
    path = tmp_path / "killed.mcap"
    child = subprocess.Popen([sys.executable, "-c", KILLED_WRITER, str(path)], stdin=subprocess.PIPE,
                             stdout=subprocess.PIPE, text=True, env={**os.environ, "PYTHONUNBUFFERED": "1"})
    assert child.stdin is not None and child.stdout is not None
    child.stdin.write(FALLBACK_DBC)
    child.stdin.close()
    counts: list[tuple[float, int]] = []
    try:
        while not counts or time.monotonic() - counts[0][0] < 1.5:
            line = child.stdout.readline()
            assert line, "the writer died"
            counts.append((time.monotonic(), int(line)))
        killed_at = time.monotonic()
        child.send_signal(signal.SIGKILL)
    finally:
        child.kill()
        child.wait()
    safe = max(n for stamp, n in counts if stamp <= killed_at - 0.3)
    frames = list(read_frames(path))
    assert len(frames) >= 0.95 * safe, (len(frames), safe, counts[-1])
    assert [int.from_bytes(f.data, "little") for f in frames] == list(range(len(frames)))
    summary = summarise(path)
    assert not summary.complete
    assert summary.frames == len(frames)
    assert len(list(read_decoded(path, "SteerCmd"))) >= 0.95 * safe


def test_close_is_idempotent_and_atexit_safe(tmp_path: Path) -> None:
    """A run that never closes its recorder still gets a complete file: close() runs at exit."""
    path = tmp_path / "atexit.mcap"
    code = textwrap.dedent("""
        import sys, cantools
        from pathlib import Path
        from bench.log.recorder import Recorder
        recorder = Recorder(Path(sys.argv[1]), [cantools.database.load_string(sys.stdin.read(), "dbc")])
        recorder.frame(0.5, 0x100, b"\\x01\\x02", channel="can0", direction="rx")
        sys.exit(0)
    """)
    subprocess.run([sys.executable, "-c", code, str(path)], input=FALLBACK_DBC, text=True, check=True)
    summary = summarise(path)
    assert summary.complete and summary.frames == 1


@pytest.mark.skipif(not hasattr(signal, "setitimer"), reason="needs SIGALRM")
@pytest.mark.parametrize("delay", [0.003, 0.011, 0.029])
def test_close_from_a_signal_handler_mid_write_leaves_a_complete_log(tmp_path: Path, delay: float) -> None:
    """The handler may interrupt a write anywhere: close() then waits for that write's end."""
    path = tmp_path / "signalled.mcap"
    recorder = Recorder(path, [cantools.database.load_string(FALLBACK_DBC, "dbc")], chunk_size=5000)
    previous = signal.signal(signal.SIGALRM, lambda *_: recorder.close())
    try:
        signal.setitimer(signal.ITIMER_REAL, delay)
        n = 0
        deadline = time.monotonic() + 5
        while not recorder._closed and time.monotonic() < deadline:
            recorder.frame(n * 1e-3, 0x100, n.to_bytes(4, "little"), channel="can0", direction="rx")
            recorder.decoded(n * 1e-3, "SteerCmd", {"SteerAngle": 1.5, "Mode": 1})
            n += 1
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
        recorder.close()
    frames = [int.from_bytes(f.data, "little") for f in read_frames(path)]
    assert frames == list(range(len(frames))) and len(frames) >= n - 1
    assert summarise(path).complete


def test_stream_is_valid_for_an_in_memory_reader(log: tuple[Path, Written]) -> None:
    """The bytes alone (no seeking by path) read with mcap's own seeking reader."""
    path, written = log
    reader = make_reader(io.BytesIO(path.read_bytes()))
    assert sum(1 for _ in reader.iter_messages(topics=[FRAMES_TOPIC])) == len(written.frames)


def test_fast_message_path_writes_what_mcaps_writer_writes(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The fast path (bench.log.mcapfast: one-pack message records and message indexes) writes mcap's own bytes:
    the same log written through mcap's public Writer.add_message is the same file, byte for byte (chunks,
    indexes, statistics and CRCs), with the creation time fixed."""
    from datetime import UTC, datetime

    from mcap.stream_reader import StreamReader

    import bench.log.mcapfast
    import bench.log.recorder

    class Fixed(datetime):
        @classmethod
        def now(cls, tz: Any = None) -> Fixed:
            return cls(2026, 1, 2, 3, 4, 5, tzinfo=UTC)

    monkeypatch.setattr(bench.log.recorder, "datetime", Fixed)
    taken: list[bool] = []
    fast_adder = bench.log.mcapfast.fast_adder

    def recording(writer: Any) -> Any:
        add = fast_adder(writer)
        taken.append(add is not None)
        return add

    monkeypatch.setattr(bench.log.mcapfast, "fast_adder", recording)
    fast, slow = tmp_path / "fast.mcap", tmp_path / "slow.mcap"
    write_log(fast, tmp_path, count=400, chunk_size=4096)
    assert taken == [True, True]   # the per-message and the batch adder: the fast path was taken
    monkeypatch.setattr(bench.log.mcapfast, "supported", lambda: False)
    write_log(slow, tmp_path, count=400, chunk_size=4096)
    assert taken[2:] == [False, False]   # mcap's public writer

    with fast.open("rb") as file:
        assert sum(type(r).__name__ == "Chunk" for r in StreamReader(file, emit_chunks=True).records) > 3
    assert fast.read_bytes() == slow.read_bytes()
    with fast.open("rb") as file:   # chunk CRCs and the summary's statistics hold
        reader = make_reader(file, validate_crcs=True)
        assert sum(1 for _ in reader.iter_messages()) == reader.get_summary().statistics.message_count


def test_the_pinned_mcap_is_the_one_the_fast_path_supports() -> None:
    """pyproject.toml pins mcap to the releases bench.log.mcapfast knows, and the installed one is among them
    (else the byte comparison above compared mcap's writer with itself)."""
    import tomllib
    from importlib.metadata import version

    from packaging.requirements import Requirement

    import bench.log.mcapfast
    from tests.repo import ROOT

    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    pins = [Requirement(r) for r in project["dependencies"] if Requirement(r).name == "mcap"]
    assert len(pins) == 1
    spec = pins[0].specifier
    assert version("mcap") in spec
    assert bench.log.mcapfast.supported()
    for prefix in bench.log.mcapfast.SUPPORTED:   # each supported release line lies inside the pin, and only those
        assert f"{prefix}0" in spec
    assert "1.5.0" not in spec and "1.7.0" not in spec


def test_the_summary_of_a_closed_log_is_read_from_its_index(log: tuple[Path, Written], tmp_path: Path) -> None:
    """`bench log info` in a few reads (issue 34: 12.4 s on a 50 MB log): the summary section and the invalid-frame
    count written at close give what reading every record gives; a cut log (no summary) is read record by record."""
    path, written = log
    assert logread._indexed_summary(path) is not None
    indexed = summarise(path)
    assert indexed == logread._scanned_summary(path)
    assert indexed.invalid_frames == sum(not f.valid for f in written.frames) > 0
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    assert logread._indexed_summary(cut) is None and not summarise(cut).complete
