"""hypothesis against the bench's input paths: frame decoding, the monitor, the run-log reader and
`bench dbc check`. None may raise anything but the bench's own errors, whatever bytes arrive.

Oracles are independent of the code under test: cantools decodes the same payload, the E2E checksum is
written here from its catalogue parameters (docs/spec/e2e.md), and the DBC ranges
come from cantools' parse of the file.
"""

from __future__ import annotations

import atexit
import functools
import math
import random
import shutil
import tempfile
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from bench.checks.monitor import Monitor
from bench.cli import main
from bench.database.check import check_text
from bench.database.codec import Codebook, load_codebook
from bench.database.errors import DecodeError
from bench.errors import BenchError
from bench.log.logread import MAGIC, read_decoded, read_frames, read_steps, summarise
from bench.log.recorder import Recorder
from tests.reference import COUNTER_VALUES, protected
from tests.repo import BENCH_DBC, CHASSIS_DBC

_CODEBOOK = load_codebook([CHASSIS_DBC, BENCH_DBC])
#: the periodic messages (the diagnostic ones are ISO-TP, judged by their framing: tests/bench/diag/)
CODECS = sorted((c for c in _CODEBOOK.by_id.values() if not c.diagnostic), key=lambda c: c.frame_id)
IDS = [c.frame_id for c in CODECS]
#: of the scale: the monitor's allowance for rounding at the range ends (bench.database.codec.RANGE_SLACK)
HALF_STEP = 0.5


def test_the_contract_messages_take_the_fast_path() -> None:
    """The fuzzing below covers the integer fast path; a database that needs cantools' path would change that."""
    assert CODECS and all(codec.fast and codec.length == 8 for codec in CODECS)


# -- MessageCodec.decode --------------------------------------------------------------------------------------
@settings(max_examples=400, deadline=None)
@given(st.sampled_from(CODECS), st.binary(min_size=8, max_size=8))
def test_decode_any_payload_of_the_right_length(codec: Any, data: bytes) -> None:
    values = codec.decode(data)
    assert list(values) == list(codec.signal_names)
    assert all(math.isfinite(v) for v in values.values())
    reference = codec.message.decode(data, decode_choices=False, scaling=True)
    for name, value in values.items():
        assert value == pytest.approx(float(reference[name]), rel=1e-12, abs=1e-9), name


@settings(max_examples=300, deadline=None)
@given(st.sampled_from(CODECS), st.binary(max_size=64))
def test_decode_other_lengths_raises_if_short_or_reads_cut(codec: Any, data: bytes) -> None:
    """What decode does with a wrong length (the monitor never asks it to, see below), as cantools does: a
    short payload raises the bench's DecodeError (a cantools DecodeError), a long one reads as if cut to the
    message's length."""
    assume(len(data) != codec.length)
    if len(data) < codec.length:
        with pytest.raises(DecodeError):
            codec.decode(data)
        return
    assert codec.decode(data) == codec.decode(data[: codec.length])


# -- the monitor ----------------------------------------------------------------------------------------------
class _Spy:
    """Wraps a codec's decode and records the lengths it was given."""

    def __init__(self, codec: Any, lengths: list[tuple[int, int]]) -> None:
        self.codec, self.decode, self.lengths = codec, codec.decode, lengths

    def __call__(self, data: bytes) -> dict[str, float]:
        self.lengths.append((len(data), self.codec.length))
        return self.decode(data)


@pytest.fixture(scope="module")
def spied() -> tuple[Codebook, list[tuple[int, int]]]:
    codebook = load_codebook([CHASSIS_DBC, BENCH_DBC])   # a private copy: its codecs get spies
    lengths: list[tuple[int, int]] = []
    for codec in codebook.by_id.values():
        try:
            codec.decode = _Spy(codec, lengths)  # type: ignore[method-assign]
        except AttributeError:   # a compiled codec (bench/compiled.py) takes no spy: CI runs this on the source
            pytest.skip("the codec is compiled and cannot be spied on; BENCH_COMPILED=0 runs this test")
    return codebook, lengths


FRAME = st.tuples(st.one_of(st.sampled_from(IDS), st.integers(0, 0x7FF)), st.binary(max_size=16),
                  st.floats(0.0, 0.05), st.booleans())


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(FRAME, max_size=30))
def test_monitor_decodes_only_frames_of_the_right_length(spied: tuple[Codebook, list[tuple[int, int]]],
                                                         frames: list[tuple[int, bytes, float, bool]]) -> None:
    codebook, lengths = spied
    lengths.clear()
    monitor = Monitor(codebook, keep_history=True)
    t = 0.0
    verdicts = []
    for frame_id, payload, dt, protect in frames:
        t += dt
        data = protected(frame_id, payload, len(verdicts)) if protect and len(payload) == 8 else payload
        verdicts.append(monitor.on_frame(t, frame_id, data, "rx"))
        codec = codebook.by_id.get(frame_id)
        if codec is not None and not codec.diagnostic and len(data) != codec.length:
            assert not verdicts[-1]
            assert monitor.invalid_log[-1].reason.startswith("length")
        monitor.check_timeouts(t)
    assert all(given_length == length for given_length, length in lengths)
    assert monitor.frames == len(frames)
    held_back = sum(state.starting for state in monitor.states.values())   # valid, not applied (E2E_SM INIT)
    assert monitor.invalid_frames + held_back == verdicts.count(False)


