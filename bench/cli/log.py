"""`bench log`: look into run logs (MCAP) without Foxglove, e.g. to see what a killed run left behind."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.table import Table

from bench.logread import LogSummary, summarise


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser("log", help="inspect run logs (MCAP)", description=__doc__)
    actions = parser.add_subparsers(dest="log_command", required=True, metavar="ACTION")
    info = actions.add_parser("info", help="time span, frames, attachments and channels of a run log")
    info.add_argument("file", type=Path, help="the run log (.mcap)")
    info.set_defaults(handler=info_handler)


def info_handler(args: argparse.Namespace) -> int:
    """Print a run log's summary; a LogError for a missing or non-MCAP file reaches the framework."""
    show(summarise(args.file), Console())
    return 0


def show(summary: LogSummary, console: Console) -> None:
    facts = Table.grid(padding=(0, 2))
    facts.add_column(style="bold")
    facts.add_column()
    facts.add_row("File", str(summary.path))
    facts.add_row("Status", "[green]complete[/]" if summary.complete
                  else "[yellow]truncated[/] (no footer: killed run or cut file)")
    if summary.start is None or summary.end is None:
        facts.add_row("Time", "no messages")
    else:
        facts.add_row("Time", f"{summary.start:.6f} s … {summary.end:.6f} s (duration {summary.end - summary.start:.6f} s)")
    invalid = f"[red]{summary.invalid_frames} invalid[/]" if summary.invalid_frames else "0 invalid"
    facts.add_row("Frames", f"{summary.frames} ({invalid})")
    facts.add_row("Attachments", ", ".join(summary.attachments) or "none")
    console.print(facts, highlight=False)

    channels = Table(title="Channels", title_justify="left")
    channels.add_column("Topic", no_wrap=True)
    channels.add_column("Messages", justify="right")
    for topic, count in sorted(summary.channels.items()):
        channels.add_row(topic, str(count), style="dim" if count == 0 else None)
    console.print(channels)
