"""The one fast path of bench.e2e (Profiles 1 and 11, DataIDMode BOTH, through the library's CRC-8 in one call)
against the public path: autosar-e2e's own profile functions, for every header offset, protected length, counter
and Data ID. Expected bytes come from the library, never from bench.e2e."""

from __future__ import annotations

from e2e import p01, p11
from hypothesis import given, settings
from hypothesis import strategies as st

from bench.e2e import Protection

LIBRARY = {"P01": (p01.e2e_p01_protect, p01.e2e_p01_check), "P11": (p11.e2e_p11_protect, p11.e2e_p11_check)}


@settings(max_examples=400, deadline=None)
@given(profile=st.sampled_from(["P01", "P11"]), offset_byte=st.integers(0, 6), whole=st.booleans(),
       data_id=st.integers(0, 0xFFFF), counter=st.integers(0, 14), payload=st.binary(min_size=8, max_size=8),
       flip=st.integers(0, 63))
def test_fast_path_writes_and_judges_the_library_bytes(profile: str, offset_byte: int, whole: bool, data_id: int,
                                                       counter: int, payload: bytes, flip: int) -> None:
    length = 0 if whole else 8
    protection = Protection(profile, data_id=data_id, offset=8 * offset_byte, length=length)
    ours = bytearray(payload)
    protection.protect(ours, counter)
    library_protect, library_check = LIBRARY[profile]
    theirs = bytearray(payload)
    theirs[offset_byte + 1] = (theirs[offset_byte + 1] & 0xF0) | counter
    library_protect(theirs, data_id, offset=offset_byte, length=length, increment_counter=False)
    assert ours == theirs
    assert protection.counter_if_intact(bytes(ours)) == counter
    damaged = bytearray(ours)
    damaged[flip // 8] ^= 1 << (flip % 8)
    intact = library_check(bytearray(damaged), data_id, offset=offset_byte, length=length)
    assert (protection.counter_if_intact(bytes(damaged)) is not None) == intact
