"""The bench's codec equals cantools bit for bit, or raises where cantools raises (issue 14).

Corpus: `../shared/corpus/dbc` beside the repository (the DBC files of cantools' own test suite). When it
is absent, its cases are skipped saying so and only the project's DBCs (chassis.dbc, bench.dbc) are compared.

Which messages: `bench dbc check` accepts no corpus file that has a message (each lacks a cycle time at
least; tests/bench/database/test_dbc_check.py), so "the messages the bench accepts" would be none. The codec is built
for every message of every DBC the bench can load (`bench.database.codec.load_dbc`: cantools' strict load, as for
a configured database), so every such message is compared: big-endian, signed, float, multiplexed
(cascaded too), value tables, 63- and 64-bit, CAN FD. The files the bench cannot load have no codec; they
are listed (UNLOADABLE) so that none is left out silently.

Oracle: cantools `Message.encode(values, scaling=True, strict=False)` for the bench's default `encode`,
`strict=True` for `encode(..., strict=True)`, `Message.decode(data, decode_choices=False)` for `decode`.
Equal means: the same bytes; decoded values numerically equal with the same sign (NaN for NaN); when
cantools raises, the bench raises an instance of the same class (its own errors subclass cantools' and
the builtin ones cantools raises).

Inputs: numbers (int, float, NaN, infinities), value-table names and a signal left out, at and around each
signal's limits (DBC minimum and maximum, just inside and outside cantools' strict tolerance, the raw
field's ends and one beyond, half-way roundings, multiplexer values in and out of the table), and payloads
of the message's length and of every length around it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from fractions import Fraction
from pathlib import Path
from typing import Any

import cantools
import pytest
from cantools.database.can import Message, Signal
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from bench.database.codec import MessageCodec, load_dbc
from bench.database.errors import DecodeError, EncodeError
from bench.errors import DatabaseError
from tests.repo import BENCH_DBC, CHASSIS_DBC, ROOT

CORPUS = ROOT.parent / "shared" / "corpus" / "dbc"
CORPUS_FILES = sorted(p for p in CORPUS.iterdir() if p.is_file()) if CORPUS.is_dir() else []
NO_CORPUS = f"no DBC corpus at {CORPUS} (../shared/corpus/dbc beside the repository): only the project's DBCs"

# Files the bench cannot load (cantools' strict load refuses them), from reading them.
UNLOADABLE = {
    "LICENSE-cantools",           # not a DBC
    "bad_message_length.dbc",     # Signal1 at bit 8 of a 1-byte message
    "issue_63.dbc",               # HtrRes and MaxRes overlap
    "issue_199.dbc",              # a standard identifier wider than 11 bits
    "issue_199_extended.dbc",     # the same
}

MISSING = object()   # a signal left out of the values


def _load(paths: list[Path]) -> tuple[list[MessageCodec], set[str]]:
    codecs, refused = [], set()
    for path in paths:
        try:
            database = load_dbc(path)
        except DatabaseError:
            refused.add(path.name)
            continue
        codecs.extend(MessageCodec(message, path.name) for message in database.messages)
    return codecs, refused


# Shapes the corpus lacks on the fast path (little-endian integers): a negative scale without an offset (the
# sign of a zero), integer scales and offsets (cantools computes those in integers), values beyond 2**53.
HANDWRITTEN = """VERSION ""
NS_ :
BS_:
BU_: ECU
BO_ 256 Negative: 8 ECU
 SG_ Down : 0|8@1+ (-0.5,0) [-127.5|0] "" ECU
 SG_ DownSigned : 8|12@1- (-0.25,0) [-512|511.75] "" ECU
 SG_ Plain : 20|4@1+ (1,0) [0|15] "" ECU
BO_ 257 IntegerScale: 8 ECU
 SG_ Stepped : 0|8@1- (3,-7) [-391|374] "" ECU
 SG_ Wide : 8|48@1+ (1000,0) [0|281474976710655000] "" ECU
 SG_ Huge : 56|8@1+ (1,100000000000000000) [0|0] "" ECU
BO_ 258 Exact: 8 ECU
 SG_ Exact52 : 0|52@1- (1,0) [0|0] "" ECU
 SG_ Exact12 : 52|12@1+ (4,-3) [0|0] "" ECU
