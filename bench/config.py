"""The project configuration (`bench.toml`) and the settings of one run.

Every bench project has its own bench.toml, found in the working directory or above it (or given with
--config); the package carries no project of its own, so it works the same from a wheel.
Every problem is a ConfigError naming the file and the key.
"""

from __future__ import annotations

import glob
import math
import tomllib
from collections.abc import Iterator
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any

from bench.contract import Requirement, load_requirements
from bench.database import overrides as overrides_table
from bench.database import sendtype
from bench.e2e.config import PARAMETERS as E2E_PARAMETERS
from bench.errors import ConfigError, SignalError, did_you_mean
from bench.transport import EMBEDDED, is_embedded
from bench.transport.busopts import BusOptions, positive_int

if TYPE_CHECKING:
    from bench.database.codec import Codebook

CONFIG_NAME = "bench.toml"
#: s a status has to start following a command change before the change counts as not followed.
DEFAULT_LATENCY_WINDOW = 1.0
#: s a plant has to acknowledge a new scenario ([scenario] timeout).
DEFAULT_SCENARIO_TIMEOUT = 2.0


# -- bench.toml's tables and keys: the one list the loader refuses unknown keys against and that
# `python -m bench.cli.configdoc` writes docs/reference/bench-toml.md from --------------------------------------
@dataclass(frozen=True)
class Key:
    """One key: what it sets, whether a table that is there must have it, and a value as written in TOML."""

    text: str
    example: str
    required: bool = False


@dataclass(frozen=True)
class TableKeys:
    """One table (or one entry of a list of tables): how it is written, what it is for, its keys."""

    header: str                   # as written in bench.toml, e.g. "[e2e.MESSAGE]"
    text: str
    keys: dict[str, Key]
    others: str = ""              # what any other key is ("" = refused, naming the key meant)
    required: bool = False        # every bench.toml has it
    example_name: str = ""        # MESSAGE or NODE in the example's header
    example_keys: tuple[str, ...] = ()   # the keys the example shows (default: all)


#: a value of each E2E parameter as written in bench.toml
_E2E_EXAMPLES = {
    "Profile": '"P11"', "DataID": "0x0222", "DataIDMode": '"NIBBLE"', "DataIDList": '"0A 0B 0C ..."', "Offset": "0",
    "DataLength": "64", "MaxDeltaCounter": "2", "WindowSize": "3", "MinOkStateInit": "1", "MaxErrorStateInit": "1",
    "MinOkStateValid": "1", "MaxErrorStateValid": "2", "MinOkStateInvalid": "3", "MaxErrorStateInvalid": "1",
}


