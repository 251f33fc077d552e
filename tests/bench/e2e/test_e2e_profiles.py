"""Interoperability per supported profile (issue 24, acceptance 2): the bench and an AUTOSAR stack configured
with the same parameters speak the same bytes.

The other side is the `autosar-e2e` library (import `e2e`), called here directly, as a supplier's test would:
thousands of frames it protects (its own counter handling, `increment_counter=True`, wraps included) are
accepted by bench.e2e.Receiver fed through bench.e2e.Protection.counter_if_intact, every frame the bench
protects passes the library's check, and corrupted, masquerading (a frame judged by another message's
parameters), repeated, skipped and stale frames are rejected with the AUTOSAR status name. The parameters come
from a database (a DBC of this file with P01, P02, P05 and P11 attributes; the contract's chassis.dbc for the
contract's Profile 11). Profile 11's CRC is also computed independently (tests/reference.py).
"""

from __future__ import annotations

import random
from collections.abc import Callable
from pathlib import Path

import pytest
from e2e import crc, p01, p02, p05, p11
from hypothesis import given
from hypothesis import strategies as st

from bench import e2e as bench_e2e
from bench.database.codec import Codebook, load_codebook
from tests.reference import crc8_j1850_p11, p11_crc
from tests.repo import E2E_ATTRIBUTE_DEFINITIONS

FRAMES = 3000          # per profile: 200 wraps of a 15-value counter, 11 of P05's 256
DATA_ID_LIST = "11 22 33 44 55 66 77 88 99 AA BB CC DD EE F0 0F"

#: A database of this test's own: one message per profile and mode, its parameters in the DBC attributes
#: (docs/spec/e2e.md "Where a message's protection comes from"; enum indexes: Profile None P01 P02 P05 P11,
#: DataIDMode BOTH ALT LOW NIBBLE).
PROFILES_DBC = f'''VERSION ""

NS_ :

BS_:

BU_: ECU

BO_ 291 Msg_P01: 8 ECU
 SG_ Crc : 8|8@1+ (1,0) [0|255] "" Vector__XXX
 SG_ Counter : 16|4@1+ (1,0) [0|14] "" Vector__XXX
 SG_ Value : 24|16@1+ (1,0) [0|65535] "" Vector__XXX

BO_ 292 Msg_P11_Nibble: 8 ECU
 SG_ Crc : 0|8@1+ (1,0) [0|255] "" Vector__XXX
 SG_ Counter : 8|4@1+ (1,0) [0|14] "" Vector__XXX
 SG_ Value : 16|16@1+ (1,0) [0|65535] "" Vector__XXX

BO_ 293 Msg_P02: 8 ECU
 SG_ Crc : 0|8@1+ (1,0) [0|255] "" Vector__XXX
 SG_ Counter : 8|4@1+ (1,0) [0|15] "" Vector__XXX
 SG_ Value : 16|16@1+ (1,0) [0|65535] "" Vector__XXX

BO_ 294 Msg_P05: 8 ECU
 SG_ Value : 0|16@1+ (1,0) [0|65535] "" Vector__XXX
 SG_ Crc : 16|16@1+ (1,0) [0|65535] "" Vector__XXX
 SG_ Counter : 32|8@1+ (1,0) [0|255] "" Vector__XXX

{E2E_ATTRIBUTE_DEFINITIONS}
BA_DEF_DEF_  "E2E_Profile" "None";
BA_DEF_DEF_  "E2E_DataID" 0;
BA_DEF_DEF_  "E2E_DataIDMode" "BOTH";
BA_DEF_DEF_  "E2E_DataIDList" "";
BA_DEF_DEF_  "E2E_Offset" 0;
BA_DEF_DEF_  "E2E_DataLength" 64;
BA_DEF_DEF_  "E2E_MaxDeltaCounter" 2;
BA_ "E2E_Profile" BO_ 291 1;
BA_ "E2E_DataID" BO_ 291 291;
BA_ "E2E_DataIDMode" BO_ 291 1;
BA_ "E2E_Offset" BO_ 291 8;
BA_ "E2E_Profile" BO_ 292 4;
BA_ "E2E_DataID" BO_ 292 2748;
BA_ "E2E_DataIDMode" BO_ 292 3;
BA_ "E2E_Profile" BO_ 293 2;
BA_ "E2E_DataIDList" BO_ 293 "{DATA_ID_LIST}";
BA_ "E2E_Profile" BO_ 294 3;
BA_ "E2E_DataID" BO_ 294 4660;
BA_ "E2E_Offset" BO_ 294 16;
BA_ "E2E_MaxDeltaCounter" BO_ 294 3;
'''

