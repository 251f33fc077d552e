"""AUTOSAR E2E profiles on a frame: where each profile puts its CRC and counter, and the library calls.

The CRC of every profile is computed by the `autosar-e2e` package (a C implementation of the AUTOSAR
profiles), never here: the bench and an ECU configured with the same parameters compute the same bytes.
This module only knows each profile's header layout (docs/spec/e2e.md "Profiles") so that the restbus can
write a counter of its choice, the fault kinds can corrupt a field, and the receiver can read the counter.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from e2e import p01, p02, p05, p07, p11
from e2e.crc import calculate_crc8

#: The profiles the bench speaks, by the name a database gives them (DBC attribute E2E_Profile, ARXML
#: category, bench.toml [e2e]).
PROFILES = ("P01", "P02", "P05", "P07", "P11")

#: Data ID modes of the profiles that have them (P01: all four; P11: BOTH and NIBBLE).
P01_MODES = {"BOTH": p01.E2E_P01_DATAID_BOTH, "ALT": p01.E2E_P01_DATAID_ALT,
             "LOW": p01.E2E_P01_DATAID_LOW, "NIBBLE": p01.E2E_P01_DATAID_NIBBLE}
P11_MODES = {"BOTH": p11.E2E_P11_DATAID_BOTH, "NIBBLE": p11.E2E_P11_DATAID_NIBBLE}


@dataclass(frozen=True, slots=True)
class Field:
    """A field of the E2E header in the frame: first bit (Intel numbering, bit 0 = LSB of byte 0) and length;
    `big_endian`: whole bytes, most significant first (Profile 7's fields), else little-endian bits."""

    start: int
    length: int
    big_endian: bool = False

    @property
    def first_byte(self) -> int:
        return self.start // 8

    def read(self, data: bytes | bytearray) -> int:
        if self.big_endian:
            return int.from_bytes(data[self.start // 8:(self.start + self.length) // 8], "big")
        return (int.from_bytes(data, "little") >> self.start) & ((1 << self.length) - 1)

    def write(self, data: bytearray, value: int) -> None:
        """Write `value` (cut to the field's width) into the field, leaving every other bit as it was."""
        mask = (1 << self.length) - 1
        byte, shift = divmod(self.start, 8)
        if self.big_endian:
            data[byte:byte + self.length // 8] = (value & mask).to_bytes(self.length // 8, "big")
            return
        span = (shift + self.length + 7) // 8
        word = int.from_bytes(data[byte:byte + span], "little")
        word = (word & ~(mask << shift)) | ((value & mask) << shift)
        data[byte:byte + span] = word.to_bytes(span, "little")

    def covers(self, start: int, length: int) -> bool:
        """Whether an Intel signal at (start, length) overlaps this field."""
        return start < self.start + self.length and self.start < start + length


@dataclass(frozen=True, slots=True)
class SMConfig:
    """The E2E state machine's parameters (AUTOSAR E2E_SMConfigType, one window size)."""

    window_size: int = 2
    min_ok_init: int = 1
    max_error_init: int = 0
    min_ok_valid: int = 2
    max_error_valid: int = 0
    min_ok_invalid: int = 2
    max_error_invalid: int = 0

    def problems(self) -> list[str]:
        """What AUTOSAR's constraints on these parameters say is wrong (empty: none)."""
        found = []
        if not 1 <= self.window_size <= 255:
            found.append(f"WindowSize {self.window_size} is not 1-255")
        for state in ("init", "valid", "invalid"):
            ok, error = getattr(self, f"min_ok_{state}"), getattr(self, f"max_error_{state}")
            if ok + error > self.window_size or ok < 0 or error < 0:
                found.append(f"MinOkState{state.title()} {ok} + MaxErrorState{state.title()} {error} "
                             f"exceed WindowSize {self.window_size}")
        return found


@dataclass(frozen=True, slots=True)
class Protection:
    """One message's E2E protection: its profile, parameters and header fields (docs/spec/e2e.md)."""

    profile: str                      # "P01", "P02", "P05", "P07", "P11"
    data_id: int = 0                  # P01, P05, P11: the 16-bit Data ID; P07: the 32-bit one
    data_id_list: bytes = b""         # P02: 16 Data IDs, one per counter value
    data_id_mode: str = "BOTH"        # P01: BOTH, ALT, LOW, NIBBLE; P11: BOTH, NIBBLE
    offset: int = 0                   # bit offset of the header (the CRC's first bit); P02: 0
    length: int = 0                   # bytes covered by the CRC (0: the whole frame)
    max_delta_counter: int = 1        # the largest counter step still accepted (OKSOMELOST above 1)
    sm: SMConfig = field(default_factory=SMConfig)
    source: str = ""                  # where the parameters came from (database attributes, ARXML, bench.toml)
    crc: Field = field(init=False)
    counter: Field = field(init=False)
    counter_modulo: int = field(init=False)
    _protect: Callable[[bytearray, int], None] = field(init=False, repr=False, compare=False)
    _intact: Callable[[bytes | bytearray], int | None] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        byte = self.offset // 8
        kw: dict[str, Any] = {"length": self.length}
        module_protect: Callable[..., None]
        module_check: Callable[..., bool]
        set_ = object.__setattr__
        if self.profile in ("P01", "P11"):
            mode_table = P01_MODES if self.profile == "P01" else P11_MODES
            module_protect = p01.e2e_p01_protect if self.profile == "P01" else p11.e2e_p11_protect
            module_check = p01.e2e_p01_check if self.profile == "P01" else p11.e2e_p11_check
            kw.update(offset=byte, data_id_mode=mode_table[self.data_id_mode])
            set_(self, "crc", Field(8 * byte, 8))
            set_(self, "counter", Field(8 * byte + 8, 4))
            set_(self, "counter_modulo", 15)      # 0 ... 14; 15 is never sent, and refused by the check
            data_id: Any = self.data_id
        elif self.profile == "P02":
            module_protect, module_check = p02.e2e_p02_protect, p02.e2e_p02_check
            set_(self, "crc", Field(0, 8))
            set_(self, "counter", Field(8, 4))
            set_(self, "counter_modulo", 16)
            data_id = bytes(self.data_id_list)
        elif self.profile == "P05":
            module_protect, module_check = p05.e2e_p05_protect, p05.e2e_p05_check
            kw.update(offset=byte)
            set_(self, "crc", Field(8 * byte, 16))
            set_(self, "counter", Field(8 * byte + 16, 8))
            set_(self, "counter_modulo", 256)
            data_id = self.data_id
        elif self.profile == "P07":   # header: CRC-64, Length, Counter, DataID, each big-endian (20 bytes)
            module_protect, module_check = p07.e2e_p07_protect, p07.e2e_p07_check
            kw.update(offset=byte)
            set_(self, "crc", Field(8 * byte, 64, big_endian=True))
            set_(self, "counter", Field(8 * byte + 96, 32, big_endian=True))
            set_(self, "counter_modulo", 1 << 32)
            data_id = self.data_id
        else:
            raise ValueError(f"E2E profile {self.profile!r} is not one of {', '.join(PROFILES)}")
        fast = _fast_crc(self.profile, self.data_id_mode, self.data_id, byte, self.length)
        counter_field = self.counter
        modulo = self.counter_modulo
        if fast is None:
            def protect_slow(data: bytearray, counter: int) -> None:
                counter_field.write(data, counter % modulo)
                module_protect(data, data_id, increment_counter=False, **kw)

            # (the library's check wants a writable buffer: it is given a copy, the frame stays as received)
            def intact_slow(data: bytes | bytearray) -> int | None:
                return counter_field.read(data) if module_check(bytearray(data), data_id, **kw) else None

            set_(self, "_protect", protect_slow)
            set_(self, "_intact", intact_slow)
        else:
            set_(self, "_intact", fast[0])
            set_(self, "_protect", fast[1])

    # -- sending ---------------------------------------------------------------------------------
    def protect(self, data: bytearray, counter: int) -> None:
        """Write `counter` (modulo the profile's range) and then the CRC into a payload, in place."""
        self._protect(data, counter)

    def next_counter(self, counter: int) -> int:
        return (counter + 1) % self.counter_modulo

    # -- receiving -------------------------------------------------------------------------------
    def counter_if_intact(self, data: bytes | bytearray) -> int | None:
        """The counter of a frame whose CRC is right; None when it is wrong (a damaged counter is not read)."""
        return self._intact(data)

    def counter_of(self, data: bytes | bytearray) -> int:
        """The counter a frame carries, right or wrong."""
        return self.counter.read(data)

    def checksum_of(self, data: bytes | bytearray) -> int:
        """The CRC a frame carries, right or wrong."""
        return self.crc.read(data)

    def set_checksum(self, data: bytearray, value: int) -> None:
        """Write a CRC value (cut to the field's width) into a payload, whatever it should be."""
        self.crc.write(data, value)

    def payload(self, data: bytes) -> bytes:
        """The frame with its CRC and counter fields cleared: what stays the same from one frame of a message
        to the next while its signals do."""
        out = bytearray(data)
        self.crc.write(out, 0)
        self.counter.write(out, 0)
        return bytes(out)

    @property
    def header_end(self) -> int:
        """The bit after the E2E header (P07's header also carries its Length and Data ID after the counter)."""
        end = max(self.crc.start + self.crc.length, self.counter.start + self.counter.length)
        return end + 32 if self.profile == "P07" else end

    @property
    def header_mask(self) -> int:
        """The CRC and counter fields as a mask over the frame read as one little-endian integer."""
        return ((1 << self.crc.length) - 1) << self.crc.start | ((1 << self.counter.length) - 1) << self.counter.start

    def describe(self) -> str:
        """One line: the profile and every parameter a receiver configures."""
        if self.profile == "P02":
            ident = "DataIDList " + " ".join(f"{b:02X}" for b in self.data_id_list)
        elif self.profile == "P05":
            ident = f"DataID 0x{self.data_id:04X}"
        elif self.profile == "P07":
            ident = f"DataID 0x{self.data_id:08X}"
        else:
            ident = f"DataID 0x{self.data_id:04X} {self.data_id_mode}"
        sm = self.sm
        return (f"{self.profile} {ident}, CRC bits {self.crc.start}-{self.crc.start + self.crc.length - 1}, "
                f"counter bits {self.counter.start}-{self.counter.start + self.counter.length - 1} "
                f"(0-{self.counter_modulo - 1}), MaxDeltaCounter {self.max_delta_counter}, "
                f"window {sm.window_size} (init {sm.min_ok_init}/{sm.max_error_init}, valid {sm.min_ok_valid}/"
                f"{sm.max_error_valid}, invalid {sm.min_ok_invalid}/{sm.max_error_invalid})")


def _fast_crc(profile: str, mode: str, data_id: int, crc_byte: int, length: int
              ) -> tuple[Callable[[bytes | bytearray], int | None], Callable[[bytearray, int], None]] | None:
    """Profiles 1 and 11 with DataIDMode BOTH (the contract's protection) through the library's CRC-8 alone:
    AUTOSAR's chained Crc_CalculateCRC8 calls over the Data ID's low and high byte, then every byte but the CRC's,
    in one library call per frame. The profile functions of `autosar-e2e` take keyword arguments, which that
    library parses slowly (docs/performance.md "E2E"); tests/bench/e2e/test_e2e_profiles.py checks that these bytes
    equal the profile functions' for every offset, length and counter. None: use the profile functions."""
    if profile not in ("P01", "P11") or mode != "BOTH":
        return None
    # The library's CRC-8 starts at 0xFF and ends with XOR 0xFF; the profiles start at 0x00 and end without XOR.
    # For an 8-bit CRC a start value is the same as XOR-ing it into the first byte, so the Data ID's low byte
    # enters XOR 0xFF and the result is XOR-ed with 0xFF again: one call with the library's defaults.
    prefix = bytes(((data_id & 0xFF) ^ 0xFF, (data_id >> 8) & 0xFF))
    end = length or None
    after = crc_byte + 1
    counter_byte = after

    def intact(data: bytes | bytearray) -> int | None:
        counter = data[counter_byte] & 0x0F
        if counter == 15 or calculate_crc8(prefix + data[:crc_byte] + data[after:end]) ^ 0xFF != data[crc_byte]:
            return None   # (the profiles' checks refuse a counter of 15, which no sender of theirs sends)
        return counter

    def protect(data: bytearray, counter: int) -> None:
        data[counter_byte] = (data[counter_byte] & 0xF0) | (counter % 15)
        data[crc_byte] = calculate_crc8(prefix + data[:crc_byte] + data[after:end]) ^ 0xFF

    return intact, protect
