"""The fast codec derived from the DBC agrees with cantools bit for bit on every message."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bench.codec import Codebook, MessageCodec, load_codebook
from bench.errors import SignalError
from bench.paths import BENCH_DBC, CHASSIS_DBC


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
        for key, value in reference.items():
            assert math.isclose(decoded[key], float(value), rel_tol=1e-12, abs_tol=1e-12), key

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