SCHEMA: dict[str, TableKeys] = {
    "bench": TableKeys(
        "[bench]", "The project: its databases, the nodes the test runner plays, its plant, where its cases and "
        "reports are. Paths are relative to bench.toml.", {
            "databases": Key("the DBC or ARXML files of the network, each checked to exist before any case",
                             '["dbc/network.dbc", "dbc/hil.dbc"]', required=True),
            "stimulus": Key("the nodes the test runner itself sends (the stimulus)", '["TESTER"]',
                            required=True),
            "plant": Key("a plant registered in the entry-point group `bench.plants`; without it the bench plays "
                         "every node that is neither stimulus nor external from its database (a restbus), and skips "
                         "a case whose DUT it would play so", '"my_plant"'),
            "testcases": Key("the folder of the test cases `bench run` runs by default", '"testcases"',
                             required=True),
            "reports": Key("the folder under which `bench run` makes a new report folder when no `--out` is given",
                           '"reports"', required=True),
        }, required=True),
    "scenario": TableKeys(
        "[scenario]", "How the `bench` fixture's `start_scenario` resets the plant: the bench sends a new id in "
        "`command` (the scenario's settings beside it in the same message) and waits for the plant to echo it in "
        "`ack`. Without this table `start_scenario` is an error.", {
            "command": Key("the signal the bench sends the scenario id in, `Message.Signal`",
                           '"HIL_Control.ScenarioNumber"', required=True),
            "ack": Key("the signal the plant echoes it in, `Message.Signal`", '"HIL_Status.ScenarioAck"',
                       required=True),
            "timeout": Key("s the plant has to acknowledge (default 2)", "2.0"),
        }),
    "contract": TableKeys(
        "[contract]", "The node contracts: markdown whose level-3 headings `### ID — title` are the requirements; "
        "test cases name the ids they check (`@pytest.mark.req`), and an id that is not there stops collection.", {
            "documents": Key("globs relative to bench.toml, each matching at least one file",
                             '["docs/contract/*.md"]'),
        }),
    "timing": TableKeys(
        "[timing]", "The report's timing section.", {
            "latency": Key("command → status latency pairs, a list of tables (below)",
                           '[{command = "ECU_Command.Angle", status = "ECU_Status.Angle"}]'),
        }),
    "timing.latency": TableKeys(
        "[timing] latency = [{...}, ...]", "One latency pair: from the onset of a command change by more than "
        "`threshold` with the status at rest, to the first status frame that moved by more than it the same way.", {
            "command": Key("the command signal, `Message.Signal`", '"ECU_Command.Angle"', required=True),
            "status": Key("the status signal that follows it, `Message.Signal`", '"ECU_Status.Angle"',
                          required=True),
            "name": Key("the pair's name in the report (default: command → status)", '"ECU steering"'),
            "threshold": Key("a change larger than this, in the signals' unit (default: one step of the coarser "
                             "signal)", "0.05"),
            "window": Key("s the status has to start following (default 1)", "1.0"),
        }),
    "bus": TableKeys(
        "[bus]", "Defaults for the bus, under the command line's options and over the databases' attributes.", {
            "bitrate": Key("nominal bit rate, bit/s (default: the databases' `Baudrate`)", "500000"),
            "fd": Key("CAN FD (default: on when the databases' `BusType` is CAN FD)", "true"),
            "data_bitrate": Key("CAN FD data-phase bit rate, bit/s (needs fd = true)", "2000000"),
        }, others="a python-can bus argument (e.g. Vector's `app_name`, PCAN's `f_clock_mhz`), passed to "
                  "`can.Bus` as given and not checked: python-can's drivers read their options from **kwargs, so no "
                  "signature tells an option from a typo; `interface` and `channel` belong to the command line"),
    "e2e": TableKeys(
        "[e2e.MESSAGE]", "A message's AUTOSAR end-to-end protection over what its database declares, by AUTOSAR's "
        "names (the DBC attributes' without `E2E_`); bench.toml over the database over the contract's defaults "
        "(docs/spec/e2e.md).",
        {name: Key(text, _E2E_EXAMPLES[name]) for name, text in E2E_PARAMETERS.items()},
        example_name="ECU_Status", example_keys=("Profile", "DataID", "MaxDeltaCounter")),
    "messages": TableKeys(
        f"[{overrides_table.TABLE}.MESSAGE]", "What a database lacks for one message (it is the OEM's, not the test "
        "engineer's to edit); `bench dbc check` names the key that fixes each timing error it reports.", {
            overrides_table.CYCLE_TIME: Key("the cycle time, ms (> 0)", "100"),
            overrides_table.SEND_TYPE: Key(f"the send type: {', '.join(overrides_table.SEND_TYPES)}", '"cyclic"'),
        }, example_name="BREMSE_33"),
    "calibration": TableKeys(
        "[calibration.NODE]", "The calibration of a real (external) ECU that its cases need to judge it, one "
        "`NAME = { value = <number>, unit = \"<unit>\" }` per value; used only while NODE is external. Which names "
        "a node needs is its campaign's to say, checked before the first case.", {
            "value": Key("a finite number", "0.6", required=True),
            "unit": Key("its unit, a non-empty string", '"km/h"', required=True),
        }, example_name="ECU"),
    "diagnostics": TableKeys(
        "[diagnostics]", "Diagnostics (UDS on ISO-TP, docs/contract/diagnostics.md).", {
            "file": Key("the declaration of every node's addresses, DTCs, DIDs and routines, relative to "
                        "bench.toml", '"dbc/diagnostics.toml"'),
            "security": Key("an external node's seed/key function `module:function` per node, called as udsoncan's "
                            "`security_algo`: function(level, seed, params) -> key bytes (default: the documented "
                            "algorithm, DIAG-SEC-01)", '{ ECU = "my_keys:ecu_key" }'),
        }),
}

#: bench.toml's tables; any other is a typo
TABLES = tuple(name for name in SCHEMA if "." not in name)