#: case -> (database, message)
CASES = {
    "P01": ("own", "Msg_P01"),
    "P02": ("own", "Msg_P02"),
    "P05": ("own", "Msg_P05"),
    "P11": ("contract", "VCU_WheelCmd_FL"),
    "P11 NIBBLE": ("own", "Msg_P11_Nibble"),
}
#: For the masquerade: a message of the same profile and layout with another DataID (or DataIDList).
OTHER = {"P11": ("contract", "VCU_WheelCmd_FR")}


@pytest.fixture(scope="module")
def own_codebook(tmp_path_factory: pytest.TempPathFactory) -> Codebook:
    path: Path = tmp_path_factory.mktemp("profiles") / "profiles.dbc"
    path.write_text(PROFILES_DBC)
    return load_codebook([path])


def _protection(case: str, own: Codebook, contract: Codebook,
                table: dict[str, tuple[str, str]] = CASES) -> bench_e2e.Protection:
    where, name = table[case]
    protection = (own if where == "own" else contract)[name].protection
    assert protection is not None, name
    return protection


def _library(p: bench_e2e.Protection) -> tuple[Callable[..., None], Callable[..., bool]]:
    """The library's protect and check with the message's parameters, written from the DBC's values (not from
    the bench's Protection internals): (protect(data, increment_counter), check(data))."""
    byte = p.offset // 8
    if p.profile in ("P01", "P11"):
        module, prefix = (p01, "E2E_P01_DATAID_") if p.profile == "P01" else (p11, "E2E_P11_DATAID_")
        mode = getattr(module, prefix + p.data_id_mode)
        protect = p01.e2e_p01_protect if p.profile == "P01" else p11.e2e_p11_protect
        check = p01.e2e_p01_check if p.profile == "P01" else p11.e2e_p11_check
        return (lambda d, inc: protect(d, p.data_id, data_id_mode=mode, length=p.length, offset=byte,
                                       increment_counter=inc),
                lambda d: check(bytearray(d), p.data_id, data_id_mode=mode, length=p.length, offset=byte))
    if p.profile == "P02":
        ids = bytes(p.data_id_list)
        return (lambda d, inc: p02.e2e_p02_protect(d, ids, length=p.length, increment_counter=inc),
                lambda d: p02.e2e_p02_check(bytearray(d), ids, length=p.length))
    return (lambda d, inc: p05.e2e_p05_protect(d, p.data_id, length=p.length, offset=byte, increment_counter=inc),
            lambda d: p05.e2e_p05_check(bytearray(d), p.data_id, length=p.length, offset=byte))


def test_the_database_gives_each_message_its_protection(own_codebook: Codebook, codebook: Codebook) -> None:
    """The DBC attributes are read as written: profile, DataID (list), mode, header places, MaxDeltaCounter."""
    got = {case: _protection(case, own_codebook, codebook) for case in CASES}
    assert (got["P01"].profile, got["P01"].data_id, got["P01"].data_id_mode) == ("P01", 0x123, "ALT")
    assert (got["P01"].crc.start, got["P01"].counter.start, got["P01"].counter_modulo) == (8, 16, 15)
    assert (got["P11 NIBBLE"].profile, got["P11 NIBBLE"].data_id, got["P11 NIBBLE"].data_id_mode) == \
        ("P11", 0xABC, "NIBBLE")
    assert got["P02"].data_id_list == bytes.fromhex(DATA_ID_LIST) and got["P02"].counter_modulo == 16
    assert (got["P05"].crc.start, got["P05"].crc.length, got["P05"].counter.start) == (16, 16, 32)
    assert got["P05"].counter_modulo == 256 and got["P05"].max_delta_counter == 3 and got["P05"].data_id == 0x1234
    assert (got["P11"].data_id, got["P11"].crc.start, got["P11"].counter.start) == (0x110, 48, 56)