"""
SYNTHETIC = [MessageCodec(m, "handwritten") for m in cantools.database.load_string(HANDWRITTEN, "dbc").messages]
PROJECT, _ = _load([CHASSIS_DBC, BENCH_DBC])     # the project's own messages are compared too, always
CORPUS_CODECS, REFUSED = _load(CORPUS_FILES)
CODECS = PROJECT + SYNTHETIC + CORPUS_CODECS
IDS = [f"{c.database}:{c.name}" for c in CODECS]


def test_the_corpus_is_beside_the_repository() -> None:
    """Without ../shared/corpus the corpus's messages are not collected at all (the comparisons below shrink to
    the project's and the handwritten ones): this skip says so in the test summary instead of a silent drop."""
    if not CORPUS_FILES:
        pytest.skip(NO_CORPUS)
    assert CORPUS_CODECS, f"{CORPUS}: no message of the corpus loads"


# -- outcomes -------------------------------------------------------------------------------------------------
def _outcome(call: Callable[[], Any]) -> tuple[str, Any]:
    try:
        return "ok", call()
    except Exception as exc:  # noqa: BLE001 - the class is what is compared
        return "raised", exc


def _same_number(ours: Any, theirs: Any) -> bool:
    if isinstance(theirs, float) and math.isnan(theirs):
        return isinstance(ours, float) and math.isnan(ours)
    return ours == theirs and math.copysign(1, ours) == math.copysign(1, theirs)


def _assert_same(ours: tuple[str, Any], theirs: tuple[str, Any], what: str) -> None:
    if theirs[0] == "raised":
        assert ours[0] == "raised", f"{what}: cantools raises {theirs[1]!r}, the bench gives {ours[1]!r}"
        assert isinstance(ours[1], type(theirs[1])), (
            f"{what}: cantools raises {type(theirs[1]).__name__} ({theirs[1]}), the bench "
            f"{type(ours[1]).__name__} ({ours[1]})")
        return
    assert ours[0] == "ok", f"{what}: cantools gives {theirs[1]!r}, the bench raises {ours[1]!r}"
    if isinstance(theirs[1], bytes):
        assert bytes(ours[1]) == theirs[1], f"{what}: bench {bytes(ours[1]).hex()} != cantools {theirs[1].hex()}"
        return
    assert list(ours[1]) == list(theirs[1]), what
    for name, value in theirs[1].items():
        assert _same_number(ours[1][name], value), f"{what}: {name} bench {ours[1][name]!r} != cantools {value!r}"


def compare_encode(codec: MessageCodec, values: dict[str, Any]) -> None:
    values = {k: v for k, v in values.items() if v is not MISSING}
    message = codec.message
    for strict in (False, True):
        theirs = _outcome(lambda strict=strict: message.encode(dict(values), scaling=True, strict=strict))
        ours = _outcome(lambda strict=strict: codec.encode(dict(values), strict=strict) if strict
                        else codec.encode(dict(values)))
        _assert_same(ours, theirs, f"encode(strict={strict}) {values}")
        if theirs[0] == "ok" and not strict:   # and what was encoded decodes alike
            compare_decode(codec, theirs[1])


def compare_decode(codec: MessageCodec, data: bytes) -> None:
    theirs = _outcome(lambda: codec.message.decode(data, decode_choices=False, scaling=True))
    ours = _outcome(lambda: codec.decode(data))
    _assert_same(ours, theirs, f"decode {data.hex()}")


# -- values, written from the DBC's numbers (not from the codec) ----------------------------------------------
def _raw_range(signal: Signal) -> tuple[int, int]:
    if signal.is_signed:
        return -(1 << (signal.length - 1)), (1 << (signal.length - 1)) - 1
    return 0, (1 << signal.length) - 1


def _physical(signal: Signal, raw: int | Fraction) -> int | float:
    """raw * scale + offset exactly, as an int when it is one (a caller may pass ints), else the nearest float."""
    value = Fraction(raw) * Fraction(signal.scale) + Fraction(signal.offset)
    return int(value) if value.denominator == 1 and Fraction(signal.scale).denominator == 1 \
        and Fraction(signal.offset).denominator == 1 else float(value)


def _mux_ids(message: Message, mux: Signal) -> list[int]:
    return sorted({i for s in message.signals if s.multiplexer_signal == mux.name for i in s.multiplexer_ids or ()})


def _neutral(message: Message, signal: Signal) -> int | float:
    """A value cantools' strict encode accepts: the first multiplexer id, else a raw value inside the range."""
    if signal.is_multiplexer:
        ids = _mux_ids(message, signal)
        return _physical(signal, ids[0]) if ids else 0
    if signal.is_float:
        return signal.minimum if signal.minimum is not None else 0.0
    lo, hi = _raw_range(signal)
    low = signal.minimum if signal.minimum is not None else -math.inf
    high = signal.maximum if signal.maximum is not None else math.inf
    targets = [0] + [Fraction(x) for x in (signal.minimum, signal.maximum) if x is not None]
    for target in targets:
        raw = (Fraction(target) - Fraction(signal.offset)) / Fraction(signal.scale)
        for candidate in (math.floor(raw), math.ceil(raw)):
            candidate = min(max(candidate, lo), hi)
            if low <= _physical(signal, candidate) <= high:
                return _physical(signal, candidate)
    return _physical(signal, min(max(0, lo), hi))