def keys(table: str) -> tuple[str, ...]:
    """The keys `table` accepts (a SCHEMA name)."""
    return tuple(SCHEMA[table].keys)


@dataclass(frozen=True)
class LatencyPair:
    """A command signal and the status signal that follows it, for the report's timing section
    (`bench.checks.timing`). `threshold` is in the signals' unit; None means one step of the coarser signal."""

    name: str
    command: tuple[str, str]            # (message, signal)
    status: tuple[str, str]
    threshold: float | None = None
    window: float = DEFAULT_LATENCY_WINDOW


@dataclass(frozen=True)
class ScenarioProtocol:
    """[scenario]: how `start_scenario` resets the plant. The bench sends a new id in `command` (a signal of a
    stimulus message, with the scenario's other settings beside it) and waits up to `timeout` s for the plant
    to echo it in `ack`. The names are the project's: the bench itself knows no message."""

    command: tuple[str, str]            # (message, signal)
    ack: tuple[str, str]
    timeout: float = DEFAULT_SCENARIO_TIMEOUT

    def problems(self, where: Path, codebook: Codebook, stimulus: tuple[str, ...]) -> list[str]:
        """The named messages and signals exist, and the stimulus nodes send the command."""
        found = [p for key, (message, signal) in (("command", self.command), ("ack", self.ack))
                 if (p := signal_problem(f"{where}: [scenario] {key}", codebook, message, signal))]
        if not found:
            senders = codebook[self.command[0]].senders
            if not set(senders) & set(stimulus):
                found.append(f"{where}: [scenario] command: {self.command[0]} is sent by "
                             f"{', '.join(senders) or 'no node'}, not by a stimulus node ({', '.join(stimulus)})")
        return found


def signal_problem(where: str, codebook: Codebook, message: str, signal: str) -> str | None:
    """What is wrong with a `Message.Signal` named in bench.toml (the codec's own error, with the name meant
    of a typo); None if fine."""
    try:
        codebook[message].signal(signal)
    except SignalError as exc:
        return f"{where}: {exc}"
    return None


@dataclass(frozen=True)
class ProjectConfig:
    path: Path
    databases: tuple[Path, ...]
    stimulus: tuple[str, ...]
    plant: str | None                            # None: no plant, every simulated node is its restbus only
    testcases: Path
    reports: Path
    latency: tuple[LatencyPair, ...] = ()
    contract: tuple[Path, ...] = ()              # the contract documents ([contract] documents, globs resolved)
    requirements: tuple[Requirement, ...] = ()   # every requirement of those documents, in document order
    bus: BusOptions = BusOptions()               # [bus]: python-can arguments (bitrate, fd, data_bitrate, ...)
    scenario: ScenarioProtocol | None = None     # [scenario]; None: the project's plant takes no scenarios
    #: [e2e.MESSAGE]: AUTOSAR E2E parameters by name (no `E2E_` prefix) over the databases' own, per message
    e2e: dict[str, dict[str, Any]] = field(default_factory=dict)
    #: [messages.MESSAGE]: a cycle time or send type over the databases' own, per message (bench.database.overrides)
    messages: dict[str, dict[str, Any]] = field(default_factory=dict)
    #: [calibration.NODE]: a real ECU's calibration the cases need to judge it (node -> name -> (value, unit))
    calibration: dict[str, dict[str, tuple[float, str]]] = field(default_factory=dict)
    #: [diagnostics] file: the diagnostic declaration (bench.diag.declaration); None: no node has diagnostics
    diagnostics: Path | None = None
    #: [diagnostics] security: an external node's seed/key function as "module:function" (its algorithm is secret)
    security: dict[str, str] = field(default_factory=dict)

    @cached_property
    def requirement_ids(self) -> frozenset[str]:
        return frozenset(r.id for r in self.requirements)

    def problems(self, codebook: Codebook) -> list[str]:
        """What bench.toml names that the databases do not have (stimulus nodes, the scenario's and the timing
        section's signals), one line each: checked before the first case, not found at the end of a run."""
        found = [f"{self.path}: [bench] stimulus: node {node!r}{did_you_mean(node, codebook.nodes)} is in none "
                 f"of the databases (nodes: {', '.join(codebook.nodes)})"
                 for node in self.stimulus if node not in codebook.nodes]
        if self.scenario is not None and not found:
            found += self.scenario.problems(self.path, codebook, self.stimulus)
        found += [f"{self.path}: [calibration.{node}]: node {node!r}{did_you_mean(node, codebook.nodes)} is in none "
                  f"of the databases (nodes: {', '.join(codebook.nodes)})"
                  for node in self.calibration if node not in codebook.nodes]
        for pair in self.latency:
            for key in ("command", "status"):
                message, signal = getattr(pair, key)
                problem = signal_problem(f"{self.path}: [timing] latency {pair.name!r} {key}", codebook, message,
                                         signal)
                if problem:
                    found.append(problem)
        return found


