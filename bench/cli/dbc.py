"""`bench dbc [FILE ...]`: list what a DBC carries (ids, senders, cycle times, signals with units),
so an engineer can check a database against k-matrix.md at a glance without opening an editor."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from cantools.database.can import Database, Message
from rich.console import Console
from rich.table import Table
from rich.text import Text

from bench import paths
from bench.codec import load_dbc


def register(subparsers: Any) -> None:
    """Add the `dbc` parser (called by `bench.cli.build_parser`)."""
    parser = subparsers.add_parser(
        "dbc",
        help="list the messages and signals of DBC files",
        description="List id, name, senders, cycle time and signals of every message. "
        "Without FILE: the contract (chassis.dbc) and the bench's own database (bench.dbc).",
    )
    parser.add_argument("files", nargs="*", type=Path, metavar="FILE", help="DBC file(s) to list")
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    """Load every file first (strict), so a bad file fails before anything is printed."""
    files: list[Path] = list(args.files) or [paths.CHASSIS_DBC, paths.BENCH_DBC]
    databases = [(path, load_dbc(path)) for path in files]  # raises DatabaseError naming the file
    console = Console()
    for path, database in databases:
        console.print(message_table(path, database))
    return 0


def message_table(path: Path, database: Database) -> Table:
    """One row per message, sorted by id (= bus priority)."""
    table = Table(title=_title(path, database), title_justify="left", show_lines=True)
    table.add_column("id", no_wrap=True, justify="right")
    table.add_column("message", no_wrap=True)
    table.add_column("sender", no_wrap=True)
    table.add_column("cycle ms", justify="right", no_wrap=True)
    table.add_column(Text("signals [unit]"))
    for message in sorted(database.messages, key=lambda m: m.frame_id):
        table.add_row(
            Text(f"0x{message.frame_id:03X}"),
            Text(message.name),
            Text(", ".join(message.senders) or "-"),
            Text("-" if message.cycle_time is None else str(message.cycle_time)),
            _signals(message),
        )
    return table


def _title(path: Path, database: Database) -> Text:
    bus = database.buses[0] if database.buses else None
    baud = f", {bus.baudrate} bit/s" if bus is not None and bus.baudrate else ""
    nodes = ", ".join(node.name for node in database.nodes)
    return Text(f"{path.name}: {len(database.messages)} messages{baud}; nodes {nodes}")


def _signals(message: Message) -> Text:
    """Text, not markup: '[deg]' would otherwise be read as a rich style tag."""
    lines = [f"{s.name} [{s.unit or '-'}]" for s in sorted(message.signals, key=lambda s: s.start)]
    return Text("\n".join(lines))