def _random_payload(p: bench_e2e.Protection, rng: random.Random, frame: bytearray) -> None:
    """New values for every bit outside the E2E header (the signals change from frame to frame)."""
    word = int.from_bytes(frame, "little")
    noise = rng.getrandbits(8 * len(frame))
    word = (word & p.header_mask) | (noise & ~p.header_mask)
    frame[:] = word.to_bytes(len(frame), "little")


def _library_stream(p: bench_e2e.Protection, count: int, seed: int) -> list[bytes]:
    """`count` frames protected by the library with its own counter handling (the counter starts one below a
    random value and the library increments it before each frame)."""
    rng = random.Random(seed)
    protect, _ = _library(p)
    frame = bytearray(8)
    p.counter.write(frame, rng.randrange(p.counter_modulo))
    frames = []
    for _ in range(count):
        _random_payload(p, rng, frame)
        protect(frame, True)
        frames.append(bytes(frame))
    return frames


def _receiver(p: bench_e2e.Protection) -> bench_e2e.Receiver:
    return bench_e2e.Receiver(p.counter_modulo, p.max_delta_counter, p.sm)


def _receive(rx: bench_e2e.Receiver, p: bench_e2e.Protection, data: bytes) -> tuple[str, bool]:
    status, applied = rx.receive(p.counter_if_intact(data))
    return status.value, applied


@pytest.mark.parametrize("case", CASES)
def test_library_frames_are_accepted_by_the_bench(own_codebook: Codebook, codebook: Codebook, case: str) -> None:
    p = _protection(case, own_codebook, codebook)
    frames = _library_stream(p, FRAMES, seed=len(case))
    counters = [p.counter_of(f) for f in frames]
    assert counters.count(0) >= FRAMES // p.counter_modulo, "the counter wraps"
    assert all((b - a) % p.counter_modulo == 1 for a, b in zip(counters, counters[1:])), "the library counts by 1"
    rx = _receiver(p)
    results = [_receive(rx, p, f) for f in frames]
    assert [status for status, _ in results[1:]] == ["OK"] * (FRAMES - 1)
    assert [applied for _, applied in results] == [False] + [True] * (FRAMES - 1)
    assert rx.state is bench_e2e.SMState.VALID


@pytest.mark.parametrize("case", CASES)
def test_bench_frames_pass_the_librarys_check(own_codebook: Codebook, codebook: Codebook, case: str) -> None:
    """Every counter value, thousands of payloads: Protection.protect's frames pass the library's check, carry
    the counter asked for, and are the very bytes the library's protect writes for that counter."""
    p = _protection(case, own_codebook, codebook)
    protect, check = _library(p)
    rng = random.Random(7)
    frame = bytearray(8)
    for i in range(FRAMES):
        _random_payload(p, rng, frame)
        counter = i % p.counter_modulo
        ours = bytearray(frame)
        p.protect(ours, counter)
        assert check(ours), (case, counter, ours.hex())
        assert p.counter_of(ours) == counter and p.counter_if_intact(bytes(ours)) == counter
        theirs = bytearray(ours)
        protect(theirs, False)
        assert theirs == ours


def _valid_receiver(p: bench_e2e.Protection, frames: list[bytes]) -> bench_e2e.Receiver:
    rx = _receiver(p)
    for data in frames:
        _receive(rx, p, data)
    assert rx.state is bench_e2e.SMState.VALID
    return rx


@pytest.mark.parametrize("case", CASES)
def test_corrupted_crc_is_an_error(own_codebook: Codebook, codebook: Codebook, case: str) -> None:
    p = _protection(case, own_codebook, codebook)
    frames = _library_stream(p, 40, seed=3)
    for bit in range(p.crc.length):
        rx = _valid_receiver(p, frames[:10])
        bad = bytearray(frames[10])
        p.set_checksum(bad, p.checksum_of(bad) ^ (1 << bit))
        assert _receive(rx, p, bytes(bad)) == ("ERROR", False)
    for byte in range(8):           # a flipped bit anywhere in the protected frame
        rx = _valid_receiver(p, frames[:10])
        bad = bytearray(frames[10])
        bad[byte] ^= 0x10
        assert _receive(rx, p, bytes(bad)) == ("ERROR", False), byte


