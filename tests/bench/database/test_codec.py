"""The fast codec derived from the DBC agrees with cantools bit for bit on every message of the contract, and
never wraps a value its bit field cannot hold (tests/bench/database/test_codec_cantools.py: the same over cantools'
test DBCs)."""

from __future__ import annotations

import math

import cantools
import pytest
from cantools.database import errors as cantools_errors
from hypothesis import given, settings
from hypothesis import strategies as st

from bench.database.codec import Codebook, MessageCodec, load_codebook
from bench.database.errors import EncodeError
from bench.errors import SignalError
from tests.repo import BENCH_DBC, CHASSIS_DBC


def _values(codec: MessageCodec) -> st.SearchStrategy[dict[str, float]]:
    fields = {}
    for s in codec.signals:
        lo = -(1 << (s.length - 1)) if s.signed else 0
        hi = (1 << (s.length - 1)) - 1 if s.signed else (1 << s.length) - 1
        fields[s.name] = st.integers(lo, hi).map(lambda raw, s=s: raw * s.scale + s.offset)
    return st.fixed_dictionaries(fields)


MESSAGES = sorted(load_codebook([CHASSIS_DBC, BENCH_DBC]).by_name)


@pytest.mark.parametrize("name", MESSAGES)
def test_fast_path_matches_cantools(codebook: Codebook, name: str) -> None:
    codec = codebook[name]
    assert codec.fast, f"{name} should use the fast path"

    @settings(max_examples=60, deadline=None)
    @given(_values(codec))
    def check(values: dict[str, float]) -> None:
        ours = bytes(codec.encode(values))
        theirs = codec.message.encode(values, scaling=True, strict=False)
        assert ours == theirs
        decoded = codec.decode(ours)
        reference = codec.message.decode(theirs, decode_choices=False, scaling=True)
        assert decoded == reference   # exactly: the same arithmetic as cantools

    check()


def test_physical_refuses_nan_out_of_range_and_unknown(codebook: Codebook) -> None:
    codec = codebook["VCU_WheelCmd_FL"]
    with pytest.raises(SignalError, match="VCU_WheelCmd_FL.SteerAngleCmd.*finite"):
        codec.physical("SteerAngleCmd", math.nan)
    with pytest.raises(SignalError, match="outside the DBC range"):
        codec.physical("SteerAngleCmd", 120.0)
    with pytest.raises(SignalError, match="no signal 'Nope'"):
        codec.physical("Nope", 1.0)
    drive = codebook["DRV_MotionRequest"]
    assert drive.physical("DriveMode", "PIVOT") == 3.0
    with pytest.raises(SignalError, match="value table"):
        drive.physical("DriveMode", "WARP")


def test_start_values_lie_in_range(codebook: Codebook) -> None:
    for codec in codebook.by_id.values():
        values = codec.start_values()
        assert codec.out_of_range(values) == [], codec.name


def test_a_value_beyond_its_bit_field_raises_rather_than_wraps(codebook: Codebook) -> None:
    """SteerAngleCmd: 16 signed bits at 0.01 deg hold [-327.68, 327.67]; one step beyond used to wrap to the
    other end (327.68 went on the wire as -327.68)."""
    codec = codebook["VCU_WheelCmd_FL"]
    values = codec.start_values()
    assert codec.encode(values | {"SteerAngleCmd": 327.67})[:2] == b"\xff\x7f"
    assert codec.encode(values | {"SteerAngleCmd": -327.68})[:2] == b"\x00\x80"
    for beyond in (327.68, -327.69, 1e6):
        with pytest.raises(EncodeError, match=r"SteerAngleCmd = .* outside its 16-bit signed field") as caught:
            codec.encode(values | {"SteerAngleCmd": beyond})
        assert isinstance(caught.value, (SignalError, OverflowError, cantools_errors.EncodeError))