def find_config(start: Path | None = None) -> Path:
    """bench.toml in the working directory or the nearest folder above it."""
    here = (start or Path.cwd()).resolve()
    for folder in (here, *here.parents):
        candidate = folder / CONFIG_NAME
        if candidate.is_file():
            return candidate
    raise ConfigError(f"no {CONFIG_NAME} in {here} or any folder above it: run from a bench project "
                      f"or give --config PATH")


def load_config(path: Path | None = None) -> ProjectConfig:
    path = Path(path) if path else find_config()
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read: {exc.strerror or exc}") from None
    except UnicodeDecodeError as exc:   # TOML is UTF-8 by definition
        raise ConfigError(f"{path}: not UTF-8 text (byte {exc.start}): not a TOML file") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: {exc}") from None
    except RecursionError:              # tomllib recurses into nested arrays and inline tables
        raise ConfigError(f"{path}: arrays or tables nested too deeply") from None
    section = data.get("bench")
    if not isinstance(section, dict):
        raise ConfigError(f"{path}: missing table [bench]")
    _known_keys(f"{path}:", data, TABLES, what="table")
    base = path.parent

    def strings(key: str) -> tuple[str, ...]:
        value = section.get(key)
        if not isinstance(value, list) or not value or not all(isinstance(v, str) and v for v in value):
            raise ConfigError(f"{path}: [bench] {key} must be a non-empty list of strings, got {value!r}")
        return tuple(value)

    def string(key: str) -> str:
        value = section.get(key)
        if not isinstance(value, str) or not value:
            raise ConfigError(f"{path}: [bench] {key} must be a non-empty string, got {value!r}")
        return value

    _known_keys(f"{path}: [bench]", section, keys("bench"))
    databases = tuple(base / p for p in strings("databases"))
    for database in databases:   # checked here so that `bench run` stops before any case starts
        if not database.is_file():
            raise ConfigError(f"{path}: [bench] databases: no such DBC file {database}")
    return ProjectConfig(
        path=path,
        databases=databases,
        stimulus=strings("stimulus"),
        plant=string("plant") if "plant" in section else None,
        testcases=base / string("testcases"),
        reports=base / string("reports"),
        latency=_latency_pairs(path, data.get("timing", {})),
        bus=_bus_table(path, data.get("bus", {})),
        scenario=_scenario(path, data.get("scenario")),
        e2e=_e2e_table(path, data.get("e2e", {})),
        messages=_messages_table(path, data.get(overrides_table.TABLE, {})),
        calibration=_calibration(path, data.get("calibration", {})),
        **_contract(path, text, data.get("contract", {})),
        **_diagnostics(path, data.get("diagnostics", {})),
    )


def _diagnostics(path: Path, table: Any) -> dict[str, Any]:
    """[diagnostics] file = "dbc/diagnostics.toml" (relative to bench.toml), security = { NODE = "module:function" }:
    the declaration is read when a session starts (bench.diag.declaration), the functions when a case unlocks."""
    if not isinstance(table, dict):
        raise ConfigError(f"{path}: [diagnostics] must be a table")
    _known_keys(f"{path}: [diagnostics]", table, keys("diagnostics"))
    if "file" not in table:
        return {}
    name = table["file"]
    if not isinstance(name, str) or not name:
        raise ConfigError(f"{path}: [diagnostics] file must be a path (a string), got {name!r}")
    file = path.parent / name
    if not file.is_file():
        raise ConfigError(f"{path}: [diagnostics] file: no such file {file}")
    security = table.get("security", {})
    if not isinstance(security, dict) or not all(isinstance(v, str) and ":" in v for v in security.values()):
        raise ConfigError(f"{path}: [diagnostics] security must be a table of NODE = \"module:function\", "
                          f"got {security!r}")
    return {"diagnostics": file, "security": dict(security)}


