"""DBC loading and per-message codecs.

cantools' database is the single source of truth; from it each message gets a precompiled codec
for its little-endian integer signals (shift, mask, scale), so the hot path of the restbus and of
the monitor costs a few integer operations per signal. Messages the fast path cannot handle
(big-endian, float or multiplexed signals) fall back to cantools. `tests/test_codec.py` proves
both agree bit for bit on every message of the contract.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

import cantools
from cantools.database.can import Database, Message

from bench import e2e
from bench.errors import DatabaseError, SignalError


class DecodeError(ValueError):
    """A payload the database cannot decode (e.g. an unknown multiplexer value)."""

#: A decoded value may exceed the DBC range by this fraction of the scale (rounding) and still be valid.
RANGE_SLACK = 0.5


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


class MessageCodec:
    """Encode and decode one message; E2E bytes are left to `bench.e2e`."""

    def __init__(self, message: Message, database_name: str) -> None:
        self.message = message
        self.database = database_name
        self.name: str = message.name
        self.frame_id: int = message.frame_id
        self.length: int = message.length
        self.senders: tuple[str, ...] = tuple(message.senders)
        cycle_ms = message.cycle_time
        self.cycle_time: float | None = cycle_ms / 1000.0 if cycle_ms else None
        self.signals: tuple[SignalCodec, ...] = tuple(
            SignalCodec(
                name=s.name, start=s.start, length=s.length, signed=s.is_signed,
                scale=float(s.scale), offset=float(s.offset),
                minimum=None if s.minimum is None else float(s.minimum),
                maximum=None if s.maximum is None else float(s.maximum),
                unit=s.unit or "",
                choices={str(name): int(raw) for raw, name in (s.choices or {}).items()},
            )
            for s in message.signals
        )
        self.by_name: dict[str, SignalCodec] = {s.name: s for s in self.signals}
        self.signal_names: tuple[str, ...] = tuple(s.name for s in self.signals)
        # The contract's end-to-end layout (docs/spec/k-matrix.md): only messages that carry it are checked for it.
        layout = {s.name: (s.start, s.length, s.byte_order) for s in message.signals}
        self.e2e = (message.length == 8
                    and layout.get("AliveCounter") == (e2e.COUNTER_BYTE * 8, 4, "little_endian")
                    and layout.get("Checksum") == (e2e.CHECKSUM_BYTE * 8, 8, "little_endian"))
        self.fast = (
            not message.is_multiplexed()
            and all(s.byte_order == "little_endian" and not s.is_float for s in message.signals)
        )
        inf = math.inf
        self._bounds: dict[str, tuple[float, float]] = {
            s.name: (-inf if s.minimum is None else s.minimum - RANGE_SLACK * abs(s.scale),
                     inf if s.maximum is None else s.maximum + RANGE_SLACK * abs(s.scale))
            for s in self.signals}
        self._unpack = tuple(
            (s.name, s.start, (1 << s.length) - 1, (1 << (s.length - 1)) if s.signed else 0,
             1 << s.length, s.scale, s.offset)
            for s in self.signals
        )

    # -- values ---------------------------------------------------------------------------------
    def start_values(self) -> dict[str, float]:
        """Physical start values from `GenSigStartValue` (a raw value, per DBC convention)."""
        values: dict[str, float] = {}
        for sig, s in zip(self.message.signals, self.signals):
            raw = sig.raw_initial if sig.raw_initial is not None else 0
            values[s.name] = raw * s.scale + s.offset
        return values

    def physical(self, signal: str, value: float | int | str) -> float:
        """A checked physical value: value-table names resolved, NaN and out-of-range refused."""
        sig = self.by_name.get(signal)
        if sig is None:
            raise SignalError(f"message {self.name} has no signal {signal!r} "
                              f"(signals: {', '.join(self.signal_names)})")
        if isinstance(value, str):
            if value not in sig.choices:
                raise SignalError(f"{self.name}.{signal}: {value!r} is not in its value table "
                                  f"({', '.join(sig.choices) or 'none'})")
            return float(sig.choices[value])
        try:
            number = float(value)
        except (TypeError, ValueError):
            raise SignalError(f"{self.name}.{signal}: {value!r} is not a number") from None
        if not math.isfinite(number):
            raise SignalError(f"{self.name}.{signal}: {value!r} is not a finite number")
        if not sig.in_range(number):
            raise SignalError(f"{self.name}.{signal}: {number:g} {sig.unit} is outside the DBC range "
                              f"[{sig.minimum:g}, {sig.maximum:g}]")
        return number

    # -- frames ---------------------------------------------------------------------------------
    def encode(self, values: Mapping[str, float]) -> bytearray:
        """Payload with every signal from `values` (checked physical values); E2E bytes zero."""
        if not self.fast:
            data = self.message.encode(dict(values), scaling=True, strict=False, padding=False)
            return bytearray(data)
        word = 0
        for name, start, mask, _, _, scale, offset in self._unpack:
            raw = round((values[name] - offset) / scale)
            word |= (raw & mask) << start
        return bytearray(word.to_bytes(self.length, "little"))

    def decode(self, data: bytes | bytearray) -> dict[str, float]:
        """Physical values of every signal (enumerations as numbers)."""
        if not self.fast:
            try:
                decoded = self.message.decode(bytes(data), decode_choices=False, scaling=True)
            except Exception as exc:   # cantools' DecodeError and friends: bus data never raises here
                raise DecodeError(f"{self.name}: {exc}") from None
            return {k: float(v) for k, v in decoded.items()}
        word = int.from_bytes(data, "little")
        out: dict[str, float] = {}
        for name, start, mask, sign_bit, span, scale, offset in self._unpack:
            raw = (word >> start) & mask
            if raw & sign_bit:
                raw -= span
            out[name] = raw * scale + offset
        return out

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


class Codebook:
    """Every message of the loaded databases, by identifier and by name."""

    def __init__(self, databases: Iterable[tuple[str, Database]]) -> None:
        self.databases: list[tuple[str, Database]] = list(databases)
        self.by_id: dict[int, MessageCodec] = {}
        self.by_name: dict[str, MessageCodec] = {}
        for db_name, db in self.databases:
            for message in db.messages:
                codec = MessageCodec(message, db_name)
                other = self.by_id.get(codec.frame_id) or self.by_name.get(codec.name)
                if other is not None:
                    raise DatabaseError(
                        f"{db_name}: message {codec.name} (0x{codec.frame_id:X}) clashes with "
                        f"{other.name} (0x{other.frame_id:X}) of {other.database}")
                self.by_id[codec.frame_id] = codec
                self.by_name[codec.name] = codec

    def __getitem__(self, name: str) -> MessageCodec:
        try:
            return self.by_name[name]
        except KeyError:
            raise SignalError(f"no message {name!r} in {', '.join(n for n, _ in self.databases)}") from None

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
    """Load a DBC strictly; any problem becomes a DatabaseError naming the file."""
    path = Path(path)
    if not path.is_file():
        raise DatabaseError(f"{path}: no such DBC file")
    try:
        return cantools.database.load_file(str(path), database_format="dbc", strict=True)
    except Exception as exc:  # cantools raises several types; every one is a bad file for us
        raise DatabaseError(f"{path}: {exc}") from None


def load_codebook(paths: Iterable[Path | str]) -> Codebook:
    return Codebook((Path(p).name, load_dbc(p)) for p in paths)