def test_strict_encoding_refuses_what_cantools_strict_refuses(codebook: Codebook) -> None:
    """strict=True: the DBC range [-90, 90] holds (cantools' EncodeError); the default leaves it to `checked`."""
    codec = codebook["VCU_WheelCmd_FL"]
    values = codec.start_values()
    assert codec.encode(values | {"SteerAngleCmd": 90.0}, strict=True)[:2] == (9000).to_bytes(2, "little")
    assert codec.encode(values | {"SteerAngleCmd": 90.01})[:2] == (9001).to_bytes(2, "little")
    with pytest.raises(cantools_errors.EncodeError, match="SteerAngleCmd"):
        codec.encode(values | {"SteerAngleCmd": 90.01}, strict=True)
    with pytest.raises(cantools_errors.EncodeError, match="not required"):
        codec.encode(values | {"Nope": 1.0}, strict=True)


def test_decode_of_the_same_payload_again_gives_the_same_values_as_a_new_dict(codebook: Codebook) -> None:
    """decode remembers the last payload (the sender's and receiver's monitors decode each frame in one
    process): a caller that changes its dict, or the bytearray it decoded, never changes a later decode."""
    codec = next(c for c in codebook.by_id.values() if c.fast and c.length == 8)
    payload = bytearray(range(1, 9))
    first = codec.decode(payload)
    expected = dict(first)
    first[next(iter(first))] = -12345.0
    again = codec.decode(bytes(payload))
    assert again == expected and again is not first
    payload[0] ^= 0xFF
    changed = codec.decode(payload)
    assert changed == codec.decode(bytes(payload)) == {s.name: v for s, v in zip(
        codec.signals, codec.message.decode(bytes(payload), decode_choices=False).values())} != expected


def test_text_for_a_signal_without_value_table_is_not_a_number(codebook: Codebook) -> None:
    """Issue 27, finding 3: `PivotX="5 m"` said "not in its value table (none)"; it is a number typed with its unit."""
    drive = codebook["DRV_MotionRequest"]
    with pytest.raises(SignalError) as raised:
        drive.physical("PivotX", "5 m")
    assert str(raised.value) == ("DRV_MotionRequest.PivotX: '5 m' is not a number (give a number in m; the signal "
                                 "has no value table)")
    with pytest.raises(SignalError, match=r"'PIVT' \(did you mean PIVOT\?\) is not in its value table \(.*PIVOT"):
        drive.physical("DriveMode", "PIVT")


# -- an OEM's inconsistent declarations (issue 33): judged as far as the frame carries them ----------------------
OEM_DBC = '''VERSION ""

NS_ :

BS_:

BU_: ECU

BO_ 256 Status: 8 ECU
 SG_ Speed : 0|16@1- (0.01,0) [-400|400] "m/s" ECU
 SG_ Level : 16|8@1+ (1,0) [0|250] "-" ECU

BA_DEF_ SG_  "GenSigStartValue" INT -2147483648 2147483647;
BA_DEF_DEF_  "GenSigStartValue" 0;
BA_ "GenSigStartValue" SG_ 256 Level 254;
'''


def _oem_status() -> MessageCodec:
    database = cantools.database.load_string(OEM_DBC, database_format="dbc")
    assert isinstance(database, cantools.database.can.Database)
    return Codebook([("oem.dbc", database)])["Status"]


def test_a_range_wider_than_its_field_is_judged_as_far_as_the_field_carries() -> None:
    """[-400|400] on a 16-bit signed field at 0.01 (which carries -327.68..327.67): 330 is refused when set, with
    the DBC's range and the reason, rather than accepted and failing at the next frame's encoding."""
    codec = _oem_status()
    assert codec.physical("Speed", 327.67) == 327.67 and codec.physical("Speed", -327.68) == -327.68
    with pytest.raises(SignalError) as error:
        codec.physical("Speed", 330.0)
    text = str(error.value)
    assert "[-327.68, 327.67]" in text and "the DBC declares [-400, 400]" in text and "16-bit signed" in text
    assert codec.out_of_range(codec.decode(codec.encode({"Speed": -327.68, "Level": 3}))) == []


def test_a_start_value_outside_the_range_starts_at_its_end() -> None:
    """GenSigStartValue 254 for a range [0|250]: the restbus starts at 250 and the first frame is sent."""
    codec = _oem_status()
    start = codec.start_values()
    assert start == {"Speed": 0.0, "Level": 250.0}
    assert codec.decode(codec.encode(codec.checked(start)))["Level"] == 250.0