def _contract(path: Path, text: str, table: Any) -> dict[str, Any]:
    """[contract] documents = ["docs/contract/*.md", ...]: globs relative to bench.toml, each matching at least
    one file; the requirements are read here so that a duplicate id stops the run before any case starts."""
    if not isinstance(table, dict):
        raise ConfigError(f"{path}: [contract] must be a table")
    _known_keys(f"{path}: [contract]", table, keys("contract"))
    if "documents" not in table:
        return {}
    patterns = table["documents"]
    if not isinstance(patterns, list) or not patterns or not all(isinstance(p, str) and p for p in patterns):
        raise ConfigError(f"{path}: [contract] documents must be a non-empty list of glob strings, got {patterns!r}")
    documents: list[Path] = []
    for pattern in patterns:
        try:
            matches = sorted(glob.glob(str(path.parent / pattern), recursive=True))
        except (OSError, ValueError) as exc:
            raise ConfigError(f"{path}:{_line_of(text, pattern)}: [contract] documents: {pattern!r}: {exc}") from None
        files = [Path(m) for m in matches if Path(m).is_file()]
        if not files:
            raise ConfigError(f"{path}:{_line_of(text, pattern)}: [contract] documents: {pattern!r} matches no file "
                              f"(relative to {path.parent})")
        documents.extend(f for f in files if f not in documents)
    requirements = load_requirements(documents)
    return {"contract": tuple(documents), "requirements": tuple(requirements.values())}


#: [bus] keys the command line owns: a project file that fixed them would silently beat --interface/--channel.
_BUS_CLI_ONLY = ("interface", "channel")


#: [e2e.MESSAGE] keys whose value is a name; DataIDList is hex text or a list of bytes; every other key a number.
_E2E_NAMES = ("Profile", "DataIDMode")


def _e2e_table(path: Path, table: Any) -> dict[str, dict[str, Any]]:
    """[e2e.MESSAGE] Profile = "P11", DataID = 0x100, MaxDeltaCounter = 2, ...: a message's end-to-end protection
    over what its database declares (docs/spec/e2e.md "Parameters"; keys are AUTOSAR's names, the DBC attributes'
    without `E2E_`). Only the form is checked here; the values are checked with the databases (`bench.e2e.config`),
    and a message name that no database has is refused there, with the name meant."""
    out: dict[str, dict[str, Any]] = {}
    for message, where, values in _message_tables(path, "e2e", table, keys("e2e")):
        parameters: dict[str, Any] = {}
        for key, value in values.items():
            if key in _E2E_NAMES:
                if not isinstance(value, str) or not value:
                    raise ConfigError(f"{where} {key} must be a name (a string), got {value!r}")
            elif key == "DataIDList":
                if isinstance(value, list) and all(isinstance(v, int) and not isinstance(v, bool) and 0 <= v <= 255
                                                   for v in value):
                    value = " ".join(f"{v:02X}" for v in value)
                elif not isinstance(value, str):
                    raise ConfigError(f"{where} DataIDList must be 16 bytes, as hex text \"0A 0B ...\" or a list "
                                      f"of numbers 0-255, got {value!r}")
            elif isinstance(value, bool) or not isinstance(value, int):
                raise ConfigError(f"{where} {key} must be a whole number, got {value!r}")
            parameters[key] = value
        out[message] = parameters
    return out


def _message_tables(path: Path, name: str, table: Any,
                    known: tuple[str, ...]) -> Iterator[tuple[str, str, dict[str, Any]]]:
    """(message, where, its table) of a [NAME.MESSAGE] section, its form checked: a table of tables whose keys are
    `known`. Whether each message exists is checked with the databases."""
    if not isinstance(table, dict):
        raise ConfigError(f"{path}: [{name}] must be a table of [{name}.MESSAGE] tables")
    for message, values in table.items():
        if not isinstance(values, dict):
            raise ConfigError(f"{path}: [{name}] {message} = {values!r}: give a message's settings as a table "
                              f"[{name}.{message}] (keys: {', '.join(known)})")
        where = f"{path}: [{name}.{message}]"
        _known_keys(where, values, known)
        yield str(message), where, values


