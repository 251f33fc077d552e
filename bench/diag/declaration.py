"""The diagnostic description of a project: addresses, DTCs, DIDs and routines of each node, read once.

One file (bench.toml `[diagnostics] file`, in this repository `dbc/diagnostics.toml`) is the only source of the
tables: the bench's simulated nodes serve it, the bench's tester decodes with it and the contract documents
describe it. TOML rather than ODX: a supplier reads and diffs it without an authoring tool, and every table the
cases need (DTC, status rules, snapshot DIDs, coding limits) fits in a page (docs/contract/diagnostics.md says
why in full).
"""

from __future__ import annotations

import math
import re
import struct
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from bench import canid
from bench.errors import ConfigError, did_you_mean

if TYPE_CHECKING:
    from bench.database.codec import Codebook

#: values a DID may take from the bench itself (`source`): the node's operating time since its power-up, s
SOURCES = ("operating_time",)
#: struct formats of the DID value types (big-endian, ISO 14229-1's byte order)
_FORMATS = {"uint8": ">B", "int8": ">b", "uint16": ">H", "int16": ">h", "uint32": ">I", "int32": ">i"}
_DTC_CODE = re.compile(r"^([PCBU])([0-3])([0-9A-F]{3})-([0-9A-F]{2})$")
_LETTERS = "PCBU"


def dtc_number(code: str) -> int:
    """The 3-byte DTC of an ISO 15031-6 / SAE J2012 code such as 'C1A01-1C' (letter, 4 digits, failure type)."""
    match = _DTC_CODE.match(code.upper())
    if match is None:
        raise ValueError(f"DTC code {code!r} is not of the form C1234-5F (P/C/B/U, a digit 0-3, three hex "
                         f"digits, '-', a failure-type byte in hex)")
    letter, first, rest, ftb = match.groups()
    return (_LETTERS.index(letter) << 22) | (int(first) << 20) | (int(rest, 16) << 8) | int(ftb, 16)


def dtc_code(number: int) -> str:
    """The ISO 15031-6 text of a 3-byte DTC: the inverse of `dtc_number`."""
    return f"{_LETTERS[(number >> 22) & 3]}{(number >> 20) & 3}{(number >> 8) & 0xFFF:03X}-{number & 0xFF:02X}"


@dataclass(frozen=True)
class Did:
    """A data identifier: how its bytes map to a physical value (or ASCII text)."""

    id: int
    name: str
    type: str
    length: int
    scale: float = 1.0
    offset: float = 0.0
    unit: str = ""
    signal: str = ""                                # a live DID equal to this "Message.Signal" the node sends
    input: str = ""                                 # a live DID equal to the last valid "Message.Signal" it read
    source: str = ""                                # a value the bench knows of any node: SOURCES
    values: Mapping[str, int] = field(default_factory=dict)   # an enumeration's names
    write: bool = False                             # coding: written with 0x2E in the extended session, unlocked
    default: float = 0.0
    minimum: float = -math.inf
    maximum: float = math.inf

    def encode(self, value: float | str) -> bytes:
        """The DID's bytes for a physical value (or text); ValueError names the DID and the value."""
        if self.type == "ascii":
            text = str(value)
            raw = text.encode("ascii", errors="replace")[: self.length]
            return raw.ljust(self.length, b" ")
        if isinstance(value, str):
            if value not in self.values:
                raise ValueError(f"DID 0x{self.id:04X} {self.name}: {value!r} is none of {', '.join(self.values)}")
            number = self.values[value]
        else:
            if not math.isfinite(value):
                raise ValueError(f"DID 0x{self.id:04X} {self.name}: {value!r} is not a finite number")
            number = round((value - self.offset) / self.scale)
        fmt = _FORMATS[self.type]
        try:
            return struct.pack(fmt, number)
        except struct.error:
            raise ValueError(f"DID 0x{self.id:04X} {self.name}: {value!r} does not fit its {self.type}") from None

    def decode(self, data: bytes) -> float | str:
        """The physical value (or text) of the DID's bytes; ValueError when their length is wrong."""
        if len(data) != self.length:
            raise ValueError(f"DID 0x{self.id:04X} {self.name}: {len(data)} bytes, expected {self.length}")
        if self.type == "ascii":
            return data.decode("ascii", errors="replace").rstrip(" \x00")
        number: int = struct.unpack(_FORMATS[self.type], data)[0]
        if self.values:
            return float(number)
        return number * self.scale + self.offset

    def in_range(self, value: float) -> bool:
        return self.minimum <= value <= self.maximum


