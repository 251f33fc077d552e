"""DBC loading and per-message codecs.

cantools' database is the single source of truth; from it each message gets a precompiled codec
for its little-endian integer signals (shift, mask, scale), so the hot path of the restbus and of
the monitor costs a few integer operations per signal. Messages the fast path cannot handle
(big-endian, float or multiplexed signals, or a signal whose values a double cannot hold exactly,
e.g. 64-bit raw values) fall back to cantools, whose integer arithmetic is exact.

Either way the codec equals cantools (`Message.encode(..., scaling=True, strict=False)` and
`Message.decode(..., decode_choices=False)`) bit for bit, or raises where cantools raises, with an
error of the same class: a raw value that does not fit its bit field raises `EncodeError` (never
wraps), a payload shorter than the message raises `DecodeError`, a longer one is cut to the
message's length. `encode(..., strict=True)` adds cantools' strict checks (exactly the signals
needed, values inside the DBC range). `tests/bench/database/test_codec.py` (the contract's messages) and
`tests/bench/database/test_codec_cantools.py` (every message of cantools' own test DBCs) prove it.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import Any, cast

import cantools
from cantools.database.can import Database, Message, Signal

from bench import canid, e2e
from bench.database import overrides, sendtype
from bench.database.errors import FIELD_OVERFLOW, DecodeError, EncodeError
from bench.errors import DatabaseError, SignalError, did_you_mean


class _Misfit(Exception):
    """A raw value outside its bit field on the fast path: cantools' encoding decides what to raise."""


#: Doubles hold every integer up to 2**53; a signal whose raw and physical values stay below this (a
#: margin of one bit) is encoded and decoded with floats exactly as cantools' integer arithmetic does.
_EXACT_LIMIT = 1 << 52

#: A decoded value may exceed the DBC range by this fraction of the scale (rounding) and still be valid.
RANGE_SLACK = 0.5

#: Raw values of the E2E fields as floats (raw * 1.0): a counter or CRC of up to 8 bits; wider fields convert.
_FLOATS: tuple[float, ...] = tuple(float(raw) for raw in range(256))

#: Frames whose E2E check a message's codec remembers (two payloads' worth of counters, and then some).
INTACT_CACHE = 64


@dataclass(frozen=True, slots=True)
class SignalCodec:
    name: str
    start: int
    length: int
    signed: bool
    scale: float
    offset: float
    minimum: float | None
    maximum: float | None
    unit: str
    choices: Mapping[str, int]   # value-table name -> raw number
    #: why the range is narrower than the DBC's ("" when it is the DBC's): its raw field carries no more
    narrowed: str = ""

    @property
    def mask(self) -> int:
        return (1 << self.length) - 1

    def in_range(self, value: float) -> bool:
        if value != value:   # NaN (a float signal) is never in range
            return False
        slack = RANGE_SLACK * abs(self.scale)
        if self.minimum is not None and value < self.minimum - slack:
            return False
        if self.maximum is not None and value > self.maximum + slack:
            return False
        return True


#: Vector's message attributes that mark a database's diagnostic messages (CANoe's and CANdb++'s convention)
DIAGNOSTIC_ATTRIBUTES = {"DiagRequest": "request", "DiagResponse": "response", "DiagState": "response"}


def bitrate_switch(message: Message, definitions: Mapping[str, Any] | None = None) -> bool:
    """Whether a CAN FD message's data phase switches to the data bit rate: Vector's `CANFD_BRS` message attribute,
    else the database's default for it (`definitions`), else 1 (CANdb++'s default); False for a classical frame."""
    if not message.is_fd:
        return False
    attributes = message.dbc.attributes if message.dbc is not None else {}
    attribute = attributes.get("CANFD_BRS")
    value: Any = attribute.value if attribute is not None else getattr((definitions or {}).get("CANFD_BRS"),
                                                                        "default_value", None)
    if value is None:
        return True
    choices = getattr(getattr(attribute, "definition", None), "choices", None)
    if isinstance(value, int) and choices and 0 <= value < len(choices):
        value = choices[value]
    return str(value).strip().strip('"') in ("1", "Yes", "yes", "True", "true")


