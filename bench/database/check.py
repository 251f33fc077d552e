"""`bench dbc check`: does a database (DBC or ARXML) meet the bench's needs? Every finding names its line in a
DBC file; an ARXML file has no line numbers, so its findings name the message (and the signal).

Why a checker of its own rather than cantools' strict load: strict loading stops at the first problem
and knows nothing of what the bench relies on — the restbus sends only messages with a cycle time (the database's
or bench.toml's [messages], bench.database.overrides), judges a signal only within what its raw field carries,
starts every signal at its `GenSigStartValue` (at the nearest end of the range when that lies outside it), and
protects and checks every message that declares an AUTOSAR E2E profile (docs/spec/e2e.md).

cantools gives no line numbers for parsed objects, so the text is scanned for `BO_ <id> <name>`,
the ` SG_ <name> ` lines of that message's block, and the `BA_DEF_`/`BA_`/`VAL_` lines naming them.

Severities: an *error* is something the bench would get wrong or refuse (a database with errors is
rejected); a *warning* is something the contract asks for (docs/spec/k-matrix.md: cycle time, send type, unit,
range, start value and comment on everything; value tables for enumerations) whose absence the bench
survives. Two inconsistencies of real databases are warnings saying what the bench does instead (a range wider
than the raw field, a start value outside the range); `strict` (`--strict`, the contract's own databases) makes
them errors.

End-to-end protection is declared per message (`bench.e2e.config`): DBC attributes `E2E_Profile`, `E2E_DataID`,
... (AUTOSAR's parameter names with the prefix `E2E_`), ARXML E2E properties (cantools' `Message.autosar.e2e`),
and, for the databases of a project, bench.toml's `[e2e.MESSAGE]` tables over both. A message that declares a
profile is checked as the bench will load it: a declaration no profile can use (an unsupported profile, a
DataIDList that is not 16 bytes, a header outside the frame, state machine parameters against AUTOSAR's
MinOk + MaxError <= WindowSize, ...) is an error on the message; a signal that overlaps the profile's CRC or
counter field without being exactly that field (the field's bits, Intel, unsigned, scale 1, offset 0) is a
warning naming the signal and the field (the bench writes the field over it). The check also reads the
attribute definitions: an `E2E_` attribute the bench does not know is a warning with the name it most likely
meant (its values would be ignored), as is a profile or DataIDMode choice no profile has; an attribute set but
never defined is cantools' load error, reported on the `BA_` line that sets it.

`--e2e` says whether a message may go without protection: `optional` (the default) — an unprotected message is
fine (the bench judges it on length, timing and ranges; the summary counts protected and unprotected messages);
`required` — every message must declare a profile, an unprotected one is an error (the contract's own
databases are checked that way in CI and in the tests).
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cantools
from cantools.database.can import Database, Message, Signal

from bench import canid
from bench.database import overrides, sendtype
from bench.database.codec import RANGE_SLACK, carried_range, diagnostic_kind, field_range
from bench.e2e import config as e2e_config
from bench.e2e.profiles import P01_MODES, PROFILES, Field, Protection
from bench.errors import DatabaseError, did_you_mean

ERROR, WARNING = "error", "warning"
OPTIONAL, REQUIRED = "optional", "required"
E2E_MODES = (OPTIONAL, REQUIRED)     # --e2e: may a message go without a declared profile?
FRAME_LENGTH = 8                     # docs/spec/k-matrix.md: classical CAN, 8-byte frames
FD_FRAME_LENGTH = canid.FD_LENGTHS[-1]   # ISO 11898-1: a CAN FD frame's longest data field
ARXML_SUFFIX = ".arxml"
#: The E2E attribute names the bench reads (`E2E_` + AUTOSAR's parameter name).
E2E_ATTRIBUTES = tuple(e2e_config.PREFIX + name for name in e2e_config.PARAMETERS)
#: The choices an ENUM definition of these attributes may offer.
E2E_CHOICES = {e2e_config.PREFIX + "Profile": (e2e_config.NONE, *PROFILES),
               e2e_config.PREFIX + "DataIDMode": tuple(P01_MODES)}
MAX_QUOTE = 160                      # characters of a parser message kept in a finding
MAX_SIGNAL_BITS = 64                 # the longest integer or float signal a CAN database can mean
MAX_FRAME_BYTES = 64                 # CAN FD; cantools' loader is slow in larger numbers (quadratic in the start bit)


@dataclass(frozen=True)
class Finding:
    """One problem: `kind` is a short stable code (tests and scripts match on it), `text` says what is wrong."""

    severity: str
    kind: str
    text: str
    line: int | None = None
    message: str | None = None
    signal: str | None = None

    def where(self) -> str:
        if self.message and self.signal:
            return f"{self.message}.{self.signal}"
        return self.message or ""


@dataclass(frozen=True)
class MessageProtection:
    """The protection the bench will apply to one message: a Protection, None (unprotected), or `refused` (its
    declaration is an error finding)."""

    name: str
    frame_id: int
    protection: Protection | None
    refused: bool = False
    diagnostic: bool = False   # ISO-TP traffic: no E2E by design, its framing is judged instead

    def describe(self) -> str:
        if self.refused:
            return "declared protection refused (see the error)"
        if self.diagnostic and self.protection is None:
            return "diagnostic (ISO-TP: its framing is checked, no E2E)"
        if self.protection is None:
            return "unprotected"
        return f"{self.protection.describe()} [{self.protection.source}]"


@dataclass
class CheckResult:
    """The findings of one file, sorted by line; `accepted` when none is an error."""

    path: Path
    findings: list[Finding] = field(default_factory=list)
    messages: int = 0
    signals: int = 0
    encoding: str = "utf-8"
    e2e: str = OPTIONAL
    protections: list[MessageProtection] = field(default_factory=list)   # in the database's order

    @property
    def protected(self) -> int:
        return sum(p.protection is not None for p in self.protections)

    @property
    def unprotected(self) -> int:
        return sum(p.protection is None and not p.refused and not p.diagnostic for p in self.protections)

    @property
    def diagnostic(self) -> int:
        return sum(p.protection is None and p.diagnostic for p in self.protections)

    @property
    def errors(self) -> list[Finding]:
        return [f for f in self.findings if f.severity == ERROR]

    @property
    def warnings(self) -> list[Finding]:
        return [f for f in self.findings if f.severity == WARNING]

    @property
    def accepted(self) -> bool:
        return not self.errors


_Add = Callable[..., None]   # add(severity, kind, text, line=None): a finding about the current object


# -- reading -----------------------------------------------------------------------------------------
def read_text(path: Path) -> tuple[str, str]:
    """(text, encoding): UTF-8 when the bytes are valid UTF-8, else cp1252 (what DBC editors write,
    and cantools' default); bytes undefined in cp1252 become U+FFFD rather than failing."""
    try:
        raw = path.read_bytes()
    except IsADirectoryError:
        raise DatabaseError(f"{path}: is a folder, not a DBC file") from None
    except OSError as exc:
        raise DatabaseError(f"{path}: cannot read: {exc.strerror or exc}") from None
    try:
        return raw.decode("utf-8"), "utf-8"
    except UnicodeDecodeError:
        return raw.decode("cp1252", errors="replace"), "cp1252"


# -- where things are in the text --------------------------------------------------------------------
_BO = re.compile(r"^\s*BO_\s+(\d+)\s+([A-Za-z0-9_]+)\s*:(?:\s*(\d+))?")
_SG = re.compile(r"^\s*SG_\s+([A-Za-z0-9_]+)(?:[^:]*:\s*(\d+)\s*\|\s*(\d+))?")
_KEYWORD = re.compile(r"^\s*([A-Z][A-Z0-9_]*)")
_BA_MSG = re.compile(r'^\s*BA_\s+"([A-Za-z0-9_]+)"\s+BO_\s+(\d+)\s')
_BA_SIG = re.compile(r'^\s*BA_\s+"([A-Za-z0-9_]+)"\s+SG_\s+(\d+)\s+([A-Za-z0-9_]+)')
_BA_ANY = re.compile(r'^\s*BA_\s+"([A-Za-z0-9_]+)"')
_BA_DEF = re.compile(r'^\s*BA_DEF_\s+(?:(BU_|BO_|SG_|EV_)\s+)?"([A-Za-z0-9_]+)"')
_QUOTED_NAME = re.compile(r"^'([A-Za-z0-9_]+)'$")
_VAL = re.compile(r"^\s*VAL_\s+(\d+)\s+([A-Za-z0-9_]+)(.*)$")
_PAIR = re.compile(r'(-?\d+)\s+"((?:[^"\\]|\\.)*)"')
_SYNTAX_LINE = re.compile(r"\bline (\d+)")
_IN_MESSAGE = re.compile(r"in message ([A-Za-z0-9_]+)")


@dataclass
class _ValueTableText:
    line: int
    pairs: list[tuple[int, str]]


class _Lines:
    """Line numbers (1-based, counted on '\\n' as cantools' parser does) of the definitions in the text."""

    def __init__(self, text: str) -> None:
        self.message: dict[str, int] = {}
        self.block: dict[tuple[int, str], int] = {}      # (DBC id, name) of a BO_ line -> line
        self.message_by_id: dict[int, int] = {}
        self.name_by_id: dict[int, str] = {}
        self.signal: dict[tuple[str, str], int] = {}
        self.message_attr: dict[tuple[int, str], int] = {}
        self.signal_attr: dict[tuple[int, str, str], int] = {}
        self.value_tables: dict[tuple[int, str], _ValueTableText] = {}
        self.definition: dict[str, tuple[int, str]] = {}   # attribute name -> (line of its BA_DEF_, object kind)
        self.attribute_set: dict[str, int] = {}            # attribute name -> line of its first BA_
        self.absurd: list[Finding] = []   # numbers no CAN frame can have (cantools would take minutes on them)
        current: str | None = None
        for number, line in enumerate(text.split("\n"), start=1):
            if (m := _BO.match(line)) is not None:
                current = m.group(2)
                if m.group(3) is not None and int(m.group(3)) > MAX_FRAME_BYTES:
                    self.absurd.append(Finding(ERROR, "frame-length", f"length {m.group(3)} bytes: a CAN frame has at "
                                               f"most {MAX_FRAME_BYTES}", number, current))
                self.message.setdefault(current, number)
                self.block.setdefault((int(m.group(1)), current), number)
                self.message_by_id.setdefault(int(m.group(1)), number)
                self.name_by_id.setdefault(int(m.group(1)), current)
            elif (m := _SG.match(line)) is not None:
                if current is not None:
                    self.signal.setdefault((current, m.group(1)), number)
                if m.group(2) is not None and max(int(m.group(2)), int(m.group(3))) >= 8 * MAX_FRAME_BYTES:
                    self.absurd.append(Finding(ERROR, "fit", f"{m.group(3)} bits from bit {m.group(2)}: beyond any "
                                               f"CAN frame ({8 * MAX_FRAME_BYTES} bits)", number, current,
                                               m.group(1)))
            elif (m := _KEYWORD.match(line)) is not None:
                current = None   # any other statement ends the message block
                if (d := _BA_DEF.match(line)) is not None:
                    self.definition.setdefault(d.group(2), (number, d.group(1) or ""))
                elif (b := _BA_ANY.match(line)) is not None:
                    self.attribute_set.setdefault(b.group(1), number)
                if (a := _BA_MSG.match(line)) is not None:
                    self.message_attr.setdefault((int(a.group(2)), a.group(1)), number)
                elif (a := _BA_SIG.match(line)) is not None:
                    self.signal_attr.setdefault((int(a.group(2)), a.group(3), a.group(1)), number)
                elif (v := _VAL.match(line)) is not None:
                    pairs = [(int(raw), name) for raw, name in _PAIR.findall(v.group(3))]
                    self.value_tables.setdefault((int(v.group(1)), v.group(2)), _ValueTableText(number, pairs))

    def of_message(self, message: Message) -> int | None:
        """By id and name (two messages may share either), else by id (cantools may show a long name)."""
        dbc_id = _dbc_id(message)
        line = self.block.get((dbc_id, message.name))
        if line is None:
            line = self.message_by_id.get(dbc_id)
        return line if line is not None else self.message.get(message.name)

    def of_signal(self, message: Message, signal: Signal) -> int | None:
        name = self._block_name(message)
        line = self.signal.get((name, signal.name))
        return line if line is not None else self.of_message(message)

    def _block_name(self, message: Message) -> str:
        """The name in the BO_ line (cantools may show a long name from SystemMessageLongSymbol)."""
        if (_dbc_id(message), message.name) in self.block:
            return message.name
        return self.name_by_id.get(_dbc_id(message), message.name)


def _dbc_id(message: Message) -> int:
    """The number of its BO_ line: a 29-bit identifier with bit 31 set, as SocketCAN writes it (bench.canid)."""
    return canid.of(message.frame_id, message.is_extended_frame)


# -- the check ---------------------------------------------------------------------------------------
Overrides = Mapping[str, Mapping[str, Any]]


def check_file(path: Path | str, e2e_mode: str = OPTIONAL, e2e_overrides: Overrides | None = None,
               message_overrides: Overrides | None = None, strict: bool = False) -> CheckResult:
    """Check one DBC or ARXML file (by its suffix); DatabaseError only when the file cannot be read at all.
    `e2e_overrides`: a project's bench.toml [e2e] table (message name -> parameters), applied to this file's
    messages of those names; `message_overrides`: its [messages] table (cycle times and send types,
    bench.database.overrides); `strict`: what the bench survives in a database but a contract must not have (a range
    wider than its raw field, a start value outside the range) is an error, not a warning."""
    path = Path(path)
    text, encoding = read_text(path)
    kind = "arxml" if path.suffix.lower() == ARXML_SUFFIX else "dbc"
    result = check_text(text, path, e2e_mode, e2e_overrides, database_format=kind, message_overrides=message_overrides,
                        strict=strict)
    result.encoding = encoding
    return result


def check_text(text: str, path: Path | str = "<text>", e2e_mode: str = OPTIONAL,
               e2e_overrides: Overrides | None = None, database_format: str = "dbc",
               message_overrides: Overrides | None = None, strict: bool = False) -> CheckResult:
    """Check DBC (or ARXML) text; never raises on any text (every problem is a finding)."""
    if e2e_mode not in E2E_MODES:
        raise ValueError(f"e2e mode must be one of {', '.join(E2E_MODES)}, got {e2e_mode!r}")
    result = CheckResult(path=Path(path), e2e=e2e_mode)
    lines = _Lines(text if database_format == "dbc" else "")   # ARXML: no line numbers
    findings = result.findings
    if lines.absurd:   # reported alone: loading such a file can take cantools minutes
        findings.extend(lines.absurd)
        return _sorted(result)
    database, strict_error = _load(text, findings, database_format)
    if database is None:
        return _sorted(result)
    supplied = message_overrides or {}
    messages = list(database.messages)
    result.messages = len(messages)
    result.signals = sum(len(m.signals) for m in messages)
    if not messages:
        findings.append(Finding(WARNING, "empty", "no messages: nothing for the bench to send or check",
                                1 if database_format == "dbc" else None))
    _check_duplicates(messages, lines, findings)
    definitions = _attribute_definitions(database)
    _check_e2e_definitions(definitions, lines, findings)
    attribute_defaults = {name: d.default_value for name, d in definitions.items()}
    protections = e2e_overrides or {}
    for message in messages:
        _check_message(message, lines, attribute_defaults, findings, supplied.get(message.name, {}), definitions,
                       strict)
        result.protections.append(_check_e2e(message, definitions, protections.get(message.name), lines,
                                             e2e_mode == REQUIRED, findings))
    if strict_error is not None:
        _add_strict_error(strict_error, lines, findings)
    return _sorted(result)


def _sorted(result: CheckResult) -> CheckResult:
    result.findings.sort(key=lambda f: (f.line or 0, f.severity != ERROR, f.kind))
    return result


def _load(text: str, findings: list[Finding], database_format: str = "dbc") -> tuple[Database | None,
                                                                                 Exception | None]:
    """Strict first (what the bench does); when that fails, non-strict to check the rest."""
    strict_error: Exception | None = None
    try:
        database = cantools.database.load_string(text, database_format=database_format, strict=True)
        if isinstance(database, Database):
            return database, None
    except Exception as exc:  # noqa: BLE001 - cantools raises many types; each is a finding
        strict_error = exc
    try:
        database = cantools.database.load_string(text, database_format=database_format, strict=False)
    except Exception as exc:  # noqa: BLE001
        findings.append(_parse_finding(exc, text if database_format == "dbc" else ""))
        return None, None
    if not isinstance(database, Database):
        findings.append(Finding(ERROR, "load", "not a CAN database", 1))
        return None, None
    return database, strict_error


def _clean(exc: BaseException) -> str:
    """cantools wraps parser errors as 'DBC: "..."'; keep the inner text, shortened, on one line."""
    text = str(exc) or type(exc).__name__
    if text.startswith('DBC: "') and text.endswith('"'):
        text = text[6:-1]
    text = " ".join(text.split())
    return text if len(text) <= MAX_QUOTE else text[: MAX_QUOTE - 1] + "…"


def _parse_finding(exc: BaseException, text: str) -> Finding:
    message = _clean(exc)
    undefined = _QUOTED_NAME.match(message)
    if undefined is not None and undefined.group(1) in (lines := _Lines(text)).attribute_set:
        # cantools' KeyError for an attribute set by a BA_ line that no BA_DEF_ defines
        name = undefined.group(1)
        return Finding(ERROR, "attribute", f"attribute {name} is set but never defined (no BA_DEF_ \"{name}\"): "
                       "cantools cannot load the file", lines.attribute_set[name])
    match = _SYNTAX_LINE.search(message)
    line = int(match.group(1)) if match else None
    if line is None:
        named = _IN_MESSAGE.search(message)
        if named is not None:
            line = _Lines(text).message.get(named.group(1))
    kind = "syntax" if "syntax" in message.lower() else "load"
    return Finding(ERROR, kind, f"cannot load: {message}", line)


def _add_strict_error(exc: Exception, lines: _Lines, findings: list[Finding]) -> None:
    """Report cantools' strict-load error unless one of our own errors on that message says the same."""
    message = _clean(exc)
    named = _IN_MESSAGE.search(message)
    name = named.group(1) if named else None
    covered = {"overlap", "fit", "signal-length", "frame-id"}
    if name and any(f.severity == ERROR and f.message == name and f.kind in covered for f in findings):
        return
    findings.append(Finding(ERROR, "load", f"cantools' strict load fails: {message}",
                            lines.message.get(name) if name else None, name))


def _attribute_definitions(database: Database) -> dict[str, Any]:
    """The database's attribute definitions by name (none for ARXML)."""
    specifics = getattr(database, "dbc", None)
    return dict(getattr(specifics, "attribute_definitions", None) or {})


def _check_duplicates(messages: list[Message], lines: _Lines, findings: list[Finding]) -> None:
    seen_id: dict[tuple[int, bool], str] = {}
    seen_name: set[str] = set()
    for message in messages:
        key = (message.frame_id, message.is_extended_frame)
        if key in seen_id:
            findings.append(Finding(ERROR, "duplicate-id", f"identifier {canid.text(_dbc_id(message))} is also "
                                    f"message {seen_id[key]}", lines.of_message(message), message.name))
        seen_id.setdefault(key, message.name)
        if message.name in seen_name:
            findings.append(Finding(ERROR, "duplicate-name", "a second message of this name",
                                    lines.of_message(message), message.name))
        seen_name.add(message.name)


# -- one message -------------------------------------------------------------------------------------
def _check_message(message: Message, lines: _Lines, defaults: dict[str, object], findings: list[Finding],
                   supplied: Mapping[str, Any], definitions: Mapping[str, Any], strict: bool = False) -> None:
    """`supplied`: bench.toml's [messages.NAME] for this message (what the project gives over its database)."""
    line = lines.of_message(message)
    name = message.name

    def add(severity: str, kind: str, text: str, at: int | None = None) -> None:
        findings.append(Finding(severity, kind, text, at or line, name))

    if message.is_fd:
        if message.length > FD_FRAME_LENGTH:
            add(ERROR, "frame-length", f"length {message.length} bytes: a CAN FD frame carries at most "
                f"{FD_FRAME_LENGTH}")
        elif message.length not in canid.FD_LENGTHS:
            add(WARNING, "frame-length", f"length {message.length} bytes is no CAN FD frame length: its frames go "
                f"out as {canid.fd_length(message.length)} bytes on SocketCAN (the kernel pads)")
    elif message.length > FRAME_LENGTH:
        add(ERROR, "frame-length", f"length {message.length} bytes in a classical CAN frame (at most "
            f"{FRAME_LENGTH}): declare it CAN FD in the database (a DBC: VFrameFormat StandardCAN_FD or "
            "ExtendedCAN_FD)")
    elif message.length != FRAME_LENGTH:
        add(WARNING, "frame-length", f"length {message.length} byte{'s' * (message.length != 1)}: the contract's "
            f"frames are {FRAME_LENGTH} bytes (docs/spec/k-matrix.md); the bench sends and judges it at its length")
    if not message.senders:
        add(WARNING, "sender", "no sender node: no node of the bench will simulate it")
    if not message.comment:
        add(WARNING, "comment", "no comment")
    _check_timing(message, lines, defaults, add, supplied, definitions)
    _check_layout(message, lines, findings)
    for signal in message.signals:
        _check_signal(message, signal, lines, findings, strict)


def _attribute(message: Message, name: str, defaults: dict[str, object]) -> tuple[object, bool]:
    """(value, explicit): the message's own attribute, else the definition's default."""
    attributes = message.dbc.attributes if message.dbc is not None else {}
    if name in attributes:
        return attributes[name].value, True
    return defaults.get(name), False


def _check_timing(message: Message, lines: _Lines, defaults: dict[str, object], add: _Add,
                  supplied: Mapping[str, Any], definitions: Mapping[str, Any]) -> None:
    """The send type (bench.database.sendtype) and, for a periodic one, the cycle time. Each error that bench.toml can
    fix names the key that fixes it (bench.database.overrides)."""
    if diagnostic_kind(message):   # ISO-TP traffic on request: no cycle time, no send type (bench.diag)
        return
    at_type = lines.message_attr.get((_dbc_id(message), "GenMsgSendType"))
    try:
        how = sendtype.sending(message, definitions, supplied.get(overrides.SEND_TYPE))
    except sendtype.SendTypeError as exc:
        add(ERROR, "send-type", f"{exc}; " + overrides.hint(message.name, overrides.SEND_TYPE, '"cyclic"'), at_type)
        return
    if how.source.startswith("no GenMsgSendType"):
        add(WARNING, "send-type",
            f"{how.source}; " + overrides.hint(message.name, overrides.SEND_TYPE, f'"{how.kind}"'))
    if not how.periodic:
        return      # sent when a value is set: no cycle time needed
    cycle_hint = overrides.hint(message.name, overrides.CYCLE_TIME, "<ms>")
    if overrides.CYCLE_TIME in supplied:
        pass   # bench.toml gives it: whatever the database says
    elif message.dbc is None:   # ARXML: the cycle time of the frame's timing, no send type attribute
        if message.cycle_time is None or message.cycle_time <= 0:
            add(ERROR, "cycle-time", f"no cyclic timing: the restbus cannot send it periodically; {cycle_hint}")
    else:
        cycle, explicit = _attribute(message, "GenMsgCycleTime", defaults)
        at = lines.message_attr.get((_dbc_id(message), "GenMsgCycleTime"))
        if cycle is None:
            add(ERROR, "cycle-time", f"no GenMsgCycleTime for its send type {how.kind} ({how.source}): the restbus "
                f"cannot send it periodically; {cycle_hint}")
        elif not isinstance(cycle, (int, float)) or not math.isfinite(cycle) or cycle <= 0:
            origin = "" if explicit else " (the attribute's default; the message sets none)"
            add(ERROR, "cycle-time", f"GenMsgCycleTime {cycle!r}{origin} is not a positive number of ms, and its "
                f"send type {how.kind} ({how.source}) is periodic; {cycle_hint}", at)


def _bits(signal: Signal) -> list[int]:
    """Absolute bit numbers (byte * 8 + bit in byte) the signal occupies; Motorola counts down the sawtooth."""
    if signal.byte_order == "little_endian":
        return list(range(signal.start, signal.start + signal.length))
    bits, position = [], signal.start
    for _ in range(signal.length):
        bits.append(position)
        position = position + 15 if position % 8 == 0 else position - 1
    return bits


def _exclusive(a: Signal, b: Signal) -> bool:
    """Two signals that are never in the same frame (different values of one multiplexer) may share bits."""
    if a.multiplexer_signal is None or b.multiplexer_signal is None:
        return False
    if a.multiplexer_signal != b.multiplexer_signal:
        return True  # cascaded multiplexing: not judged here (the message is reported as multiplexed)
    return not set(a.multiplexer_ids or ()) & set(b.multiplexer_ids or ())


def _check_layout(message: Message, lines: _Lines, findings: list[Finding]) -> None:
    frame_bits = message.length * 8
    owner: dict[int, Signal] = {}
    reported: set[tuple[str, str]] = set()
    for signal in message.signals:
        line = lines.of_signal(message, signal)
        if not 0 < signal.length <= MAX_SIGNAL_BITS:
            findings.append(Finding(ERROR, "signal-length", f"length {signal.length} bits: a signal has 1 to "
                                    f"{MAX_SIGNAL_BITS}", line, message.name, signal.name))
            continue
        bits = _bits(signal)
        outside = [b for b in bits if not 0 <= b < frame_bits]
        if outside:
            findings.append(Finding(ERROR, "fit", f"{signal.length} bits from bit {signal.start} "
                                    f"({signal.byte_order.replace('_', '-')}) do not fit in the "
                                    f"{message.length}-byte frame", line, message.name, signal.name))
        for bit in bits:
            other = owner.get(bit)
            if other is None:
                owner[bit] = signal
            elif not _exclusive(signal, other) and (other.name, signal.name) not in reported:
                reported.add((other.name, signal.name))
                shared = sorted(set(bits) & set(_bits(other)))
                findings.append(Finding(ERROR, "overlap", f"overlaps {other.name} in bit(s) "
                                        f"{_ranges(shared)}", line, message.name, signal.name))


def _ranges(bits: list[int]) -> str:
    parts, start = [], None
    for i, bit in enumerate(bits):
        if start is None:
            start = bit
        if i + 1 == len(bits) or bits[i + 1] != bit + 1:
            parts.append(str(start) if start == bit else f"{start}-{bit}")
            start = None
    return ", ".join(parts)


# -- one signal --------------------------------------------------------------------------------------
def _raw_limits(signal: Signal) -> tuple[int, int]:
    if signal.is_signed:
        return -(1 << (signal.length - 1)), (1 << (signal.length - 1)) - 1
    return 0, (1 << signal.length) - 1


def _g(value: float) -> str:
    return f"{value:.10g}"


def _check_signal(message: Message, signal: Signal, lines: _Lines, findings: list[Finding],
                  strict: bool = False) -> None:
    """`strict`: a range wider than the raw field and a start value outside the range are errors (a contract's
    own databases); else warnings, with what the bench does instead (bench.database.codec)."""
    line = lines.of_signal(message, signal)
    survivable = ERROR if strict else WARNING
    dbc_id = _dbc_id(message)

    def add(severity: str, kind: str, text: str, at: int | None = None) -> None:
        findings.append(Finding(severity, kind, text, at or line, message.name, signal.name))

    if not signal.unit:
        add(WARNING, "unit", "no unit")
    if not signal.comment:
        add(WARNING, "comment", "no comment")
    if not 0 < signal.length <= MAX_SIGNAL_BITS:
        return  # reported by the layout check; nothing below is meaningful
    scale, offset = float(signal.scale), float(signal.offset)
    if signal.is_float and signal.length not in (32, 64):
        add(ERROR, "float", f"a float signal must be 32 or 64 bits, not {signal.length}")
    if scale == 0 or not math.isfinite(scale) or not math.isfinite(offset):
        add(ERROR, "scale", f"scale {_g(scale)} / offset {_g(offset)}: every raw value would decode alike"
            if scale == 0 else f"scale {_g(scale)} / offset {_g(offset)} is not a finite number")
        return
    slack = RANGE_SLACK * abs(scale)
    carried = carried_range(signal)   # the codec's range: the rule of range-raw and of the start value's fallback
    minimum, maximum = signal.minimum, signal.maximum
    if minimum is None or maximum is None:
        add(WARNING, "range", "no range ([0|0]): the monitor cannot judge its values")
    elif minimum > maximum:
        add(ERROR, "range-order", f"range [{_g(minimum)}|{_g(maximum)}]: minimum above maximum")
    elif not signal.is_float:
        if "narrowed" in carried:
            lo, hi = field_range(signal)
            kind = "signed" if signal.is_signed else "unsigned"
            add(survivable, "range-raw", f"range [{_g(minimum)}|{_g(maximum)}] is wider than the {signal.length}-bit "
                f"{kind} raw field can carry at scale {_g(scale)}, offset {_g(offset)}: [{_g(lo)}|{_g(hi)}]"
                + ("" if strict else f"; the bench judges and accepts [{_g(carried['minimum'])}|"
                                     f"{_g(carried['maximum'])}]"))
        if maximum > minimum and maximum - minimum < abs(scale) * (1 - 1e-9):
            add(WARNING, "resolution", f"range [{_g(minimum)}|{_g(maximum)}] is narrower than one step "
                f"({_g(scale)})")
    _check_start_value(message, signal, scale, offset, slack, carried, lines.signal_attr.get(
        (dbc_id, signal.name, "GenSigStartValue")), add, survivable)
    _check_value_table(message, signal, lines, add)


def _check_start_value(message: Message, signal: Signal, scale: float, offset: float, slack: float,
                       carried: Mapping[str, Any], at: int | None, add: _Add, survivable: str = ERROR) -> None:
    """The restbus starts at raw GenSigStartValue (raw 0 when absent); one outside the signal's range starts at the
    nearest end of the range instead (bench.database.codec.MessageCodec.start_values): `survivable` is the
    severity of that (a warning, or an error with --strict). Without a range to fall back to, a raw start value
    outside its field cannot be sent: an error."""
    raw = signal.raw_initial
    if raw is None:
        add(WARNING, "start-value", "no GenSigStartValue: the bench starts it at raw 0")
        raw, origin = 0, "raw 0 (no GenSigStartValue)"
    else:
        origin = f"GenSigStartValue {raw}"
    if not isinstance(raw, (int, float)) or not math.isfinite(raw):
        add(ERROR, "start-value", f"{origin} is not a finite number", at)
        return
    lo, hi = carried["minimum"], carried["maximum"]
    value = raw * scale + offset
    instead = ""
    if lo is not None and value < lo - slack:
        instead = f"; the restbus starts it at {_g(lo)}"
    elif hi is not None and value > hi + slack:
        instead = f"; the restbus starts it at {_g(hi)}"
    if not signal.is_float:
        raw_lo, raw_hi = _raw_limits(signal)
        if not raw_lo <= raw <= raw_hi:
            add(survivable if instead else ERROR, "start-value", f"{origin} does not fit the {signal.length}-bit "
                f"raw field [{raw_lo}|{raw_hi}]" + (instead if survivable == WARNING else ""), at)
            return
    minimum, maximum = signal.minimum, signal.maximum
    if (minimum is not None and value < minimum - slack) or (maximum is not None and value > maximum + slack):
        unit = f" {signal.unit}" if signal.unit else ""
        add(survivable, "start-value", f"{origin} is {_g(value)}{unit}, outside the range "
            f"[{_g(minimum if minimum is not None else -math.inf)}|"
            f"{_g(maximum if maximum is not None else math.inf)}]"
            + (instead if survivable == WARNING else ": the bench refuses it in a contract's own database"), at)


def _check_value_table(message: Message, signal: Signal, lines: _Lines, add: _Add) -> None:
    table_text = lines.value_tables.get((_dbc_id(message), signal.name))
    at = table_text.line if table_text else None
    if table_text is not None and not table_text.pairs:
        add(WARNING, "value-table", "empty value table (VAL_ without entries)", at)
        return
    if table_text is not None:
        raws = [raw for raw, _ in table_text.pairs]
        repeated = sorted({r for r in raws if raws.count(r) > 1})
        if repeated:
            add(WARNING, "value-table", f"value(s) {', '.join(map(str, repeated))} named twice: the last "
                "name wins", at)
    choices: Mapping[int, object] = signal.choices or {}
    if not choices:
        return
    names = [str(n) for n in choices.values()]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        add(WARNING, "value-table", f"name(s) {', '.join(twice)} stand for more than one value: setting "
            "it by name is ambiguous", at)
    if not signal.is_float:
        raw_lo, raw_hi = _raw_limits(signal)
        outside = [int(raw) for raw in choices if not raw_lo <= int(raw) <= raw_hi]
        if outside:
            add(WARNING, "value-table", f"value(s) {', '.join(map(str, outside))} do not fit the "
                f"{signal.length}-bit raw field [{raw_lo}|{raw_hi}]", at)
    if float(signal.scale) != 1 or float(signal.offset) != 0:
        add(WARNING, "value-table", f"value table on a scaled signal (scale {_g(float(signal.scale))}, offset "
            f"{_g(float(signal.offset))}): the bench sets a name's number as the physical value", at)


# -- end-to-end protection ---------------------------------------------------------------------------
def _check_e2e_definitions(definitions: Mapping[str, Any], lines: _Lines, findings: list[Finding]) -> None:
    """The E2E attribute definitions themselves: a name the bench does not know (a typo: its values would be
    ignored), an ENUM choice no profile has, a definition or a value on signals (the bench reads messages')."""
    for name, definition in definitions.items():
        if not name.upper().startswith("E2E"):
            continue
        line, kind = lines.definition.get(name, (None, ""))
        if name not in E2E_ATTRIBUTES:
            findings.append(Finding(WARNING, "e2e-attribute", f"attribute {name} is not an E2E parameter the bench "
                                    f"knows{did_you_mean(name, E2E_ATTRIBUTES)}: its values are ignored (known: "
                                    f"{', '.join(E2E_ATTRIBUTES)})", line))
            continue
        if kind and kind != "BO_":
            findings.append(Finding(WARNING, "e2e-attribute", f"attribute {name} is defined for {kind} objects: "
                                    "the bench reads E2E parameters of messages (BA_DEF_ BO_)", line))
        allowed = E2E_CHOICES.get(name)
        choices = [str(c) for c in (getattr(definition, "choices", None) or ())]
        strange = [c for c in choices if allowed is not None and c not in allowed]
        if strange:
            findings.append(Finding(WARNING, "e2e-attribute", f"attribute {name}: choice(s) "
                                    f"{', '.join(repr(c) for c in strange)} mean nothing to the bench (it knows "
                                    f"{', '.join(allowed or ())}): a message set to one is refused", line))
    for (_, signal, name), line in sorted(lines.signal_attr.items(), key=lambda item: item[1]):
        if name in E2E_ATTRIBUTES:
            findings.append(Finding(WARNING, "e2e-attribute", f"{name} set on signal {signal}: the bench reads "
                                    "E2E parameters of messages only, so this value is ignored", line))


def _check_e2e(message: Message, definitions: Mapping[str, Any], override: Mapping[str, Any] | None,
               lines: _Lines, required: bool, findings: list[Finding]) -> MessageProtection:
    """The protection a message declares, checked as the bench loads it (`bench.e2e.config.protection`), and the
    signals on its CRC and counter fields."""
    line = lines.of_message(message)
    name = message.name
    try:
        protection = e2e_config.protection(message, definitions, override)
    except e2e_config.ProtectionError as exc:
        text = str(exc)
        text = text[len(name) + 2:] if text.startswith(f"{name}: ") else text
        findings.append(Finding(ERROR, "e2e", f"{text}{' (bench.toml [e2e] applied)' if override else ''}",
                                line, name))
        return MessageProtection(name, message.frame_id, None, refused=True)
    if protection is None:
        if required and not diagnostic_kind(message):   # ISO-TP carries no E2E (its framing is checked instead)
            findings.append(Finding(ERROR, "e2e", "no E2E protection declared (E2E_Profile, ARXML E2E properties "
                                    "or bench.toml [e2e]): --e2e required wants a profile on every message",
                                    line, name))
        return MessageProtection(name, message.frame_id, None, diagnostic=bool(diagnostic_kind(message)))
    for what, place in (("CRC", protection.crc), ("counter", protection.counter)):
        span = set(range(place.start, place.start + place.length))
        for signal in message.signals:
            if not span & set(_bits(signal)):
                continue
            wrong = _not_exactly(signal, place)
            if wrong:
                findings.append(Finding(
                    WARNING, "e2e", f"overlaps the {protection.profile} {what} field (bits {place.start}-"
                    f"{place.start + place.length - 1}) but {'; '.join(wrong)}: the bench writes the field over it "
                    f"(the {what} is {place.length} unsigned Intel bits at bit {place.start}, scale 1, offset 0)",
                    lines.of_signal(message, signal), name, signal.name))
    return MessageProtection(name, message.frame_id, protection)


def _not_exactly(signal: Signal, place: Field) -> list[str]:
    """How a signal over an E2E field differs from that field (empty: it is exactly the field)."""
    wrong = []
    if signal.start != place.start or signal.length != place.length or signal.byte_order != "little_endian":
        order = "" if signal.byte_order == "little_endian" else " big-endian"
        wrong.append(f"is {signal.length}{order} bits at bit {signal.start}")
    if signal.is_signed or signal.is_float:
        wrong.append("is signed" if signal.is_signed else "is a float")
    if float(signal.scale) != 1 or float(signal.offset) != 0:
        wrong.append(f"has scale {_g(float(signal.scale))}, offset {_g(float(signal.offset))}")
    return wrong


def protection_line(result: CheckResult, entry: MessageProtection) -> str:
    """What the bench will apply to one message, e.g. `x.dbc: Brake_Status 0x100: P11 DataID 0x0100 BOTH, ...`."""
    return f"{result.path}: {entry.name} {canid.text(entry.frame_id)}: {entry.describe()}"


def summary_line(result: CheckResult) -> str:
    errors, warnings = len(result.errors), len(result.warnings)
    verdict = "accepted" if result.accepted else "rejected"
    return (f"{result.path}: {verdict}: {errors} error{'s' * (errors != 1)}, {warnings} "
            f"warning{'s' * (warnings != 1)} ({result.messages} messages: {result.protected} protected, "
            f"{result.unprotected} unprotected{f', {result.diagnostic} diagnostic' if result.diagnostic else ''}; "
            f"{result.signals} signals; end-to-end {result.e2e})")


def format_finding(result: CheckResult, finding: Finding) -> str:
    where = f"{result.path}:{finding.line}" if finding.line else f"{result.path}"
    subject = f" {finding.where()}:" if finding.where() else ""
    return f"{where}: {finding.severity} [{finding.kind}]{subject} {finding.text}"


def check_files(paths: Iterable[Path | str], e2e_mode: str = OPTIONAL,
                e2e_overrides: Overrides | None = None,
                message_overrides: Overrides | None = None, strict: bool = False) -> list[CheckResult | DatabaseError]:
    """Each file's result, or the DatabaseError of a file that cannot be read."""
    out: list[CheckResult | DatabaseError] = []
    for path in paths:
        try:
            out.append(check_file(path, e2e_mode, e2e_overrides, message_overrides, strict))
        except DatabaseError as exc:
            out.append(exc)
    return out