@dataclass(frozen=True)
class Dtc:
    """One diagnostic trouble code: the fault condition it records and how it is confirmed."""

    code: str
    number: int
    name: str
    text: str
    requirement: str
    fault: str            # "Message.Signal" whose value `name` is the bus reaction, or ""
    confirm: float        # s of continuous failure in one operation cycle before confirmedDTC
    warning_indicator: bool


@dataclass(frozen=True)
class Routine:
    id: int
    name: str
    duration: float       # s: the node answers responsePending (NRC 0x78) meanwhile


@dataclass(frozen=True)
class NodeDiagnostics:
    """One node's diagnostic description."""

    node: str
    request: int
    response: int
    security_constant: int
    dids: tuple[Did, ...]                 # identification, the snapshot's common DIDs and the node's own
    identification: Mapping[str, str]     # the reference ECU's identification values by DID name
    snapshot: tuple[int, ...]             # DIDs of snapshot record 0x01, in order
    dtcs: tuple[Dtc, ...]
    routines: tuple[Routine, ...]

    def did(self, key: int | str) -> Did:
        """A DID by id or name; KeyError names the node and what it has."""
        for did in self.dids:
            if did.id == key or did.name == key:
                return did
        shown = f"0x{key:04X}" if isinstance(key, int) else repr(key)
        raise KeyError(f"{self.node}: no DID {shown} (DIDs: "
                       f"{', '.join(f'0x{d.id:04X} {d.name}' for d in self.dids)})")

    def dtc(self, key: int | str) -> Dtc:
        """A DTC by number, code or name; KeyError names the node and what it has."""
        for dtc in self.dtcs:
            if key in (dtc.number, dtc.code, dtc.name):
                return dtc
        shown = f"0x{key:06X}" if isinstance(key, int) else repr(key)
        raise KeyError(f"{self.node}: no DTC {shown} (DTCs: {', '.join(f'{d.code} {d.name}' for d in self.dtcs)})")

    def routine(self, key: int | str) -> Routine:
        for routine in self.routines:
            if key in (routine.id, routine.name):
                return routine
        shown = f"0x{key:04X}" if isinstance(key, int) else repr(key)
        raise KeyError(f"{self.node}: no routine {shown} (routines: "
                       f"{', '.join(f'0x{r.id:04X} {r.name}' for r in self.routines) or 'none'})")


@dataclass(frozen=True)
class Protocol:
    """What every node of the project shares: timing, the functional address, the fault memory's rules."""

    functional_request: int = 0x7DF
    padding: int = 0xCC
    p2: float = 0.050
    p2_star: float = 2.0
    s3: float = 5.0
    block_size: int = 0
    stmin: float = 0.0
    n_bs: float = 1.0
    n_cr: float = 1.0
    security_attempts: int = 3
    security_delay: float = 10.0
    aging_cycles: int = 3
    healing_cycles: int = 1


@dataclass(frozen=True)
class Declaration:
    path: Path
    protocol: Protocol
    nodes: Mapping[str, NodeDiagnostics]

    def node(self, name: str) -> NodeDiagnostics:
        try:
            return self.nodes[name]
        except KeyError:
            raise KeyError(f"{self.path.name}: node {name!r} has no diagnostics (nodes with diagnostics: "
                           f"{', '.join(self.nodes) or 'none'})") from None

    def by_request(self) -> dict[int, NodeDiagnostics]:
        return {n.request: n for n in self.nodes.values()}

    def problems(self, codebook: Codebook) -> list[str]:
        """What the declaration names that the databases do not have, one line each (checked before the first
        case): each node, and each identifier as a diagnostic message (DiagRequest / DiagResponse = Yes)."""
        found = []
        for node in self.nodes.values():
            where = f"{self.path}: [nodes.{node.node}]"
            if node.node not in codebook.nodes:
                found.append(f"{where}: node {node.node!r}{did_you_mean(node.node, codebook.nodes)} is in none of "
                             f"the databases (nodes: {', '.join(codebook.nodes)})")
            for key, frame_id, kind in (("request", node.request, "request"), ("response", node.response, "response")):
                codec = codebook.by_id.get(frame_id)
                if codec is None:
                    found.append(f"{where} {key}: {canid.text(frame_id)} is no message of the databases (declare it "
                                 f"with the attribute Diag{kind.title()} = Yes)")
                elif codec.diagnostic != kind:
                    found.append(f"{where} {key}: {canid.text(frame_id)} is {codec.name}, not a diagnostic {kind} "
                                 f"(its database's attribute Diag{kind.title()} is not Yes)")
            for did in node.dids:
                for key, name in (("signal", did.signal), ("input", did.input)):
                    message, _, signal = name.partition(".")
                    codec = codebook.by_name.get(message)
                    if name and (codec is None or signal not in codec.by_name):
                        found.append(f"{where} DID 0x{did.id:04X} {did.name}: {key} {name!r} is in none of the "
                                     f"databases")
        functional = self.protocol.functional_request
        codec = codebook.by_id.get(functional)
        if codec is None or codec.diagnostic != "request":
            found.append(f"{self.path}: [protocol] functional_request: {canid.text(functional)} is no diagnostic "
                         f"request message of the databases")
        return found

    def diagnostic_ids(self) -> frozenset[int]:
        """Every identifier of the diagnostic traffic: the functional request and each node's pair."""
        ids = {self.protocol.functional_request}
        for node in self.nodes.values():
            ids.update((node.request, node.response))
        return frozenset(ids)


