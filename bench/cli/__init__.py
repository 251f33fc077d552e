"""The `bench` command. Each subcommand is its own module with `register(subparsers)`;
the parser it adds sets `handler=run`, a function `run(args) -> int` (the exit code)."""

from __future__ import annotations

import argparse
import importlib
import sys

from rich.console import Console
from rich.markup import escape

from bench.errors import BenchError

SUBCOMMANDS = ("run", "plant", "dbc", "log", "monitor", "replay", "report")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="bench", description="HIL CAN test bench for chassis ECUs.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in SUBCOMMANDS:
        importlib.import_module(f"bench.cli.{name}").register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.handler(args))
    except BenchError as exc:
        console = Console(stderr=True, soft_wrap=True)
        for problem in getattr(exc, "problems", None) or [str(exc)]:   # one line per bad input
            console.print(f"[bold red]bench {args.command}: error:[/] {escape(problem)}", highlight=False)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
