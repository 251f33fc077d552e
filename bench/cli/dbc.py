"""`bench dbc [FILE ...]`: list what a database (DBC or ARXML) carries (ids, senders, cycle times, the E2E
protection the bench applies, signals with units), so an engineer can check it against the project's
communication matrix at a glance without opening an editor. Without FILE: the databases of the project's
bench.toml ([bench] databases), with its [e2e] table applied.

`bench dbc check [--e2e optional|required] [FILE ...]`: check databases against the bench's needs
(`bench.database.check`), print per message the protection the bench will apply (profile, DataID, offsets, window) or
"unprotected", then every finding with its file and line. `--e2e optional` (the default): a message may go
without protection; `--e2e required`: every message must declare a profile (the contract's databases). Exit 0
when no file has an error (warnings allowed), 1 when one has, 2 when a file cannot be read. `check` is
recognised as the first word, so a file named "check" is listed with `bench dbc ./check`.
"""

from __future__ import annotations

import argparse
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any, NoReturn

from cantools.database.can import Database, Message, Signal
from rich.console import Console
from rich.table import Table
from rich.text import Text

from bench import canid
from bench.cli.common import table_console
from bench.config import load_config
from bench.database import check as dbccheck
from bench.database import overrides as overrides_table
from bench.database.codec import load_dbc
from bench.e2e import config as e2e_config
from bench.errors import ConfigError, DatabaseError, did_you_mean

CHECK = "check"
STRICT_HELP = ("check only: what the bench survives in a database but a contract must not have (a range wider than "
               "its raw field, a start value outside its range) is an error, not a warning (how the contract's own "
               "databases are checked)")
#: Where `Protection.describe()` is broken into lines in the table: before each group of parameters.
_PARTS = re.compile(r", (?=CRC bits|counter bits|MaxDeltaCounter|window)")
E2E_HELP = ("check only: may a message go without E2E protection? optional (the default): yes, it is listed as "
            "unprotected; required: every message must declare a profile (E2E_Profile P01/P02/P05/P07/P11 and the "
            "other E2E_* attributes, ARXML E2E properties, or bench.toml [e2e]), an unprotected one is an error "
            "(how the contract's own databases are checked). A declared protection is checked either way.")
CHECK_DESCRIPTION = (
    "Check DBC or ARXML files against the bench's needs (cycle and send types, layout, ranges, start values, value "
    "tables, E2E protection); print per message the protection the bench will apply (profile, DataID or "
    "DataIDList, CRC and counter bits, MaxDeltaCounter, the state machine's window) or 'unprotected', then every "
    "finding with its file and line (ARXML: with its message). A message is protected when it declares an AUTOSAR "
    "E2E profile: DBC attributes E2E_Profile (None, P01, P02, P05, P07, P11), E2E_DataID, E2E_DataIDMode, "
    "E2E_DataIDList, E2E_Offset, E2E_DataLength, E2E_MaxDeltaCounter, E2E_WindowSize, E2E_MinOkState*/"
    "E2E_MaxErrorState* (Init, Valid, Invalid); ARXML E2E properties; bench.toml [e2e.MESSAGE] over both when the "
    "files are the project's. A declaration no profile can use is an error; a signal over the CRC or counter "
    "field that is not exactly that field is a warning. A cycle time or send type the database lacks comes from "
    "bench.toml [messages.MESSAGE] (cycle_time_ms, send_type) when the files are the project's; each error such a "
    "table fixes names its key. Exit 0: no errors; 1: a file has errors; 2: a file cannot be read.")
CONFIG_HELP = "the project's bench.toml, whose [bench] databases are the default FILEs (default: found from here up)"
VALUES_HELP = ("list only: each signal with its DBC range and its value table (the names a case may give, e.g. "
               "bench.set(MESSAGE, SIGNAL=\"NAME\"))")


