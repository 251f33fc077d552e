"""`bench dbc [FILE ...]`: list what a DBC carries (ids, senders, cycle times, signals with units),
so an engineer can check a database against the project's communication matrix at a glance without opening
an editor. Without FILE: the databases of the project's bench.toml ([bench] databases).

`bench dbc check [FILE ...]`: check databases against the bench's needs (`bench.dbccheck`) and print
every finding with its file and line. Exit 0 when no file has an error (warnings allowed), 1 when one
has, 2 when a file cannot be read. `check` is recognised as the first word, so a file named "check"
is listed with `bench dbc ./check`.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any, NoReturn

from cantools.database.can import Database, Message, Signal
from rich.console import Console
from rich.table import Table
from rich.text import Text

from bench import dbccheck
from bench.codec import load_dbc
from bench.config import load_config
from bench.errors import ConfigError, DatabaseError

CHECK = "check"
E2E_HELP = ("check only: the end-to-end layout (the bench's counter and checksum signals) is an error (required), "
            "a warning (optional), or required when the file declares either signal (auto, the default)")
CONFIG_HELP = "the project's bench.toml, whose [bench] databases are the default FILEs (default: found from here up)"
VALUES_HELP = ("list only: each signal with its DBC range and its value table (the names a case may give, e.g. "
               "bench.set(..., DriveMode=\"PIVOT\"))")


def register(subparsers: Any) -> None:
    """Add the `dbc` parser (called by `bench.cli.build_parser`)."""
    parser = subparsers.add_parser(
        "dbc",
        help="list the messages and signals of DBC files, or check them (bench dbc check FILE...)",
        usage="bench dbc [FILE ...]\n       bench dbc check [--e2e {auto,required,optional}] [FILE ...]",
        description="List id, name, senders, cycle time and signals of every message; "
        "'bench dbc check FILE...' checks them against the bench's needs instead (cycle and send types, "
        "layout, ranges, start values, end-to-end layout, value tables) and prints every finding with its line. "
        "Without FILE: the databases of the project's bench.toml ([bench] databases).",
    )
    # REMAINDER, parsed again in `run`: so that options may follow the words (`check --e2e required FILE`)
    parser.add_argument("files", nargs=argparse.REMAINDER, metavar="[check] FILE",
                        help="DBC file(s); a first word 'check' checks them instead of listing them")
    parser.add_argument("--e2e", choices=dbccheck.E2E_MODES, default=None, help=E2E_HELP)
    parser.add_argument("--config", default=None, help=CONFIG_HELP)
    parser.add_argument("--values", action="store_true", help=VALUES_HELP)
    parser.set_defaults(handler=run)


class _WordsParser(argparse.ArgumentParser):
    """Parses the words after `bench dbc`; a mistake is a ConfigError (one line, exit 2), not an exit."""

    def error(self, message: str) -> NoReturn:
        raise ConfigError(message)


def _words(prog: str, words: list[str], with_e2e: bool) -> argparse.Namespace:
    parser = _WordsParser(prog=prog, add_help=prog.endswith("check"))
    parser.add_argument("files", nargs="*", metavar="FILE")
    parser.add_argument("--config", default=None, help=CONFIG_HELP)
    if with_e2e:
        parser.add_argument("--e2e", choices=dbccheck.E2E_MODES, default=None, help=E2E_HELP)
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
        files = [Path(f) for f in checked.files] or configured(checked.config or args.config)
        return check(files, checked.e2e or args.e2e or "auto")
    if args.e2e is not None:
        raise ConfigError("--e2e: only for 'bench dbc check FILE...'")
    listed = _words("bench dbc", words, with_e2e=False)
    files = [Path(f) for f in listed.files] or configured(listed.config or args.config)
    databases = [(path, load_dbc(path)) for path in files]  # raises DatabaseError naming the file
    console = Console()
    for path, database in databases:
        console.print(message_table(path, database, values=listed.values or args.values))
    return 0


def configured(config: str | None) -> list[Path]:
    """The project's databases: what `bench run` would load (ConfigError without a bench.toml)."""
    return list(load_config(Path(config) if config else None).databases)


def message_table(path: Path, database: Database, values: bool = False) -> Table:
    """One row per message, sorted by id (= bus priority); `values`: each signal with its range and value
    table."""
    table = Table(title=_title(path, database), title_justify="left", show_lines=True)
    table.add_column("id", no_wrap=True, justify="right")
    table.add_column("message", no_wrap=True)
    table.add_column("sender", no_wrap=True)
    table.add_column("cycle ms", justify="right", no_wrap=True)
    table.add_column(Text("signals [unit] range: value table" if values else "signals [unit]"))
    for message in sorted(database.messages, key=lambda m: m.frame_id):
        table.add_row(
            Text(f"0x{message.frame_id:03X}"),
            Text(message.name),
            Text(", ".join(message.senders) or "-"),
            Text("-" if message.cycle_time is None else str(message.cycle_time)),
            _signals(message, values),
        )
    return table


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


def check(files: list[Path], e2e_mode: str) -> int:
    """Print every finding as FILE:LINE, then one summary line per file (compiler style, so editors jump to it)."""
    out = Console(soft_wrap=True, highlight=False)
    err = Console(stderr=True, soft_wrap=True, highlight=False)
    unreadable = rejected = 0
    for outcome in dbccheck.check_files(files, e2e_mode):
        if isinstance(outcome, DatabaseError):
            unreadable += 1
            err.print(Text.assemble(("bench dbc check: error: ", "bold red"), str(outcome)))
            continue
        for finding in outcome.findings:
            style = "red" if finding.severity == dbccheck.ERROR else "yellow"
            out.print(Text(dbccheck.format_finding(outcome, finding), style=style))
        rejected += not outcome.accepted
        out.print(Text(dbccheck.summary_line(outcome), style="bold green" if outcome.accepted else "bold red"))
    if len(files) > 1:
        out.print(Text(f"{len(files)} files: {len(files) - rejected - unreadable} accepted, {rejected} rejected, "
                       f"{unreadable} unreadable"))
    return 2 if unreadable else (1 if rejected else 0)