def _edges(message: Message, signal: Signal) -> list[Any]:
    """Values at and around the limits of one signal."""
    out: list[Any] = [math.nan, math.inf, -math.inf, MISSING, "NoSuchChoice"]
    out += [str(name) for name in (signal.choices or {}).values()]
    for limit in (signal.minimum, signal.maximum):
        if limit is not None:
            tiny = abs(signal.scale) * 1e-7
            step = 1e-5 * abs(signal.scale)
            out += [limit, limit - tiny, limit + tiny, limit - step, limit + step]
    if signal.is_float:
        out += [0.0, -0.0, 1.5, 3.4e38, 3.5e38, 1e39, -1e39, 1e308, 5e-324, 2**64, -(2**64)]
        return out
    lo, hi = _raw_range(signal)
    for raw in (lo, hi, lo - 1, hi + 1, 0, 1, -1):
        out.append(_physical(signal, raw))
        out.append(float(_physical(signal, raw)))
    for raw in (Fraction(2 * lo - 1, 2), Fraction(2 * hi + 1, 2), Fraction(2 * lo + 1, 2), Fraction(2 * hi - 1, 2)):
        out.append(_physical(signal, raw))   # half-way: cantools rounds half to even
    if signal.is_multiplexer:
        ids = _mux_ids(message, signal)
        out += [_physical(signal, i) for i in ids]
        out += [_physical(signal, i) for i in (max(ids, default=0) + 1, min(ids, default=0) - 1) if lo <= i <= hi]
    return out


def _neutral_values(message: Message) -> dict[str, Any]:
    return {s.name: _neutral(message, s) for s in message.signals}


def _bits(signal: Signal) -> list[int]:
    """Byte-major bit numbers (byte * 8 + bit, bit 0 the least significant) of the signal, least significant
    first; Motorola signals run from the most significant bit down the DBC's sawtooth."""
    if signal.byte_order == "little_endian":
        return list(range(signal.start, signal.start + signal.length))
    bits, position = [], signal.start
    for _ in range(signal.length):
        bits.append(position)
        position = position + 15 if position % 8 == 0 else position - 1
    return bits[::-1]