@settings(max_examples=400, deadline=None)
@given(st.sampled_from(CODECS), st.binary(min_size=8, max_size=8), st.integers(0, COUNTER_VALUES - 1))
def test_monitor_verdict_on_protected_random_payloads(codec: Any, payload: bytes, counter: int) -> None:
    """With a correct CRC, in sequence after a first frame (which is never applied, docs/spec/e2e.md), a frame
    is valid exactly when every signal cantools decodes lies in its DBC range (half a step of slack), and then
    its values are the ones applied."""
    data = protected(codec.frame_id, payload, counter)
    monitor = Monitor(_CODEBOOK)
    first = protected(codec.frame_id, payload, (counter - 1) % COUNTER_VALUES)
    assert not monitor.on_frame(0.99, codec.frame_id, first, "rx")
    valid = monitor.on_frame(1.0, codec.frame_id, data, "rx")
    decoded = codec.message.decode(data, decode_choices=False, scaling=True)
    in_range = all(
        (s.minimum is None or decoded[s.name] >= s.minimum - HALF_STEP * abs(s.scale)) and
        (s.maximum is None or decoded[s.name] <= s.maximum + HALF_STEP * abs(s.scale))
        for s in codec.message.signals)
    assert valid == in_range
    latest = monitor.latest(codec.name, 1.0)
    if valid:
        assert latest is not None and latest == pytest.approx({k: float(v) for k, v in decoded.items()})
    else:
        assert latest is None and monitor.invalid_log[-1].reason.startswith("range")


@settings(max_examples=200, deadline=None)
@given(st.sampled_from(CODECS),
       st.lists(st.tuples(st.binary(min_size=8, max_size=8), st.integers(0, COUNTER_VALUES - 1)),
                min_size=2, max_size=20))
def test_monitor_counter_check(codec: Any, frames: list[tuple[bytes, int]]) -> None:
    """CRCs right, counters random: a frame after a frame with counter c is rejected, by its AUTOSAR status,
    unless its counter is c + 1 or c + 2 (mod 15: OK or OKSOMELOST with MaxDeltaCounter 2)."""
    monitor = Monitor(_CODEBOOK)
    previous = None
    for i, (payload, counter) in enumerate(frames):
        valid = monitor.on_frame(i * 0.001, codec.frame_id, protected(codec.frame_id, payload, counter), "rx")
        if previous is not None and (counter - previous) % COUNTER_VALUES not in (1, 2):
            assert not valid
            status = "E2E REPEATED" if counter == previous else "E2E WRONGSEQUENCE"
            assert monitor.invalid_log[-1].reason.startswith(status)
        previous = counter


FOREIGN_DBC = """VERSION ""
BS_:
BU_: ECU
BO_ 256 Short: 4 ECU
 SG_ A : 0|16@1+ (1,0) [0|65535] "-" ECU
BO_ 257 Muxed: 8 ECU
 SG_ Sel M : 0|8@1+ (1,0) [0|255] "-" ECU
 SG_ B m1 : 8|16@1+ (1,0) [0|65535] "-" ECU
 SG_ C m2 : 8|16@1+ (1,0) [0|65535] "-" ECU
"""


@settings(max_examples=100, deadline=None, derandomize=True)
@given(st.sampled_from([256, 257]), st.binary(max_size=8))
def test_monitor_on_a_foreign_database(frame_id: int, data: bytes) -> None:
    import cantools

    codebook = Codebook([("foreign.dbc", cantools.database.load_string(FOREIGN_DBC, database_format="dbc"))])
    length = codebook.by_id[frame_id].length
    payload = (data + bytes(8))[:8]
    payload = protected(frame_id, payload, 0) if length == 8 else payload[:length]
    Monitor(codebook).on_frame(0.0, frame_id, payload, "rx")


# -- the run-log reader ---------------------------------------------------------------------------------------
_LOG_DIR = Path(tempfile.mkdtemp(prefix="bench-logread-fuzz-"))
atexit.register(shutil.rmtree, _LOG_DIR, ignore_errors=True)