def _messages_table(path: Path, table: Any) -> dict[str, dict[str, Any]]:
    """[messages.MESSAGE] cycle_time_ms = 10, send_type = "cyclic": what a database lacks for one message
    (bench.database.overrides)."""
    out: dict[str, dict[str, Any]] = {}
    for message, where, values in _message_tables(path, overrides_table.TABLE, table, keys("messages")):
        cycle = values.get(overrides_table.CYCLE_TIME)
        if cycle is not None and (isinstance(cycle, bool) or not isinstance(cycle, (int, float))
                                  or not math.isfinite(cycle) or cycle <= 0):
            raise ConfigError(f"{where} {overrides_table.CYCLE_TIME} must be a positive number of milliseconds, "
                              f"got {cycle!r}")
        send_type = values.get(overrides_table.SEND_TYPE)
        if send_type is not None and send_type not in overrides_table.SEND_TYPES:
            meant = sendtype.kind_of(send_type)
            hint = f" (did you mean {meant!r}?)" if meant else ""
            raise ConfigError(f"{where} {overrides_table.SEND_TYPE} {send_type!r} is no send type the bench knows"
                              f"{hint}; its send types: {', '.join(overrides_table.SEND_TYPES)}")
        out[message] = dict(values)
    return out


def _calibration(path: Path, table: Any) -> dict[str, dict[str, tuple[float, str]]]:
    """[calibration.NODE] name = { value = <number>, unit = "<unit>" }: the calibration of a real (external) ECU
    that its cases need to judge it (e.g. a controller's thresholds); which names a node needs is its campaign's to say.
    The form is checked here, the node names with the databases (`ProjectConfig.problems`)."""
    if not isinstance(table, dict):
        raise ConfigError(f"{path}: [calibration] must be a table of [calibration.NODE] tables")
    out: dict[str, dict[str, tuple[float, str]]] = {}
    for node, values in table.items():
        where = f"{path}: [calibration.{node}]"
        if not isinstance(values, dict):
            raise ConfigError(f"{path}: [calibration] {node} = {values!r}: give a node's calibration as a table "
                              f"[calibration.{node}] of name = {{ value = <number>, unit = \"<unit>\" }}")
        entries: dict[str, tuple[float, str]] = {}
        for name, item in values.items():
            if not isinstance(item, dict):
                raise ConfigError(f"{where} {name} must be {{ value = <number>, unit = \"<unit>\" }}, got {item!r}")
            _known_keys(f"{where} {name}:", item, keys("calibration"))
            value, unit = item.get("value"), item.get("unit")
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ConfigError(f"{where} {name}: value must be a finite number, got {value!r}")
            if not isinstance(unit, str) or not unit:
                raise ConfigError(f"{where} {name}: unit must be a non-empty string, got {unit!r}")
            entries[name] = (float(value), unit)
        out[node] = entries
    return out


def _bus_table(path: Path, table: Any) -> BusOptions:
    """[bus] bitrate = 500000, fd = true, data_bitrate = 2000000, and any other python-can bus argument
    (e.g. PCAN's f_clock_mhz, Vector's app_name), passed to `can.Bus` as given. Unknown keys are not refused here,
    unlike every other table: python-can's drivers read their options from **kwargs, so no signature tells an
    option from a typo (README, "Real hardware")."""
    if not isinstance(table, dict):
        raise ConfigError(f"{path}: [bus] must be a table")
    cli_only = [k for k in _BUS_CLI_ONLY if k in table]
    if cli_only:
        raise ConfigError(f"{path}: [bus] {', '.join(cli_only)}: give it on the command line "
                          f"(--{' / --'.join(cli_only)}), not in bench.toml")
    extra = {k: v for k, v in table.items() if k not in keys("bus")}
    for key, value in extra.items():
        if isinstance(value, (dict, list)) and key != "can_filters":
            raise ConfigError(f"{path}: [bus] {key}: python-can bus arguments are plain values, got {value!r}")
    fd = table.get("fd")
    if fd is not None and not isinstance(fd, bool):
        raise ConfigError(f"{path}: [bus] fd must be true or false, got {fd!r}")
    options = BusOptions(
        bitrate=positive_int(f"{path}: [bus] bitrate", table["bitrate"]) if "bitrate" in table else None,
        fd=fd,
        data_bitrate=(positive_int(f"{path}: [bus] data_bitrate", table["data_bitrate"])
                      if "data_bitrate" in table else None),
        extra=extra)
    if options.data_bitrate is not None and options.fd is False:
        raise ConfigError(f"{path}: [bus] data_bitrate needs fd = true")
    return options