def _payload(length: int, bits: list[int]) -> bytes:
    data = bytearray(length)
    for bit in bits:
        data[bit // 8] |= 1 << (bit % 8)
    return bytes(data)


def _edge_payloads(message: Message) -> list[bytes]:
    n = message.length
    out = [bytes(n), b"\xff" * n, b"\x55" * n, b"\xaa" * n, b"\xff" * (n + 3), b"\xff" * max(n - 1, 0), b""]
    for signal in message.signals:
        bits = _bits(signal)
        out += [_payload(n, bits), _payload(n, bits[-1:]), _payload(n, bits[:1]), _payload(n, bits[:-1])]
    return out


# -- the comparisons ------------------------------------------------------------------------------------------
@pytest.mark.skipif(not CORPUS_FILES, reason=NO_CORPUS)
def test_the_corpus_loads_as_expected() -> None:
    """Files are left out only when the bench cannot load them at all (so nothing is skipped silently)."""
    assert REFUSED == UNLOADABLE
    assert len(CORPUS_CODECS) > 400
    kinds = {
        "big-endian": any(s.byte_order == "big_endian" for c in CODECS for s in c.message.signals),
        "float": any(s.is_float for c in CODECS for s in c.message.signals),
        "multiplexed": any(c.message.is_multiplexed() for c in CODECS),
        "64-bit": any(s.length == 64 and not s.is_float for c in CODECS for s in c.message.signals),
        "value tables": any(s.choices for c in CODECS for s in c.message.signals),
        "fast path": any(c.fast for c in CORPUS_CODECS),
    }
    assert all(kinds.values()), kinds


@pytest.mark.parametrize("codec", CODECS, ids=IDS)
def test_edges_equal_cantools(codec: MessageCodec) -> None:
    message = codec.message
    base = _neutral_values(message)
    compare_encode(codec, base)
    for signal in message.signals:
        for value in _edges(message, signal):
            compare_encode(codec, {**base, signal.name: value})
    for data in _edge_payloads(message):
        compare_decode(codec, data)


def _value(message: Message, signal: Signal) -> st.SearchStrategy[Any]:
    span = abs(signal.maximum - signal.minimum) if signal.minimum is not None and signal.maximum is not None else 0
    around = [st.just(math.nan), st.just(math.inf), st.just(-math.inf), st.just(MISSING)]
    if signal.choices:
        around.append(st.sampled_from([str(n) for n in signal.choices.values()] + ["NoSuchChoice"]))
    if signal.minimum is not None and signal.maximum is not None:
        around.append(st.floats(float(signal.minimum - span - 1), float(signal.maximum + span + 1)))
    if signal.is_float:
        return st.one_of(st.floats(width=signal.length), st.floats(), st.integers(-(2**70), 2**70), *around)
    lo, hi = _raw_range(signal)
    raw = st.integers(lo - 3, hi + 3)
    ids = _mux_ids(message, signal) if signal.is_multiplexer else []
    strategies = [raw.map(lambda r: _physical(signal, r)),
                  raw.map(lambda r: float(_physical(signal, r))),
                  raw.map(lambda r: _physical(signal, Fraction(2 * r + 1, 2))),
                  st.floats(allow_nan=False), *around]
    if ids:
        strategies.append(st.sampled_from(ids).map(lambda r: _physical(signal, r)))
    return st.one_of(*strategies)


@pytest.mark.parametrize("codec", CODECS, ids=IDS)
def test_hypothesis_equals_cantools(codec: MessageCodec) -> None:
    message = codec.message
    n = message.length

    # No shrinking: when the codec breaks, it breaks on hundreds of messages, and shrinking each takes seconds.
    @settings(max_examples=50, deadline=None, database=None, phases=[Phase.explicit, Phase.generate],
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
    @given(values=st.fixed_dictionaries({s.name: _value(message, s) for s in message.signals}),
           data=st.binary(min_size=n, max_size=n), other=st.binary(max_size=n + 8))
    def check(values: dict[str, Any], data: bytes, other: bytes) -> None:
        compare_encode(codec, values)
        compare_decode(codec, data)
        compare_decode(codec, other)

    check()


# -- the regressions of issue 14 ------------------------------------------------------------------------------
def test_the_project_messages_take_the_fast_path() -> None:
    assert PROJECT and all(c.fast for c in PROJECT)


def test_the_fast_path_is_taken_only_where_doubles_are_exact() -> None:
    """Negative and Exact fit in doubles (fast path); IntegerScale's Wide and Huge do not (cantools' path)."""
    assert {c.name: c.fast for c in SYNTHETIC} == {"Negative": True, "IntegerScale": False, "Exact": True}
    negative = next(c for c in SYNTHETIC if c.name == "Negative")
    assert math.copysign(1, negative.decode(bytes(8))["Down"]) == 1.0   # cantools: 0 * -0.5 + 0 is +0.0


def _codec(file: str, message: str) -> MessageCodec:
    return next(c for c in CODECS if c.database == file and c.name == message)


@pytest.mark.skipif(not CORPUS_FILES, reason=NO_CORPUS)
def test_a_value_outside_its_bit_field_raises_rather_than_wraps() -> None:
    """vehicle.dbc declares Accel_Longitudinal [-65|65] in 16 signed bits at 0.001: -65 is raw -65000."""
    codec = _codec("vehicle.dbc", "RT_SB_Accel")
    assert codec.fast
    values = {s.name: 0 for s in codec.message.signals} | {"Accel_Longitudinal": -65}
    with pytest.raises(OverflowError):
        codec.message.encode(values, strict=False)
    with pytest.raises(EncodeError, match=r"Accel_Longitudinal.*-65000.*16-bit signed"):
        codec.encode(values)
    assert codec.encode(values | {"Accel_Longitudinal": -32.768}) == b"\x00\x00\x00\x80\x00\x00\x00\x00"


@pytest.mark.skipif(not CORPUS_FILES, reason=NO_CORPUS)
def test_a_64_bit_maximum_keeps_every_bit() -> None:
    """padding_bit_order.dbc MSG4.M: 64 unsigned bits, maximum 2**64 - 1; a double would make that 2**64."""
    codec = _codec("padding_bit_order.dbc", "MSG4")
    assert codec.encode({"M": 2**64 - 1}) == b"\xff" * 8
    assert codec.decode(b"\xff" * 8) == {"M": 2**64 - 1}
    assert codec.decode(b"\xfe" + b"\xff" * 7)["M"] == 2**64 - 2
    with pytest.raises(EncodeError):
        codec.encode({"M": 2**64})


@pytest.mark.skipif(not CORPUS_FILES, reason=NO_CORPUS)
def test_a_short_payload_raises_a_long_one_is_cut() -> None:
    codec = _codec("vehicle.dbc", "RT_SB_Accel")
    with pytest.raises(DecodeError, match="7 bytes"):
        codec.decode(bytes(7))
    assert codec.decode(bytes(8) + b"\xff") == codec.decode(bytes(8))