def register(subparsers: Any) -> None:
    """Add the `dbc` parser (called by `bench.cli.build_parser`)."""
    parser = subparsers.add_parser(
        "dbc",
        help="list the messages and signals of DBC files, or check them (bench dbc check FILE...)",
        usage="bench dbc [FILE ...]\n       bench dbc check [--e2e {optional,required}] [--strict] [FILE ...]",
        description="List id, name, senders, cycle time, E2E protection and signals of every message of DBC or "
        "ARXML files; 'bench dbc check FILE...' checks them against the bench's needs instead (cycle and send "
        "types, layout, ranges, start values, value tables, the E2E protection each message declares), prints "
        "per message the protection the bench will apply (profile, DataID, offsets, window) or 'unprotected', and "
        "every finding with its line. Without FILE: the databases of the project's bench.toml ([bench] databases), "
        "with its [e2e] table applied.",
    )
    # REMAINDER, parsed again in `run`: so that options may follow the words (`check --e2e required FILE`)
    parser.add_argument("files", nargs=argparse.REMAINDER, metavar="[check] FILE",
                        help="DBC or ARXML file(s); a first word 'check' checks them instead of listing them")
    parser.add_argument("--e2e", choices=dbccheck.E2E_MODES, default=None, help=E2E_HELP)
    parser.add_argument("--strict", action="store_true", help=STRICT_HELP)
    parser.add_argument("--config", default=None, help=CONFIG_HELP)
    parser.add_argument("--values", action="store_true", help=VALUES_HELP)
    parser.set_defaults(handler=run)


class _WordsParser(argparse.ArgumentParser):
    """Parses the words after `bench dbc`; a mistake is a ConfigError (one line, exit 2), not an exit."""

    def error(self, message: str) -> NoReturn:
        raise ConfigError(message)


def _words(prog: str, words: list[str], with_e2e: bool) -> argparse.Namespace:
    checking = prog.endswith("check")
    parser = _WordsParser(prog=prog, add_help=checking, description=CHECK_DESCRIPTION if checking else None)
    parser.add_argument("files", nargs="*", metavar="FILE")
    parser.add_argument("--config", default=None, help=CONFIG_HELP)
    if with_e2e:
        parser.add_argument("--e2e", choices=dbccheck.E2E_MODES, default=None, help=E2E_HELP)
        parser.add_argument("--strict", action="store_true", help=STRICT_HELP)
    else:
        parser.add_argument("--values", action="store_true", help=VALUES_HELP)
    return parser.parse_intermixed_args(words)


def run(args: argparse.Namespace) -> int:
    """Load every file first (strict), so a bad file fails before anything is printed."""
    words: list[str] = list(args.files)
    if words and words[0] == CHECK:
        if args.values or "--values" in words:
            raise ConfigError("--values: only for the listing, 'bench dbc [FILE ...] --values'")
        checked = _words("bench dbc check", words[1:], with_e2e=True)
        files, overrides, message_overrides = _files(checked.files, checked.config or args.config)
        return check(files, checked.e2e or args.e2e or dbccheck.OPTIONAL, overrides, message_overrides,
                     strict=checked.strict or args.strict)
    if args.e2e is not None or args.strict:
        raise ConfigError(f"{'--e2e' if args.e2e is not None else '--strict'}: only for 'bench dbc check FILE...'")
    listed = _words("bench dbc", words, with_e2e=False)
    files, overrides, message_overrides = _files(listed.files, listed.config or args.config)
    databases = [(path, load_dbc(path)) for path in files]  # raises DatabaseError naming the file
    console = table_console()
    for path, database in databases:
        console.print(message_table(path, database, overrides, values=listed.values or args.values,
                                    message_overrides=message_overrides))
    return 0


def _files(given: list[str], config: str | None) -> tuple[list[Path], dict[str, dict[str, Any]],
                                                         dict[str, dict[str, Any]]]:
    """The files named, or the project's databases with its [e2e] and [messages] tables: what `bench run` would
    load (ConfigError without a bench.toml)."""
    if given:
        return [Path(f) for f in given], {}, {}
    project = load_config(Path(config) if config else None)
    return list(project.databases), project.e2e, project.messages


def message_table(path: Path, database: Database, e2e_overrides: Mapping[str, Mapping[str, Any]] | None = None,
                  values: bool = False, message_overrides: Mapping[str, Mapping[str, Any]] | None = None) -> Table:
    """One row per message, sorted by id (= bus priority); `values`: each signal with its range and value
    table; a cycle time from bench.toml's [messages] is marked so."""
    table = Table(title=_title(path, database), title_justify="left", show_lines=True)
    messages = list(database.messages)
    widest_id = max((m.frame_id for m in messages), default=0)
    table.add_column("id", no_wrap=True, justify="right", min_width=len(canid.text(widest_id)))
    table.add_column("message", no_wrap=True, min_width=max((len(m.name) for m in messages), default=7))
    table.add_column("sender", no_wrap=True)
    table.add_column("cycle ms", justify="right", no_wrap=True)
    table.add_column("E2E", no_wrap=True)
    table.add_column(Text("signals [unit] range: value table" if values else "signals [unit]"))
    definitions = dict(getattr(database.dbc, "attribute_definitions", None) or {}) if database.dbc else {}
    overrides = e2e_overrides or {}
    for message in sorted(database.messages, key=lambda m: m.frame_id):
        table.add_row(
            Text(canid.text(message.frame_id)),
            Text(message.name),
            Text(", ".join(message.senders) or "-"),
            Text(_cycle(message, message_overrides)),
            _protection(message, definitions, overrides.get(message.name)),
            _signals(message, values),
        )
    return table


