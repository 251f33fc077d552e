"""E2E Profile 7 on a 64-byte CAN FD frame, as a database declares it: the bench's frames pass the `autosar-e2e`
library's own check and equal the library's bytes, the library's frames pass the bench's receiver, any flipped bit
is an ERROR, another Data ID is a masquerade, and the 32-bit counter runs past 2^32 - 1 to 0. The expected layout
(CRC-64 at the offset, length, counter, Data ID, each big-endian) is AUTOSAR's (docs/spec/e2e.md "Profiles"), read
back from the library's frames, not from the bench's Protection."""

from __future__ import annotations

import random

import cantools
import pytest
from e2e import crc, p07

from bench import e2e as bench_e2e
from bench.database.codec import Codebook
from bench.errors import DatabaseError
from tests.repo import VFRAMEFORMAT_DEFINITION

DATA_ID = 0x0EB00200
DBC = f'''VERSION ""
NS_ :
BS_:
BU_: ECU
BO_ 512 Status: 64 ECU
 SG_ Value : 240|16@1+ (1,0) [0|65535] "" Vector__XXX
 SG_ Tail : 496|16@1+ (1,0) [0|65535] "" Vector__XXX
BO_ 513 Short: 16 ECU
 SG_ Value : 0|16@1+ (1,0) [0|65535] "" Vector__XXX
{VFRAMEFORMAT_DEFINITION}
BA_DEF_ BO_ "GenMsgCycleTime" INT 0 65535;
BA_DEF_ BO_ "E2E_Profile" ENUM "None","P01","P02","P05","P07","P11";
BA_DEF_ BO_ "E2E_DataID" INT 0 2147483647;
BA_DEF_ BO_ "E2E_Offset" INT 0 504;
BA_DEF_ BO_ "E2E_MaxDeltaCounter" INT 1 255;
BA_DEF_DEF_ "VFrameFormat" "StandardCAN_FD";
BA_DEF_DEF_ "E2E_Profile" "None";
BA_DEF_DEF_ "E2E_DataID" 0;
BA_DEF_DEF_ "E2E_Offset" 0;
BA_DEF_DEF_ "E2E_MaxDeltaCounter" 2;
BA_ "GenMsgCycleTime" BO_ 512 10;
BA_ "E2E_Profile" BO_ 512 4;
BA_ "E2E_DataID" BO_ 512 {DATA_ID};
BA_ "E2E_Offset" BO_ 512 64;
'''
OFFSET_BYTE = 8


@pytest.fixture(scope="module")
def protection() -> bench_e2e.Protection:
    book = Codebook([("p07.dbc", cantools.database.load_string(DBC, "dbc"))])
    found = book["Status"].protection
    assert found is not None
    return found


def _library_frame(payload: bytes, counter: int) -> bytearray:
    """The library's frame for a counter: the counter written big-endian where AUTOSAR puts it, then its protect."""
    data = bytearray(payload)
    data[OFFSET_BYTE + 12:OFFSET_BYTE + 16] = counter.to_bytes(4, "big")
    p07.e2e_p07_protect(data, DATA_ID, offset=OFFSET_BYTE, increment_counter=False)
    return data


def _payloads(n: int, seed: int) -> list[bytes]:
    rng = random.Random(seed)
    out = []
    for _ in range(n):
        data = bytearray(rng.randbytes(64))
        data[OFFSET_BYTE:OFFSET_BYTE + 20] = bytes(20)
        out.append(bytes(data))
    return out


def test_the_database_declares_profile_7(protection: bench_e2e.Protection) -> None:
    assert (protection.profile, protection.data_id, protection.offset) == ("P07", DATA_ID, 64)
    assert protection.counter_modulo == 1 << 32