def diagnostic_kind(message: Message) -> str:
    """"request" or "response" for a diagnostic message (ISO-TP traffic, no cycle time, no E2E), else "".
    A DBC marks it with Vector's `DiagRequest` / `DiagResponse` / `DiagState` attribute set to Yes."""
    attributes = message.dbc.attributes if message.dbc is not None else {}
    for name, kind in DIAGNOSTIC_ATTRIBUTES.items():
        attribute = attributes.get(name)
        if attribute is not None and attribute.value in (1, "Yes", "yes"):
            return kind
    return ""


class MessageCodec:
    """Encode and decode one message; E2E bytes are left to `bench.e2e`."""

    def __init__(self, message: Message, database_name: str, protection: e2e.Protection | None = None,
                 cycle_time_ms: float | None = None, definitions: Mapping[str, Any] | None = None,
                 send_type: str | None = None) -> None:
        """`cycle_time_ms`, `send_type`: bench.toml's [messages.NAME] over the database's (bench.database.overrides);
        `definitions`: the database's attribute definitions (defaults of the attributes a message does not set).
        A send type the bench cannot use raises sendtype.SendTypeError."""
        self.message = message
        self.database = database_name
        self.name: str = message.name
        #: its identifier, format and CAN FD or not in one int (bench.canid): what the bench looks it up by
        self.frame_id: int = canid.of(message.frame_id, message.is_extended_frame, is_fd=message.is_fd)
        #: the frame_id of its frames on the bus: with the bit rate switch where the database asks for it
        self.send_id: int = self.frame_id | (canid.BRS if bitrate_switch(message, definitions) else 0)
        self.length: int = message.length
        #: the bytes its frames carry on the bus: a CAN FD frame between two DLC lengths is padded to the next
        self.frame_length: int = (canid.fd_length(message.length) if message.is_fd and message.length <= 64
                                  else message.length)
        self.senders: tuple[str, ...] = tuple(message.senders)
        cycle_ms = message.cycle_time if cycle_time_ms is None else cycle_time_ms
        self.cycle_time: float | None = cycle_ms / 1000.0 if cycle_ms else None
        #: "request" / "response": ISO-TP traffic (bench.diag), judged by its framing, never by cycle, E2E or range
        self.diagnostic: str = diagnostic_kind(message)
        #: how it is sent (bench.database.sendtype): the restbus sends it so, the monitor judges it so; a diagnostic
        #: message is written by the diagnostic stack on request
        self.sending: sendtype.Sending = (sendtype.Sending(sendtype.ON_WRITE, source="diagnostic message")
                                          if self.diagnostic else sendtype.sending(message, definitions, send_type))
        #: each signal's inactive value (a cyclic_if_active message is silent while every signal has it)
        self.inactive: dict[str, float] | None = None
        if self.sending.kind == sendtype.IF_ACTIVE:
            raw = sendtype.inactive_values(message, definitions) or {}
            self.inactive = {s.name: raw[s.name] * float(s.scale) + float(s.offset) if s.name in raw
                             else (s.raw_initial or 0) * float(s.scale) + float(s.offset) for s in message.signals}
        self.signals: tuple[SignalCodec, ...] = tuple(
            SignalCodec(
                name=s.name, start=s.start, length=s.length, signed=s.is_signed,
                scale=float(s.scale), offset=float(s.offset),
                **carried_range(s),
                unit=s.unit or "",
                choices={str(name): int(raw) for raw, name in (s.choices or {}).items()},
            )
            for s in message.signals
        )
        self.by_name: dict[str, SignalCodec] = {s.name: s for s in self.signals}
        #: a multiplexed message's frames, one per combination of multiplexer values (the database's order): each
        #: the multiplexer values and the signals that frame carries; () for a plain message
        self.variants: tuple[tuple[dict[str, int], tuple[str, ...]], ...] = (
            tuple(variants(message.signal_tree)) if message.is_multiplexed() else ())
        self.multiplexed: bool = bool(self.variants)
        #: each multiplexer signal's values in the database
        self.multiplexer_values: dict[str, tuple[int, ...]] = {}
        for chosen, _ in self.variants:
            for name, value in chosen.items():
                known = self.multiplexer_values.setdefault(name, ())
                if value not in known:
                    self.multiplexer_values[name] = (*known, value)
        self.signal_names: tuple[str, ...] = tuple(s.name for s in self.signals)
        # The end-to-end protection (docs/spec/e2e.md): from the database (DBC attributes or ARXML) or bench.toml,
        # checked by the Codebook; None: the message is unprotected (judged on its length, timing and ranges).
        self.protection: e2e.Protection | None = protection
        self.e2e: bool = protection is not None
        #: The signals that sit on the protection's CRC or counter field (shown as E2E, never set by hand).
        self.e2e_signals: frozenset[str] = frozenset(
            () if protection is None else
            (s.name for s in message.signals if s.byte_order == "little_endian"
             and (protection.crc.covers(s.start, s.length) or protection.counter.covers(s.start, s.length))))
        self.fast = (
            not message.is_multiplexed()
            and all(s.byte_order == "little_endian" and not s.is_float and _float_exact(s)
                    for s in message.signals)
        )
        inf = math.inf
        self._bounds: dict[str, tuple[float, float]] = {
            s.name: (-inf if s.minimum is None else s.minimum - RANGE_SLACK * abs(s.scale),
                     inf if s.maximum is None else s.maximum + RANGE_SLACK * abs(s.scale))
            for s in self.signals}
        # Decoding: without an offset when no signal has one (x + 0.0 differs from x only for x = -0.0,
        # which a positive scale never gives); one loop either way, so the values come in signal order.
        self._no_offset = all(s.offset == 0 and s.scale > 0 for s in self.signals)
        # Decode once per distinct payload: in one process the sender's and the receiver's monitors see the same
        # frame, and most frames repeat their values with only the counter and the checksum new. The cache is keyed
        # by the payload without those two fields when they are plain raw numbers whose DBC range covers their
        # whole field (scale 1, offset 0, unsigned: the contract's layout), so a repeat costs a copy and two
        # numbers, and its range check is the one of the payload's first frame. One entry (key, values, names
        # out of range or None until asked), replaced whole, so a reader on another thread never pairs a payload
        # with other values.
        full = (1 << (8 * self.length)) - 1
        self._e2e_fields: tuple[tuple[str, int, int], ...] = ()   # (signal, shift, mask) of the plain E2E fields
        if self.fast and protection is not None:
            plain = []
            for field_ in (protection.counter, protection.crc):
                sig = next((s for s in self.signals if s.start == field_.start and s.length == field_.length), None)
                # (an E2E field's DBC range does not matter here: the profile's check judges it before any decode)
                if sig is not None and not sig.signed and sig.scale == 1 and sig.offset == 0:
                    plain.append((sig.name, field_.start, (1 << field_.length) - 1))
            if len(plain) == len([s for s in self.signals if s.name in self.e2e_signals]):
                self._e2e_fields = tuple(plain)
        self._body_mask = full & ~protection.header_mask if self._e2e_fields and protection is not None else full
        self._entry: tuple[int, dict[str, float], tuple[str, ...] | None] = (-1, {}, None)
        # The E2E check of a frame, once per distinct frame: both monitors of a process check each frame, and a
        # message whose values stay the same repeats its frames (one per counter value).
        self._intact: dict[bytes, int | None] = {}
        # `decode_checked` of a frame, once per distinct frame (both monitors of a process judge every frame, and
        # a message whose values stay the same repeats its 16 frames): its values dict is shared by the callers,
        # who only read it (a Mapping to behaviours, the log and the timing collector).
        self._checked: dict[bytes, tuple[dict[str, float], tuple[str, ...]]] = {}
        self._unpack: tuple[tuple[Any, ...], ...] = tuple(
            (s.name, s.start, (1 << s.length) - 1, (1 << (s.length - 1)) if s.signed else 0,
             1 << s.length, s.scale, s.offset)[: 6 if self._no_offset else 7]
            for s in self.signals
        )
        # Encoding, by the arithmetic a signal needs (identity, scale only, scale and offset): the fewer
        # operations, the faster; every form gives the same raw value as cantools' conversion.
        fields = [(s.name, s.start, (1 << s.length) - 1, *_raw_limits(s.length, s.signed), s.scale, s.offset)
                  for s in self.signals]
        self._pack_identity = tuple(f[:5] for f in fields if f[5] == 1 and f[6] == 0)
        self._pack_scaled = tuple(f[:6] for f in fields if f[5] != 1 and f[6] == 0)
        self._pack_linear = tuple(f for f in fields if f[6] != 0)

    def counter_if_intact(self, data: bytes | bytearray) -> int | None:
        """The counter of a frame of this protected message if its CRC is right, else None (the profile's
        check, `bench.e2e.Protection.counter_if_intact`), computed once per distinct frame."""
        protection = self.protection
        assert protection is not None, f"{self.name} is not E2E-protected"
        if type(data) is not bytes:
            return protection.counter_if_intact(data)
        cache = self._intact
        found = cache.get(data, -1)
        if found == -1:
            found = protection.counter_if_intact(data)
            if len(cache) >= INTACT_CACHE:
                cache.clear()
            cache[data] = found
        return found

    # -- values ---------------------------------------------------------------------------------
    def start_values(self) -> dict[str, float]:
        """Physical start values from `GenSigStartValue` (a raw value, per DBC convention; raw 0 without one).
        A start value outside the signal's range starts at the nearest end of it (`bench dbc check` warns of it):
        an OEM's database may carry one, and the first frame must not stop the run."""
        values: dict[str, float] = {}
        for sig, s in zip(self.message.signals, self.signals):
            raw = sig.raw_initial if sig.raw_initial is not None else 0
            value = raw * s.scale + s.offset
            slack = RANGE_SLACK * abs(s.scale)
            if s.minimum is not None and value < s.minimum - slack:
                value = s.minimum
            elif s.maximum is not None and value > s.maximum + slack:
                value = s.maximum
            values[s.name] = value
        return values

    def signal(self, name: str) -> SignalCodec:
        """The signal of that name; a SignalError naming the message, the name meant and its signals if none."""
        sig = self.by_name.get(name)
        if sig is None:
            raise SignalError(f"message {self.name} has no signal {name!r}{did_you_mean(name, self.signal_names)} "
                              f"(signals: {', '.join(self.signal_names)})")
        return sig

    def physical(self, signal: str, value: float | int | str) -> float:
        """A checked physical value: value-table names resolved, NaN and out-of-range refused."""
        sig = self.signal(signal)
        if isinstance(value, str):
            if not sig.choices:   # a text for a signal that has no names: a number typed with its unit, say
                unit = f" in {sig.unit}" if sig.unit else ""
                raise SignalError(f"{self.name}.{signal}: {value!r} is not a number (give a number{unit}; "
                                  "the signal has no value table)")
            if value not in sig.choices:
                raise SignalError(f"{self.name}.{signal}: {value!r}{did_you_mean(value, sig.choices)} is not in its "
                                  f"value table ({', '.join(sig.choices)})")
            return float(sig.choices[value])
        try:
            number = float(value)
        except (TypeError, ValueError):
            raise SignalError(f"{self.name}.{signal}: {value!r} is not a number") from None
        if not math.isfinite(number):
            raise SignalError(f"{self.name}.{signal}: {value!r} is not a finite number")
        if not sig.in_range(number):
            raise SignalError(f"{self.name}.{signal}: {number:g} {sig.unit} is outside the DBC range "
                              f"[{sig.minimum:g}, {sig.maximum:g}]{sig.narrowed}")
        return number

    # -- frames ---------------------------------------------------------------------------------
    def encode(self, values: Mapping[str, float], strict: bool = False) -> bytearray:
        """Payload with every signal from `values` (physical values; E2E bytes zero), as cantools encodes it.

        A raw value outside its bit field raises EncodeError (never wraps). `strict` adds cantools'
        own strict checks (cantools' EncodeError): exactly the signals the frame needs, each inside
        its DBC range; the bench's default leaves the range to `checked` (half a step of slack)."""
        if strict:
            self.message.assert_signals_encodable(values, scaling=True)
        if not self.fast:
            return self._encode_cantools(values)
        word = 0
        try:
            for name, start, mask, lo, hi in self._pack_identity:
                raw = round(values[name])
                if not lo <= raw <= hi:
                    raise _Misfit
                word |= (raw & mask) << start
            for name, start, mask, lo, hi, scale in self._pack_scaled:
                raw = round(values[name] / scale)
                if not lo <= raw <= hi:
                    raise _Misfit
                word |= (raw & mask) << start
            for name, start, mask, lo, hi, scale, offset in self._pack_linear:
                raw = round((values[name] - offset) / scale)
                if not lo <= raw <= hi:
                    raise _Misfit
                word |= (raw & mask) << start
        except Exception:   # noqa: BLE001 - not a number that fits (a name, NaN, too large...): cantools decides
            return self._encode_cantools(values)
        return bytearray(word.to_bytes(self.length, "little"))

    def _encode_cantools(self, values: Mapping[str, float]) -> bytearray:
        """cantools' encoding, or its error; a raw value that does not fit its field raises EncodeError."""
        data = values if isinstance(values, dict) else dict(values)
        try:
            encoded = self.message.encode(data, scaling=True, strict=False, padding=False)
        except FIELD_OVERFLOW as exc:
            raise EncodeError(f"{self.name}: {self._misfit(data) or exc}") from exc
        return bytearray(encoded)

    def _misfit(self, values: Mapping[str, object]) -> str | None:
        """Which value does not fit its field, as cantools converts it (for the error message)."""
        for sig in self.message.signals:
            value = values.get(sig.name)
            if sig.is_float or not isinstance(value, (int, float)):
                continue
            try:
                raw = sig.conversion.numeric_scaled_to_raw(value)
            except (ArithmeticError, ValueError):
                continue
            lo, hi = _raw_limits(sig.length, sig.is_signed)
            if not lo <= raw <= hi:
                kind = "signed" if sig.is_signed else "unsigned"
                return (f"{sig.name} = {value!r} is raw {raw}, outside its {sig.length}-bit {kind} field "
                        f"[{lo}, {hi}]")
        return None

    def decode(self, data: bytes | bytearray) -> dict[str, float]:
        """Physical values of every signal (enumerations as numbers), as cantools decodes them; a payload
        shorter than the message raises DecodeError, a longer one is read up to the message's length."""
        if not self.fast:
            try:
                decoded: Any = self.message.decode(bytes(data), decode_choices=False, scaling=True)
            except Exception as exc:   # cantools' DecodeError and friends: bus data never raises here
                raise DecodeError(f"{self.name}: {exc}") from None
            return {k: v if type(v) is int and not -_EXACT_LIMIT <= v <= _EXACT_LIMIT else float(v)
                    for k, v in decoded.items()}
        return self._cached(data)[1]

    def decode_checked(self, data: bytes | bytearray) -> tuple[dict[str, float], tuple[str, ...]]:
        """`decode` and `out_of_range` of a frame (the monitor, every frame): the names out of range are
        computed once per distinct payload (the fields of a plain counter and checksum are never out)."""
        if not self.fast:
            values = self.decode(data)
            return values, tuple(self.out_of_range(values))
        memo = self._checked
        if type(data) is bytes:
            found = memo.get(data)
            if found is not None:
                return found
        entry, values = self._cached(data)
        bad = entry[2]
        if bad is None:
            bad = tuple(self.out_of_range(values))
            self._entry = (entry[0], entry[1], bad)
        if type(data) is bytes:   # a pure function of the frame's bytes: remembered whole
            if len(memo) >= INTACT_CACHE:
                memo.clear()
            memo[data] = values, bad
        return values, bad

    def _cached(self, data: bytes | bytearray) -> tuple[tuple[int, dict[str, float], tuple[str, ...] | None],
                                                        dict[str, float]]:
        """The cache entry of a fast-path payload (decoded again when its body changed) and a copy of its values
        with this frame's counter and checksum."""
        if len(data) < self.length:
            raise DecodeError(f"{self.name}: {len(data)} bytes, the message has {self.length}")
        word = int.from_bytes(data, "little")
        entry = self._entry
        if word & self._body_mask != entry[0]:
            entry = self._decode_word(word)
        values = entry[1].copy()
        for name, shift, mask in self._e2e_fields:
            raw = (word >> shift) & mask
            values[name] = _FLOATS[raw] if raw < 256 else float(raw)
        return entry, values

    def _decode_word(self, word: int) -> tuple[int, dict[str, float], tuple[str, ...] | None]:
        out: dict[str, float] = {}
        if self._no_offset:
            for name, start, mask, sign_bit, span, scale in self._unpack:
                raw = (word >> start) & mask
                if raw & sign_bit:
                    raw -= span
                out[name] = raw * scale
        else:
            for name, start, mask, sign_bit, span, scale, offset in self._unpack:
                raw = (word >> start) & mask
                if raw & sign_bit:
                    raw -= span
                out[name] = raw * scale + offset
        entry = self._entry = (word & self._body_mask, out, None)
        return entry

    def out_of_range(self, values: Mapping[str, float]) -> list[str]:
        """Names of the signals whose decoded value lies outside the DBC range."""
        bounds = self._bounds
        for name, value in values.items():   # the fast common case: every value in range (NaN fails)
            lo, hi = bounds[name]
            if not lo <= value <= hi:
                break
        else:
            return []
        return [s.name for s in self.signals if not s.in_range(values[s.name])]

    def checked(self, values: Mapping[str, float | int | str]) -> dict[str, float]:
        """Every value checked as `physical` does (the restbus, once per frame): plain in-range floats
        pass on a fast path, anything else (names, ints, NaN, out of range) takes the careful one."""
        bounds = self._bounds
        out: dict[str, float] = {}
        for name, value in values.items():
            limits = bounds.get(name)
            if limits is not None and type(value) is float and limits[0] <= value <= limits[1]:
                out[name] = value
            else:
                out[name] = self.physical(name, value)
        return out