def _cycle(message: Message, supplied_by: Mapping[str, Mapping[str, Any]] | None) -> str:
    supplied = overrides_table.cycle_time_ms(supplied_by, message.name)
    if supplied is not None:
        return f"{supplied:g} (bench.toml)"
    return "-" if message.cycle_time is None else str(message.cycle_time)


def _protection(message: Message, definitions: Mapping[str, Any], override: Mapping[str, Any] | None) -> Text:
    """The protection the bench applies, one parameter group a line; 'unprotected', or why it is refused."""
    try:
        protection = e2e_config.protection(message, definitions, override)
    except e2e_config.ProtectionError as exc:
        return Text(f"refused: {exc}", style="red")
    if protection is None:
        return Text("unprotected")
    return Text("\n".join(_PARTS.split(protection.describe())))


def _title(path: Path, database: Database) -> Text:
    bus = database.buses[0] if database.buses else None
    baud = f", {bus.baudrate} bit/s" if bus is not None and bus.baudrate else ""
    nodes = ", ".join(node.name for node in database.nodes)
    return Text(f"{path.name}: {len(database.messages)} messages{baud}; nodes {nodes}")


def _signals(message: Message, values: bool = False) -> Text:
    """Text, not markup: '[deg]' would otherwise be read as a rich style tag."""
    lines = [f"{s.name} [{s.unit or '-'}]" + (_values(s) if values else "")
             for s in sorted(message.signals, key=lambda s: s.start)]
    return Text("\n".join(lines))


def _values(signal: Signal) -> str:
    """' -80..80' and, for a signal with a value table, ': 0 NORMAL, 1 CRAB, ...' (raw value, name)."""
    low, high = ("?" if v is None else f"{v:g}" for v in (signal.minimum, signal.maximum))
    text = "" if signal.minimum is None and signal.maximum is None else f" {low}..{high}"
    if signal.choices:
        text += ": " + ", ".join(f"{raw} {name}" for raw, name in sorted(signal.choices.items()))
    return text


def check(files: list[Path], e2e_mode: str, e2e_overrides: Mapping[str, Mapping[str, Any]] | None = None,
          message_overrides: Mapping[str, Mapping[str, Any]] | None = None, strict: bool = False) -> int:
    """Print per message the protection the bench applies, every finding as FILE:LINE, then one summary line per
    file (compiler style, so editors jump to it)."""
    out = Console(soft_wrap=True, highlight=False)
    err = Console(stderr=True, soft_wrap=True, highlight=False)
    unreadable = rejected = 0
    outcomes = dbccheck.check_files(files, e2e_mode, e2e_overrides, message_overrides, strict)
    for outcome in outcomes:
        if isinstance(outcome, DatabaseError):
            unreadable += 1
            err.print(Text.assemble(("bench dbc check: error: ", "bold red"), str(outcome)))
            continue
        for entry in outcome.protections:
            out.print(Text(dbccheck.protection_line(outcome, entry)))
        for finding in outcome.findings:
            style = "red" if finding.severity == dbccheck.ERROR else "yellow"
            out.print(Text(dbccheck.format_finding(outcome, finding), style=style))
        rejected += not outcome.accepted
        out.print(Text(dbccheck.summary_line(outcome), style="bold green" if outcome.accepted else "bold red"))
    if len(files) > 1:
        out.print(Text(f"{len(files)} files: {len(files) - rejected - unreadable} accepted, {rejected} rejected, "
                       f"{unreadable} unreadable"))
    names = [p.name for outcome in outcomes if isinstance(outcome, dbccheck.CheckResult) for p in outcome.protections]
    stray = [name for name in (e2e_overrides or {}) if name not in names]
    for name in stray:   # what `bench run` refuses too (bench.database.codec.Codebook)
        out.print(Text(f"bench.toml: error [e2e] {name}: no such message in the databases{did_you_mean(name, names)}",
                       style="red"))
    unknown = overrides_table.unknown_messages(message_overrides, names)
    for line in unknown:
        out.print(Text(line, style="red"))
    return 2 if unreadable else (1 if rejected or stray or unknown else 0)