def test_the_library_writes_autosars_header() -> None:
    """What the rest of this file relies on: CRC-64/XZ over the bytes after the CRC, length and Data ID in place."""
    assert crc.calculate_crc64(b"123456789") == 0x995DC9BBDF1939FA
    data = _library_frame(bytes(64), 7)
    header = data[OFFSET_BYTE:OFFSET_BYTE + 20]
    assert int.from_bytes(header[8:12], "big") == 64 and int.from_bytes(header[12:16], "big") == 7
    assert int.from_bytes(header[16:20], "big") == DATA_ID
    covered = bytes(data[:OFFSET_BYTE] + data[OFFSET_BYTE + 8:])
    assert int.from_bytes(header[:8], "big") == crc.calculate_crc64(covered)


@pytest.mark.parametrize("counter", [0, 1, 255, 256, 65_536, (1 << 32) - 2, (1 << 32) - 1])
def test_bench_frames_are_the_librarys(protection: bench_e2e.Protection, counter: int) -> None:
    for payload in _payloads(50, seed=counter % 1000):
        ours = bytearray(payload)
        protection.protect(ours, counter)
        assert ours == _library_frame(payload, counter)
        assert p07.e2e_p07_check(bytearray(ours), DATA_ID, offset=OFFSET_BYTE)
        assert protection.counter_if_intact(bytes(ours)) == counter == protection.counter_of(ours)


def test_library_frames_pass_the_receiver_across_the_counters_wrap(protection: bench_e2e.Protection) -> None:
    rx = bench_e2e.Receiver(protection.counter_modulo, protection.max_delta_counter, protection.sm)
    start = (1 << 32) - 20
    counters = [(start + i) % (1 << 32) for i in range(40)]
    results = [rx.receive(protection.counter_if_intact(bytes(_library_frame(p, c))))
               for p, c in zip(_payloads(40, seed=1), counters)]
    assert 0 in counters and [str(s) for s, _ in results[1:]] == ["OK"] * 39
    assert rx.state is bench_e2e.SMState.VALID and results[-1][1]


def test_any_flipped_bit_is_an_error_and_another_data_id_a_masquerade(protection: bench_e2e.Protection) -> None:
    frame = _library_frame(_payloads(1, seed=2)[0], 1234)
    for bit in range(0, 8 * 64, 7):
        bad = bytearray(frame)
        bad[bit // 8] ^= 1 << (bit % 8)
        assert protection.counter_if_intact(bytes(bad)) is None, bit
    other = bytearray(frame[:OFFSET_BYTE + 16]) + bytearray(frame[OFFSET_BYTE + 20:])
    other[OFFSET_BYTE + 16:OFFSET_BYTE + 16] = (DATA_ID ^ 1).to_bytes(4, "big")
    p07.e2e_p07_protect(other, DATA_ID ^ 1, offset=OFFSET_BYTE, increment_counter=False)
    assert protection.counter_if_intact(bytes(other)) is None


def test_the_restbus_counts_each_frame_and_the_monitor_accepts_them(protection: bench_e2e.Protection) -> None:
    from bench.checks.monitor import Monitor
    from bench.sim.restbus import Restbus

    book = Codebook([("p07.dbc", cantools.database.load_string(DBC, "dbc"))])
    restbus, monitor = Restbus(book, {"ECU"}), Monitor(book)
    restbus.set_tick(0.001)
    sent = []
    for tick in range(400):
        restbus.set("Status", Value=tick)
        for frame_id, data in restbus.due(tick):
            if frame_id == book["Status"].send_id:
                sent.append(data)
                monitor.on_frame(tick * 0.001, book["Status"].frame_id, data, "rx")
    assert len(sent) == 40
    assert [p07.e2e_p07_check(bytearray(d), DATA_ID, offset=OFFSET_BYTE) for d in sent] == [True] * len(sent)
    assert [int.from_bytes(d[OFFSET_BYTE + 12:OFFSET_BYTE + 16], "big") for d in sent] == list(range(len(sent)))
    assert monitor.invalid_frames == 0


def test_a_header_that_does_not_fit_is_refused() -> None:
    text = DBC + 'BA_ "E2E_Profile" BO_ 513 4;\n'
    with pytest.raises(DatabaseError, match=r"Short: the P07 header \(bits 0-159\) does not fit the 16-byte frame"):
        Codebook([("p07.dbc", cantools.database.load_string(text, "dbc"))])