class _Reader:
    """Reads one table with one line per problem: file, table, key and what is wrong."""

    def __init__(self, path: Path, where: str, table: Mapping[str, Any]) -> None:
        self.path, self.where, self.table = path, where, table

    def fail(self, key: str, what: str) -> ConfigError:
        return ConfigError(f"{self.path}: {self.where} {key}: {what}")

    def number(self, key: str, default: float | None = None, *, integer: bool = False,
               low: float = -math.inf, high: float = math.inf) -> float:
        if key not in self.table:
            if default is None:
                raise self.fail(key, "missing")
            return default   # the caller's, not the file's: it may be infinite (min/max: no limit)
        value = self.table[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise self.fail(key, f"{value!r} is not a number")
        if integer and not isinstance(value, int):
            raise self.fail(key, f"{value!r} is not an integer")
        if not low <= value <= high:
            raise self.fail(key, f"{value!r} is outside {low:g}..{high:g}")
        return value

    def integer(self, key: str, default: int | None = None, low: float = 0, high: float = math.inf) -> int:
        return int(self.number(key, default, integer=True, low=low, high=high))

    def text(self, key: str, default: str | None = None) -> str:
        value = self.table.get(key, default)
        if not isinstance(value, str) or (default is None and not value):
            raise self.fail(key, "missing" if value is None else f"{value!r} is not a text")
        return value

    def flag(self, key: str, default: bool) -> bool:
        value = self.table.get(key, default)
        if not isinstance(value, bool):
            raise self.fail(key, f"{value!r} is not true or false")
        return value

    def tables(self, key: str) -> list[Mapping[str, Any]]:
        value = self.table.get(key, [])
        if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
            raise self.fail(key, "is not an array of tables ([[...]])")
        return value


def _did(path: Path, where: str, table: Mapping[str, Any]) -> Did:
    r = _Reader(path, where, table)
    did_id = r.integer("id", high=0xFFFF)
    where = f"{where} 0x{did_id:04X}"
    r = _Reader(path, where, table)
    kind = r.text("type")
    if kind != "ascii" and kind not in _FORMATS:
        raise r.fail("type", f"{kind!r} is none of ascii, {', '.join(_FORMATS)}")
    length = r.integer("length", low=1, high=4000) if kind == "ascii" else struct.calcsize(_FORMATS[kind])
    values = table.get("values", {})
    if not isinstance(values, dict) or not all(isinstance(v, int) for v in values.values()):
        raise r.fail("values", "is not a table of names = integers")
    scale = r.number("scale", 1.0)
    if scale == 0:
        raise r.fail("scale", "is 0")
    write = r.flag("write", False)
    source = r.text("source", "")
    if source and source not in SOURCES:
        raise r.fail("source", f"{source!r} is none of {', '.join(SOURCES)}")
    return Did(did_id, r.text("name"), kind, length, scale, r.number("offset", 0.0), r.text("unit", ""),
               r.text("signal", ""), r.text("input", ""), source, dict(values), write,
               r.number("default", 0.0 if not write else None),
               r.number("min", -math.inf), r.number("max", math.inf))


def _node(path: Path, name: str, table: Mapping[str, Any], common: list[Did]) -> NodeDiagnostics:
    where = f"[nodes.{name}]"
    r = _Reader(path, where, table)
    own = [_did(path, f"[[nodes.{name}.did]]", t) for t in r.tables("did")]
    dids = common + own
    seen: dict[int, str] = {}
    for did in dids:
        if did.id in seen:
            raise r.fail("did", f"DID 0x{did.id:04X} declared twice ({seen[did.id]} and {did.name})")
        seen[did.id] = did.name
    identification = table.get("identification", {})
    if not isinstance(identification, dict) or not all(isinstance(v, str) for v in identification.values()):
        raise r.fail("identification", "is not a table of DID name = text")
    snapshot = table.get("snapshot", [])
    if not isinstance(snapshot, list) or not all(isinstance(v, int) and v in seen for v in snapshot):
        raise r.fail("snapshot", f"{snapshot!r}: every entry must be the id of a DID of the node")
    dtcs = []
    for t in r.tables("dtc"):
        d = _Reader(path, f"[[nodes.{name}.dtc]] {t.get('code', '?')}", t)
        code = d.text("code")
        try:
            number = dtc_number(code)
        except ValueError as exc:
            raise d.fail("code", str(exc)) from None
        dtcs.append(Dtc(code.upper(), number, d.text("name"), d.text("text"), d.text("requirement"),
                        d.text("fault", ""), d.number("confirm_ms", low=0) / 1000.0, d.flag("warning_indicator", True)))
    numbers = [d.number for d in dtcs]
    if len(set(numbers)) != len(numbers):
        raise r.fail("dtc", "two DTCs share a code")
    routines = []
    for t in r.tables("routine"):
        d = _Reader(path, f"[[nodes.{name}.routine]]", t)
        routines.append(Routine(d.integer("id", high=0xFFFF), d.text("name"), d.number("duration_ms", low=0) / 1e3))
    return NodeDiagnostics(name, _frame_id(r.integer("request", high=0x1FFFFFFF)),
                           _frame_id(r.integer("response", high=0x1FFFFFFF)),
                           r.integer("security_constant", high=0xFFFFFFFF), tuple(dids), dict(identification),
                           tuple(snapshot), tuple(dtcs), tuple(routines))


def _frame_id(identifier: int) -> int:
    """A declared identifier as the bench's frame_id (bench.canid): one above 0x7FF is a 29-bit one."""
    return canid.of(identifier, identifier > canid.SFF_MASK)


def load_declaration(path: Path) -> Declaration:
    """Read and check a diagnostic declaration; ConfigError names the file, the table, the key and the problem."""
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read: {exc.strerror or exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from None
    r = _Reader(path, "[protocol]", data.get("protocol", {}))
    ms = 1000.0
    protocol = Protocol(
        _frame_id(r.integer("functional_request", 0x7DF, high=0x1FFFFFFF)), r.integer("padding", 0xCC, high=0xFF),
        r.number("p2_ms", 50, low=1) / ms, r.number("p2_star_ms", 2000, low=1) / ms,
        r.number("s3_ms", 5000, low=1) / ms,
        r.integer("block_size", 0, high=255), r.number("stmin_ms", 0, low=0, high=127) / ms,
        r.number("n_bs_ms", 1000, low=1) / ms, r.number("n_cr_ms", 1000, low=1) / ms,
        r.integer("security_attempts", 3, low=1, high=255), r.number("security_delay_ms", 10000, low=0) / ms,
        r.integer("aging_cycles", 3, low=1, high=255), r.integer("healing_cycles", 1, low=1, high=255))
    top = _Reader(path, "", data)
    common = [_did(path, "[[identification]]", t) for t in top.tables("identification")]
    common += [_did(path, "[[snapshot]]", t) for t in top.tables("snapshot")]
    nodes_table = data.get("nodes", {})
    if not isinstance(nodes_table, dict):
        raise top.fail("nodes", "is not a table of nodes")
    nodes = {name: _node(path, name, table, common) for name, table in nodes_table.items()}
    used: dict[int, str] = {protocol.functional_request: "[protocol] functional_request"}
    for node in nodes.values():
        for key, frame_id in (("request", node.request), ("response", node.response)):
            if frame_id in used:
                raise ConfigError(f"{path}: [nodes.{node.node}] {key}: {canid.text(frame_id)} is also {used[frame_id]}")
            used[frame_id] = f"[nodes.{node.node}] {key}"
    return Declaration(path, protocol, nodes)