def _known_keys(where: str, table: dict[str, Any], known: tuple[str, ...], what: str = "key") -> None:
    """Refuse a key (or table) bench.toml does not know, with the known one it most likely meant: a typo such as
    `testcase` or `[scenaro]` would otherwise be read as absent and give a default or a later, vaguer error."""
    unknown = [key for key in table if key not in known]
    if unknown:
        named = ", ".join(f"{key}{did_you_mean(key, known)}" for key in unknown)
        raise ConfigError(f"{where} unknown {what}(s) {named} (known: {', '.join(known)})")


def _line_of(text: str, needle: str) -> int:
    """The 1-based line of bench.toml that holds a value (tomllib gives no positions); 0 when not found."""
    for number, line in enumerate(text.splitlines(), 1):
        if needle in line:
            return number
    return 0


def _latency_pairs(path: Path, timing: Any) -> tuple[LatencyPair, ...]:
    """[timing] latency = [{command = "Msg.Signal", status = "Msg.Signal", name?, threshold?, window?}, ...]"""
    if not isinstance(timing, dict):
        raise ConfigError(f"{path}: [timing] must be a table")
    _known_keys(f"{path}: [timing]", timing, keys("timing"))
    entries = timing.get("latency", [])
    if not isinstance(entries, list):
        raise ConfigError(f"{path}: [timing] latency must be a list of tables, got {entries!r}")
    pairs = []
    for i, entry in enumerate(entries, 1):
        where = f"{path}: [timing] latency entry {i}"
        if not isinstance(entry, dict):
            raise ConfigError(f"{where} must be a table like {{command = \"Msg.Signal\", status = \"Msg.Signal\"}}, "
                              f"got {entry!r}")
        _known_keys(f"{where}:", entry, keys("timing.latency"))
        command, status = (_signal_ref(where, entry, key) for key in ("command", "status"))
        name = entry.get("name", f"{command[0]}.{command[1]} → {status[0]}.{status[1]}")
        if not isinstance(name, str) or not name:
            raise ConfigError(f"{where}: name must be a non-empty string, got {name!r}")
        threshold = entry.get("threshold")
        if threshold is not None:
            threshold = _positive(where, "threshold", threshold)
        window = _positive(where, "window", entry.get("window", DEFAULT_LATENCY_WINDOW))
        pairs.append(LatencyPair(name, command, status, threshold, window))
    return tuple(pairs)


def _scenario(path: Path, table: Any) -> ScenarioProtocol | None:
    """[scenario] command = "Message.Signal", ack = "Message.Signal", timeout = s (optional)."""
    if table is None:
        return None
    where = f"{path}: [scenario]"
    if not isinstance(table, dict):
        raise ConfigError(f"{where} must be a table")
    _known_keys(where, table, keys("scenario"))
    for key in ("command", "ack"):
        if key not in table:
            raise ConfigError(f"{where} needs {key} = \"Message.Signal\"")
    timeout = _positive(where, "timeout", table.get("timeout", DEFAULT_SCENARIO_TIMEOUT))
    return ScenarioProtocol(_signal_ref(where, table, "command"), _signal_ref(where, table, "ack"), timeout)


def _signal_ref(where: str, entry: dict[str, Any], key: str) -> tuple[str, str]:
    value = entry.get(key)
    parts = value.split(".") if isinstance(value, str) else []
    if len(parts) != 2 or not all(parts):
        raise ConfigError(f"{where}: {key} must be \"Message.Signal\", got {value!r}")
    return parts[0], parts[1]


def _positive(where: str, key: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not (math.isfinite(value) and value > 0):
        raise ConfigError(f"{where}: {key} must be a positive number, got {value!r}")
    return float(value)


@dataclass
class RunSettings:
    """How one run reaches its bus; the same for `bench run`, `bench plant` and plain pytest."""

    interface: str = EMBEDDED
    channel: str | None = None
    external: list[str] = field(default_factory=list)
    vehicle: str | None = None
    bus: BusOptions = field(default_factory=BusOptions)   # from the command line; over [bus] and the databases

    @property
    def virtual_time(self) -> bool:
        return is_embedded(self.interface)