def variants(tree: Sequence[Any]) -> list[tuple[dict[str, int], tuple[str, ...]]]:
    """The frames a multiplexed message can be (cantools' `signal_tree`, cascaded multiplexers included): each the
    values of its multiplexers and the signals it carries, in the database's order."""
    found: list[tuple[dict[str, int], tuple[str, ...]]] = [({}, ())]
    for node in tree:
        if isinstance(node, str):
            found = [(chosen, (*names, node)) for chosen, names in found]
            continue
        for multiplexer, branches in node.items():
            found = [({**chosen, multiplexer: value, **inner}, (*names, multiplexer, *inner_names))
                     for chosen, names in found for value, branch in branches.items()
                     for inner, inner_names in variants(branch)]
    return found


def field_range(signal: Signal) -> tuple[float, float]:
    """(lowest, highest) physical value an integer signal's raw field carries at its scale and offset."""
    raw_lo, raw_hi = _raw_limits(signal.length, signal.is_signed)
    scale, offset = float(signal.scale), float(signal.offset)
    lo, hi = sorted((raw_lo * scale + offset, raw_hi * scale + offset))
    return lo, hi


def carried_range(signal: Signal) -> dict[str, Any]:
    """The signal's range as the bench judges it: the DBC's, narrowed to what its raw field carries when the DBC
    declares more than half a step beyond it (an OEM's database may; `bench dbc check` warns, `--strict` refuses:
    one rule for both). A value outside the field would not fit the frame: refused when a case or the restbus sets
    it, never wrapped."""
    minimum = None if signal.minimum is None else float(signal.minimum)
    maximum = None if signal.maximum is None else float(signal.maximum)
    if signal.is_float or minimum is None or maximum is None or not 0 < signal.length <= 64 or signal.scale == 0:
        return {"minimum": minimum, "maximum": maximum}
    lo, hi = field_range(signal)
    tol = RANGE_SLACK * abs(float(signal.scale)) + 1e-9 * max(1.0, abs(lo), abs(hi))
    if lo - tol <= minimum and maximum <= hi + tol:
        return {"minimum": minimum, "maximum": maximum}
    kind = "signed" if signal.is_signed else "unsigned"
    return {"minimum": max(minimum, lo), "maximum": min(maximum, hi),
            "narrowed": f" (the DBC declares [{minimum:g}, {maximum:g}], more than its {signal.length}-bit {kind} "
                        "field carries)"}