@pytest.mark.parametrize("case", ["P01", "P02", "P05", "P11", "P11 NIBBLE"])
def test_a_frame_judged_as_another_message_is_an_error(own_codebook: Codebook, codebook: Codebook,
                                                       case: str) -> None:
    """Masquerade: a frame of one message received under another identifier, whose receiver has the same
    profile and layout but its own DataID (DataIDList for P02), fails the CRC: ERROR."""
    p = _protection(case, own_codebook, codebook)
    if case in OTHER:
        other = _protection(case, own_codebook, codebook, OTHER)
    elif p.profile == "P02":
        other = bench_e2e.Protection("P02", data_id_list=bytes(b ^ 0x40 for b in p.data_id_list),
                                     max_delta_counter=p.max_delta_counter, sm=p.sm)
    else:
        other = bench_e2e.Protection(p.profile, data_id=p.data_id ^ 0x0101, data_id_mode=p.data_id_mode,
                                     offset=p.offset, length=p.length, max_delta_counter=p.max_delta_counter,
                                     sm=p.sm)
    assert other.data_id != p.data_id or other.data_id_list != p.data_id_list
    assert (other.crc, other.counter) == (p.crc, p.counter)
    own_frames = _library_stream(other, 10, seed=5)
    rx = _valid_receiver(other, own_frames)
    for data in _library_stream(p, p.counter_modulo, seed=6):     # every counter value
        assert _receive(rx, other, data) == ("ERROR", False)


@pytest.mark.parametrize("case", CASES)
def test_repeated_skipped_and_stale_frames(own_codebook: Codebook, codebook: Codebook, case: str) -> None:
    p = _protection(case, own_codebook, codebook)
    frames = _library_stream(p, 3 * p.counter_modulo + 20, seed=9)
    # repeated: the same frame again
    rx = _valid_receiver(p, frames[:10])
    assert _receive(rx, p, frames[9]) == ("REPEATED", False)
    # skipped beyond MaxDeltaCounter: max_delta frames lost, the next counter step is max_delta + 1
    rx = _valid_receiver(p, frames[:10])
    assert _receive(rx, p, frames[9 + p.max_delta_counter + 1]) == ("WRONGSEQUENCE", False)
    # ... while a skip within it is OKSOMELOST, and applied
    rx = _valid_receiver(p, frames[:10])
    assert _receive(rx, p, frames[9 + p.max_delta_counter]) == ("OKSOMELOST", True)
    # stale: an old frame sent again, k frames after it was first sent (less than a counter cycle minus the
    # accepted step ago: WRONGSEQUENCE; exactly a counter cycle ago: REPEATED)
    end = len(frames) - 1
    modulo = p.counter_modulo
    for k in [*range(1, modulo - p.max_delta_counter), modulo]:
        rx = _valid_receiver(p, frames[end - 10:end + 1])
        expected = "REPEATED" if k == modulo else "WRONGSEQUENCE"
        assert _receive(rx, p, frames[end - k]) == (expected, False), k


# -- Profile 11's CRC, independently ------------------------------------------------------------------------
def test_the_p11_crc_is_crc8_sae_j1850_from_zero_without_final_xor() -> None:
    """Against the library: AUTOSAR writes Profile 11's CRC with Crc_CalculateCRC8 (CRC-8/SAE-J1850, start and
    final XOR 0xFF) continued from a start value of 0xFF and the result XORed with 0xFF: the same polynomial
    from 0x00 without a final XOR (check value 0x37, where CRC-8/SAE-J1850 itself gives 0x4B)."""
    assert crc8_j1850_p11(b"123456789") == 0x37
    assert crc.calculate_crc8(b"123456789") == 0x4B
    rng = random.Random(1)
    for size in range(1, 20):
        data = rng.randbytes(size)
        assert crc.calculate_crc8(data, 0xFF, False) ^ 0xFF == crc8_j1850_p11(data)


