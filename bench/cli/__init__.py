"""The `bench` command. Each subcommand is its own module with `register(subparsers)`;
the parser it adds sets `handler=run`, a function `run(args) -> int` (the exit code)."""

from __future__ import annotations

import argparse
import importlib
import sys

from rich.console import Console
from rich.markup import escape

from bench.errors import BenchError, did_you_mean
from bench.stop import STOP

SUBCOMMANDS = ("run", "plant", "diag", "dbc", "log", "monitor", "replay", "report")


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The whole command line, or with `only` just that subcommand's (its module alone is imported: `bench run`
    then loads neither the log reader and mcap nor the monitor and DBC checker, 0.07 s of CPU at its start)."""
    parser = argparse.ArgumentParser(prog="bench", description="HIL CAN test bench for chassis ECUs.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in SUBCOMMANDS:
        if only is None or name == only:
            importlib.import_module(f"bench.cli.{name}").register(sub)
    return parser


def _subcommand(argv: list[str] | None) -> str | None:
    """The subcommand a command line names first, when it is one (no top-level option before it): then the
    parser needs no other. Otherwise (`bench --help`, a typo) None: the whole parser, with every subcommand."""
    words = sys.argv[1:] if argv is None else argv
    return words[0] if words and words[0] in SUBCOMMANDS else None


def chosen_parser(parser: argparse.ArgumentParser, args: argparse.Namespace) -> argparse.ArgumentParser:
    """The innermost (sub)command's parser that `args` came through: its usage and options are the ones a
    user who mistyped an option needs to see, not the top level's."""
    while True:
        actions = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
        if not actions or getattr(args, actions[0].dest, None) not in actions[0].choices:
            return parser
        parser = actions[0].choices[getattr(args, actions[0].dest)]


def unknown_arguments(parser: argparse.ArgumentParser, extras: list[str]) -> str:
    """'unrecognized arguments: --interfce x (did you mean --interface?)': a typo gets the close option."""
    options = [o for a in parser._actions for o in a.option_strings]
    shown = [extra + (did_you_mean(extra.split("=", 1)[0], options) if extra.startswith("-") else "")
             for extra in extras]
    return f"unrecognized arguments: {' '.join(shown)}"


def main(argv: list[str] | None = None) -> int:
    parser = build_parser(_subcommand(argv))
    args, extras = parser.parse_known_args(argv)
    if extras:
        chosen = chosen_parser(parser, args)
        chosen.error(unknown_arguments(chosen, extras))
    try:
        return int(args.handler(args))
    except BenchError as exc:
        console = Console(stderr=True, soft_wrap=True)
        for problem in getattr(exc, "problems", None) or [str(exc)]:   # one line per bad input
            console.print(f"[bold red]bench {args.command}: error:[/] {escape(problem)}", highlight=False)
        return 2
    except KeyboardInterrupt:
        return STOP.exit_code()


if __name__ == "__main__":
    sys.exit(main())