@functools.cache
def small_log() -> bytes:
    """A real log with many small chunks (compressed): frames, decoded values and steps."""
    import cantools

    path = _LOG_DIR / "small.mcap"
    databases = [cantools.database.load_file(str(p)) for p in (CHASSIS_DBC, BENCH_DBC)]
    recorder = Recorder(path, databases, [], chunk_size=512)
    codec = _CODEBOOK["VCU_WheelCmd_FL"]
    for i in range(60):
        data = protected(codec.frame_id, bytes(8), i)
        recorder.frame(i * 0.01, codec.frame_id, data, channel="fuzz", direction="rx", valid=i % 7 != 0)
        recorder.decoded(i * 0.01, codec.name, codec.decode(data))
        if i % 20 == 0:
            recorder.step(i * 0.01, 2, "step", f"step {i}")
    recorder.close()
    return path.read_bytes()


def _write(data: bytes) -> Path:
    path = _LOG_DIR / "fuzz.mcap"
    path.write_bytes(data)
    return path


def _read_all(data: bytes) -> None:
    """Every reader of `bench.log.logread` on these bytes: a clean (possibly empty) iteration or a BenchError."""
    path = _write(data)
    for reader in (read_frames, read_decoded, read_steps):
        try:
            for _ in reader(path):
                pass
        except BenchError:
            pass
    try:
        summarise(path)
    except BenchError:
        pass


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=512))
def test_read_arbitrary_bytes(data: bytes) -> None:
    _read_all(data)


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=512))
def test_read_arbitrary_bytes_after_the_magic(data: bytes) -> None:
    _read_all(MAGIC + data)


def test_read_the_undamaged_small_log() -> None:
    assert len(list(read_frames(_write(small_log())))) == 60


@settings(max_examples=100, deadline=None, derandomize=True)
@given(st.data())
def test_read_a_damaged_log(data: st.DataObject) -> None:
    """A real log with bytes overwritten and a cut: never anything but a BenchError."""
    damaged = bytearray(small_log())
    for _ in range(data.draw(st.integers(1, 8), label="damages")):
        at = data.draw(st.integers(0, len(damaged) - 1), label="at")
        damaged[at] = data.draw(st.integers(0, 255), label="byte")
    cut = data.draw(st.integers(0, len(damaged)), label="cut")
    _read_all(bytes(damaged[:cut]))


# -- bench dbc check on mutations of the contract -------------------------------------------------------------
CONTRACT = CHASSIS_DBC.read_text(encoding="utf-8")
CONTRACT_LINES = CONTRACT.split("\n")
JUNK = st.sampled_from(list(' :|@+-()[],;"\'\\0123456789xX_ABCDEFGHIJKLMNOPQRSTUVWXYZ\t\x00é'))


@st.composite
def mutated_contract(draw: st.DrawFn) -> str:
    lines = list(CONTRACT_LINES)
    for _ in range(draw(st.integers(1, 6), label="mutations")):
        kind = draw(st.sampled_from(["delete", "flip", "duplicate", "swap"]), label="kind")
        i = draw(st.integers(0, len(lines) - 1), label="line")
        if kind == "delete":
            del lines[i]
        elif kind == "duplicate":
            lines.insert(i, lines[i])
        elif kind == "swap":
            j = draw(st.integers(0, len(lines) - 1), label="other line")
            lines[i], lines[j] = lines[j], lines[i]
        elif lines[i]:
            k = draw(st.integers(0, len(lines[i]) - 1), label="column")
            lines[i] = lines[i][:k] + draw(JUNK, label="char") + lines[i][k + 1:]
        if not lines:
            break
    return "\n".join(lines)


@settings(max_examples=100, deadline=None)
@given(mutated_contract())
def test_check_never_raises_on_a_mutated_contract(text: str) -> None:
    result = check_text(text, "chassis.dbc")
    for finding in result.findings:
        assert finding.severity in ("error", "warning") and finding.text
        assert finding.line is None or 1 <= finding.line <= text.count("\n") + 1


_CLI_DIR = Path(tempfile.mkdtemp(prefix="bench-dbccheck-fuzz-"))
atexit.register(shutil.rmtree, _CLI_DIR, ignore_errors=True)


@settings(max_examples=40, deadline=None)
@given(mutated_contract(), st.sampled_from(["utf-8", "cp1252"]))
def test_cli_check_on_a_mutated_contract(text: str, encoding: str) -> None:
    path = _CLI_DIR / "mutated.dbc"
    path.write_bytes(text.encode(encoding, errors="replace"))
    assert main(["dbc", "check", str(path)]) in (0, 1)


def test_mutations_do_get_rejected() -> None:
    """The mutation strategy is not toothless: most single character flips in signal lines are found."""
    rng = random.Random(8)
    rejected = 0
    sg_lines = [i for i, line in enumerate(CONTRACT_LINES) if line.startswith(" SG_ ")]
    for _ in range(20):
        lines = list(CONTRACT_LINES)
        i = rng.choice(sg_lines)
        k = lines[i].index(":") + 2          # the start bit
        lines[i] = lines[i][:k] + "9" + lines[i][k + 1:]
        rejected += not check_text("\n".join(lines)).accepted
    assert rejected >= 15