def _raw_limits(length: int, signed: bool) -> tuple[int, int]:
    if signed:
        return -(1 << (length - 1)), (1 << (length - 1)) - 1
    return 0, (1 << length) - 1


def _plain_raw(signal: SignalCodec) -> bool:
    """An unsigned raw number (scale 1, offset 0) whose DBC range, if any, holds every value of its field."""
    return (not signal.signed and signal.scale == 1 and signal.offset == 0
            and (signal.minimum is None or signal.minimum <= 0)
            and (signal.maximum is None or signal.maximum >= (1 << signal.length) - 1))


def _float_exact(signal: Signal) -> bool:
    """Whether doubles give exactly cantools' numbers for this integer signal: cantools computes in
    integers when scale and offset are integers, so every raw value times the scale, plus the offset,
    must stay where doubles hold integers exactly."""
    lo, hi = _raw_limits(signal.length, signal.is_signed)
    scale, offset = Fraction(signal.scale), Fraction(signal.offset)
    largest = max(abs(lo), abs(hi)) * abs(scale) + abs(offset)
    return max(abs(lo), abs(hi)) <= _EXACT_LIMIT and largest <= _EXACT_LIMIT


class Codebook:
    """Every message of the loaded databases, by frame_id (a received frame's `frame_id & bench.canid.IDENTITY`) and
    by name."""

    def __init__(self, databases: Iterable[tuple[str, Database]],
                 e2e_overrides: Mapping[str, Mapping[str, Any]] | None = None,
                 message_overrides: overrides.MessageOverrides | None = None) -> None:
        """`e2e_overrides`: bench.toml's `[e2e]` table, message name -> AUTOSAR parameters over the database's;
        `message_overrides`: its `[messages]` table (bench.database.overrides)."""
        self.databases: list[tuple[str, Database]] = list(databases)
        self.by_id: dict[int, MessageCodec] = {}
        self.by_name: dict[str, MessageCodec] = {}
        protections = dict(e2e_overrides or {})
        names = [m.name for _, db in self.databases for m in db.messages]
        for name in protections:
            if name not in names:
                raise DatabaseError(f"bench.toml: [e2e] {name}: no such message{did_you_mean(name, names)}")
        unknown = overrides.unknown_messages(message_overrides, names)
        if unknown:
            raise DatabaseError(unknown[0])
        for db_name, db in self.databases:
            definitions: Mapping[str, Any] = (db.dbc.attribute_definitions if db.dbc is not None else None) or {}
            for message in db.messages:
                try:
                    protection = e2e.protection(message, definitions, protections.get(message.name))
                except e2e.ProtectionError as exc:
                    over = f" (with bench.toml [e2e.{message.name}])" if message.name in protections else ""
                    raise DatabaseError(f"{db_name}{over}: {exc}") from None
                cycle_ms = overrides.cycle_time_ms(message_overrides, message.name)
                try:
                    codec = MessageCodec(message, db_name, protection, cycle_ms, definitions,
                                         overrides.send_type(message_overrides, message.name))
                except sendtype.SendTypeError as exc:
                    raise DatabaseError(f"{db_name}: message {message.name}: {exc}; "
                                        + overrides.hint(message.name, overrides.SEND_TYPE, '"cyclic"')) from None
                other = self.by_id.get(codec.frame_id) or self.by_name.get(codec.name)
                if other is not None:
                    raise DatabaseError(
                        f"{db_name}: message {codec.name} ({canid.text(codec.frame_id)}) clashes with "
                        f"{other.name} ({canid.text(other.frame_id)}) of {other.database}")
                self.by_id[codec.frame_id] = codec
                self.by_name[codec.name] = codec

    def __getitem__(self, name: str) -> MessageCodec:
        try:
            return self.by_name[name]
        except KeyError:
            raise SignalError(f"no message {name!r}{did_you_mean(name, self.by_name)} in "
                              f"{', '.join(n for n, _ in self.databases)}") from None

    def sent_by(self, nodes: Iterable[str]) -> list[MessageCodec]:
        wanted = set(nodes)
        return [c for c in self.by_id.values() if wanted.intersection(c.senders)]

    @property
    def nodes(self) -> list[str]:
        seen: dict[str, None] = {}
        for _, db in self.databases:
            for node in db.nodes:
                seen[node.name] = None
        return list(seen)