def test_the_documents_example_frame(codebook: Codebook) -> None:
    """docs/spec/e2e.md "The CRC, worked through": DataID 0x110, data bytes 0, counter 0 -> CRC 0x41."""
    assert p11_crc(0x110, bytes(8)) == 0x41
    p = codebook["VCU_WheelCmd_FL"].protection
    assert p is not None
    for counter, frame in ((0, "00 00 00 00 00 00 41 00"), (1, "00 00 00 00 00 00 5C 01")):
        data = bytearray(8)
        p.protect(data, counter)
        assert data == bytes.fromhex(frame)
    data = bytearray.fromhex("01 02 03 04 05 06 00 20")
    codebook["DRV_MotionRequest"].protection.protect(data, 7)
    assert data == bytes.fromhex("01 02 03 04 05 06 5C 27")


@given(st.sampled_from(sorted(range(0x100, 0x170))), st.binary(min_size=8, max_size=8), st.integers(0, 14))
def test_protect_writes_the_reference_crc(frame_id: int, payload: bytes, counter: int) -> None:
    """Any DataID, payload and counter: Protection.protect (the contract's parameters) writes the counter into
    bits 56-59 and, into byte 6, the CRC over DataID low, DataID high, bytes 0-5 and byte 7; every other bit stays."""
    p = bench_e2e.Protection("P11", data_id=frame_id, offset=48)
    data = bytearray(payload)
    p.protect(data, counter)
    assert data[7] & 0x0F == counter and data[7] & 0xF0 == payload[7] & 0xF0 and data[:6] == payload[:6]
    assert data[6] == crc8_j1850_p11(bytes([frame_id & 0xFF, frame_id >> 8]) + bytes(data[:6]) + bytes(data[7:]))


# -- the document's "Profiles" table, independently -----------------------------------------------------------
def _crc(data: bytes, poly: int, width: int, start: int, final_xor: int) -> int:
    """A CRC without reflection, bit by bit (docs/spec/e2e.md "Profiles")."""
    top, mask, crc_ = 1 << (width - 1), (1 << width) - 1, start
    for byte in data:
        crc_ ^= byte << (width - 8)
        for _ in range(8):
            crc_ = ((crc_ << 1) ^ poly) & mask if crc_ & top else (crc_ << 1) & mask
    return crc_ ^ final_xor


def test_the_documents_check_values() -> None:
    check = b"123456789"
    assert _crc(check, 0x1D, 8, 0x00, 0x00) == 0x37          # P01, P11
    assert _crc(check, 0x2F, 8, 0xFF, 0xFF) == 0xDF == crc.calculate_crc8_h2f(check)   # P02
    assert _crc(check, 0x1021, 16, 0xFFFF, 0) == 0x29B1 == crc.calculate_crc16(check)  # P05


@pytest.mark.parametrize("case", CASES)
def test_the_documents_layouts(own_codebook: Codebook, codebook: Codebook, case: str) -> None:
    """The bytes each CRC runs over, in the document's order, give the CRC Protection.protect writes."""
    p = _protection(case, own_codebook, codebook)
    rng = random.Random(11)
    o = p.offset // 8
    for i in range(200):
        data = bytearray(rng.randbytes(8))
        p.protect(data, i)
        if p.profile == "P02":
            expected = _crc(bytes(data[1:]) + bytes([p.data_id_list[data[1] & 0x0F]]), 0x2F, 8, 0xFF, 0xFF)
            assert data[0] == expected
        elif p.profile == "P05":
            body = bytes(data[:o]) + bytes(data[o + 2:])
            assert int.from_bytes(data[o:o + 2], "little") == _crc(body + p.data_id.to_bytes(2, "little"),
                                                                   0x1021, 16, 0xFFFF, 0)
        else:
            ident = {"BOTH": bytes([p.data_id & 0xFF, p.data_id >> 8]), "LOW": bytes([p.data_id & 0xFF]),
                     "ALT": bytes([p.data_id >> 8 if data[o + 1] & 1 else p.data_id & 0xFF]),
                     "NIBBLE": bytes([p.data_id & 0xFF, 0])}[p.data_id_mode]
            assert data[o] == crc8_j1850_p11(ident + bytes(data[:o]) + bytes(data[o + 1:]))
            if p.data_id_mode == "NIBBLE":
                assert data[o + 1] >> 4 == (p.data_id >> 8) & 0x0F
