"""The codec's decode cache (one entry per message, keyed by the payload without its E2E counter and CRC) gives
what cantools decodes for any sequence of frames, and `decode_checked` names exactly the signals outside the DBC
range (with its half-step slack), whichever frame of a payload came first."""

from __future__ import annotations

from typing import Any, cast

import cantools
import pytest
from cantools.database.can import Database, Message
from hypothesis import given, settings
from hypothesis import strategies as st

from bench.database.codec import RANGE_SLACK, MessageCodec, load_codebook
from bench.database.errors import DecodeError
from tests.reference import COUNTER_VALUES, contract_checksum
from tests.repo import BENCH_DBC, CHASSIS_DBC

CODEBOOK = load_codebook([CHASSIS_DBC, BENCH_DBC])

# A message without E2E protection (no E2E attributes) with signals named AliveCounter and Checksum: ordinary
# signals then, and a Checksum whose DBC range leaves out part of its field, and a signal whose range leaves out
# raw values: the cache must not skip the range check of either.
NARROW_DBC = """VERSION ""
BU_: A B
BO_ 291 Narrow: 8 A
 SG_ Level : 0|8@1+ (0.5,-10) [-10|100] "-" B
 SG_ Flag : 8|2@1+ (1,0) [0|2] "-" B
 SG_ AliveCounter : 48|4@1+ (1,0) [0|15] "-" B
 SG_ Checksum : 56|8@1+ (1,0) [0|200] "-" B
"""
_NARROW_DB = cantools.database.load_string(NARROW_DBC, database_format="dbc")
assert isinstance(_NARROW_DB, Database)
NARROW = MessageCodec(_NARROW_DB.get_message_by_name("Narrow"), "narrow.dbc")
CODECS = {**CODEBOOK.by_name, "Narrow": NARROW}


def _reference(message: Message, data: bytes) -> tuple[dict[str, float], list[str]]:
    """cantools' values, and the signals outside [minimum, maximum] by more than half a step."""
    values = cast(dict[str, Any], message.decode(data[: message.length], decode_choices=False, scaling=True))
    bad = []
    for s in message.signals:
        slack = RANGE_SLACK * abs(float(s.scale))
        v = float(values[s.name])
        if (s.minimum is not None and v < s.minimum - slack) or (s.maximum is not None and v > s.maximum + slack):
            bad.append(s.name)
    return {k: float(v) for k, v in values.items()}, bad


@st.composite
def _frames(draw: st.DrawFn) -> tuple[str, list[bytes | bytearray]]:
    """A message and frames of it: a few bodies, each sent with many counters and checksums, as bytes, as a
    bytearray or with bytes after the message's end."""
    name = draw(st.sampled_from(sorted(CODECS)))
    length = CODECS[name].length
    bodies = draw(st.lists(st.binary(min_size=length, max_size=length), min_size=1, max_size=3))
    frames: list[bytes | bytearray] = []
    for _ in range(draw(st.integers(1, 30))):
        frame = bytearray(draw(st.sampled_from(bodies)))
        if length == 8:     # the contract's header: the CRC in byte 6, the counter in the low nibble of byte 7
            frame[7] = (frame[7] & 0xF0) | draw(st.integers(0, COUNTER_VALUES - 1))
            frame[6] = draw(st.integers(0, 255))
        form = draw(st.sampled_from(["bytes", "bytearray", "longer"]))
        frames.append(bytes(frame) if form == "bytes" else frame if form == "bytearray" else bytes(frame) + b"\x55")
    return name, frames


@settings(max_examples=400, deadline=None)
@given(_frames())
def test_decode_and_range_equal_cantools_for_any_frame_sequence(case: tuple[str, list[bytes | bytearray]]) -> None:
    name, frames = case
    codec = CODECS[name]
    for data in frames:
        expected, expected_bad = _reference(codec.message, bytes(data))
        values, bad = codec.decode_checked(data)
        assert values == expected and list(values) == list(expected)
        assert list(bad) == expected_bad
        assert codec.decode(data) == expected
        if isinstance(data, bytearray):       # the caller may reuse its buffer: the cache keeps no reference
            data[0] ^= 0xFF
            assert codec.decode(bytes(data)) == _reference(codec.message, bytes(data))[0]


def test_the_narrow_checksum_is_checked_on_every_frame() -> None:
    """A Checksum whose range leaves out part of its field (of an unprotected message: an ordinary signal) is
    judged on every frame: the same body with an out-of-range Checksum after an in-range one is still refused."""
    assert NARROW.protection is None
    good = bytes([40, 1, 0, 0, 0, 0, 3, 100])
    bad = bytes([40, 1, 0, 0, 0, 0, 4, 250])
    assert NARROW.decode_checked(good)[1] == ()
    assert NARROW.decode_checked(bad)[1] == ("Checksum",)
    assert NARROW.decode_checked(good)[1] == ()


def test_a_short_frame_is_refused_after_a_cached_one() -> None:
    codec = CODEBOOK["VCU_WheelCmd_FL"]
    data = bytes(8)
    codec.decode_checked(data)
    with pytest.raises(DecodeError):
        codec.decode_checked(data[:7])
    with pytest.raises(DecodeError):
        codec.decode(data[:7])


PERIODIC = sorted(n for n, c in CODEBOOK.by_name.items() if not c.diagnostic)   # (diagnostic ones carry no E2E)


@settings(max_examples=200, deadline=None)
@given(st.sampled_from(PERIODIC), st.lists(st.binary(min_size=8, max_size=8), min_size=1, max_size=8),
       st.lists(st.tuples(st.integers(0, 7), st.booleans()), min_size=1, max_size=200))
def test_the_e2e_check_is_remembered_per_frame_only(name: str, pool: list[bytes],
                                                    picks: list[tuple[int, bool]]) -> None:
    """The codec's memo of the E2E check (frames repeat: both monitors, and one frame per counter value of an
    unchanged payload) gives the Profile 11 check's answer for every frame, right CRCs and wrong, bytes and
    bytearray."""
    codec = CODEBOOK[name]
    frames = [f[:6] + bytes((contract_checksum(codec.frame_id, f),)) + f[7:] if i % 2 else f
              for i, f in enumerate(pool)]
    for index, as_bytearray in picks:
        data = frames[index % len(frames)]
        right = data[6] == contract_checksum(codec.frame_id, data) and data[7] & 0x0F < COUNTER_VALUES
        expected = data[7] & 0x0F if right else None
        assert codec.counter_if_intact(bytearray(data) if as_bytearray else data) == expected