def load_dbc(path: Path | str) -> Database:
    """Load a DBC (or an ARXML system description, by its suffix) strictly; any problem becomes a DatabaseError
    naming the file."""
    path = Path(path)
    if not path.is_file():
        raise DatabaseError(f"{path}: no such DBC file")
    kind = "arxml" if path.suffix.lower() == ".arxml" else "dbc"
    try:
        return cast(Database, cantools.database.load_file(str(path), database_format=kind, strict=True))
    except Exception as exc:  # cantools raises several types; every one is a bad file for us
        raise DatabaseError(f"{path}: {exc}") from None


#: Codebooks loaded in this process (load_codebook), the most recent last; a few, for a process that loads others.
_LOADED: dict[tuple[object, ...], Codebook] = {}
LOADED_KEPT = 4


def _file_key(path: Path) -> tuple[object, ...]:
    """What identifies a database file's content cheaply: its name as given, where it is, its size and its time."""
    try:
        stat = path.stat()
    except OSError:
        return (path.name, str(path), None, None)       # not there: load_dbc says so
    return (path.name, str(path.resolve()), stat.st_size, stat.st_mtime_ns)


def load_codebook(paths: Iterable[Path | str],
                  e2e_overrides: Mapping[str, Mapping[str, Any]] | None = None,
                  message_overrides: overrides.MessageOverrides | None = None) -> Codebook:
    """The databases' messages; `e2e_overrides` is bench.toml's [e2e] table (message -> AUTOSAR parameters), given
    by every caller that loads a project's databases so that each process applies the same protection;
    `message_overrides` its [messages] table (cycle times and send types over the databases').

    Parsed once per process: the same files (path, size, modification time) with the same overrides give the same
    Codebook again (it does not change once built). Why: `bench run`'s checks, the pytest plugin (twice) and the
    session each asked for the project's databases, and cantools parsed them every time (3 to 5 times a run);
    the log process, a program of its own, parses them once in its own process."""
    files = [Path(p) for p in paths]
    given = [e2e_overrides or {}, message_overrides or {}]
    key = (tuple(_file_key(p) for p in files), json.dumps(given, sort_keys=True, default=repr))
    codebook = _LOADED.pop(key, None)
    if codebook is None:
        codebook = Codebook(((p.name, load_dbc(p)) for p in files), e2e_overrides, message_overrides)
    _LOADED[key] = codebook
    while len(_LOADED) > LOADED_KEPT:
        del _LOADED[next(iter(_LOADED))]
    return codebook
