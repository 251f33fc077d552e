"""The option groups of the subcommands that reach a bus (each option is declared once, in bench.options),
and the checks they share.

A bad value is a `ConfigError` (one line, exit 2, printed by `bench.cli.main`), found before a bus is
used or a case runs.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

from rich.console import Console

from bench.config import ProjectConfig
from bench.database.codec import Codebook, load_codebook
from bench.errors import ConfigError
from bench.options import add_cli_options
from bench.session import resolve_bus_options
from bench.transport import EMBEDDED, PYTHON_CAN_VIRTUAL, check_interface
from bench.transport.busopts import BusOptions

BUS_OPTIONS = ("interface", "channel", "bitrate", "fd", "data-bitrate", "config")
NODE_OPTIONS = ("external", "fault")


#: Columns a table printed into a pipe or a file may take: more than any row needs, so the table is whole.
PIPED_WIDTH = 1000


def table_console(stderr: bool = False) -> Console:
    """A console to print tables on: at a terminal its width (rich narrows the wrappable columns first; the
    identifier and name columns are no_wrap with a min_width, so they are never cut); into a pipe or a file
    (`bench dbc > file`, a CI log) wide enough that no table is cut at 80 columns (issue 34: `0…`, `DR…`)."""
    stream = sys.stderr if stderr else sys.stdout
    return Console(stderr=stderr, width=None if stream.isatty() else PIPED_WIDTH, highlight=False)


def add_bus_options(parser: argparse.ArgumentParser, default_interface: str, channel_help: str = "") -> None:
    """--interface, --channel, --bitrate, --fd/--no-fd, --data-bitrate, --config (declared in bench.options)."""
    add_cli_options(parser, BUS_OPTIONS, defaults={"interface": default_interface},
                    helps={"channel": channel_help} if channel_help else None)


def add_node_options(parser: argparse.ArgumentParser, helps: dict[str, str] | None = None) -> None:
    """--external and --fault: which nodes are real, which faults the bench injects (bench.options); `helps`
    adapts an option's help to the command (bench.options.add_cli_options)."""
    add_cli_options(parser, NODE_OPTIONS, helps=helps)


def given_bus_options(args: argparse.Namespace) -> BusOptions:
    """What the command line says about the bus (None where it says nothing)."""
    return BusOptions(bitrate=args.bitrate, fd=args.fd, data_bitrate=args.data_bitrate)


def check_out_dir(out_dir: Path, force: bool) -> None:
    """The report folder: a folder (or creatable), writable, and not a previous report unless --force.
    Created here, so that pytest never meets a folder it cannot write."""
    if out_dir.exists() and not out_dir.is_dir():
        raise ConfigError(f"--out {out_dir}: is a file, not a folder")
    if out_dir.is_dir() and any(out_dir.iterdir()) and not force:
        raise ConfigError(f"--out {out_dir}: folder exists and is not empty (a previous report?); "
                          "give another folder, or --force to write into it")
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=out_dir):
            pass
    except OSError as exc:
        raise ConfigError(f"--out {out_dir}: cannot write there: {exc.strerror or exc}") from None
    if not os.access(out_dir, os.W_OK | os.X_OK):   # a folder the probe could use but the run could not
        raise ConfigError(f"--out {out_dir}: cannot write there: permission denied")


def reject_in_process(interface: str) -> None:
    """For the commands that share a bus with other processes (plant, monitor, replay)."""
    check_interface(interface)
    if interface == EMBEDDED:
        raise ConfigError(f"--interface {EMBEDDED}: the embedded bus (in process, virtual time) cannot be reached "
                          "from another process; use udp_multicast, socketcan or a hardware interface")
    if interface == PYTHON_CAN_VIRTUAL:
        raise ConfigError(f"--interface {PYTHON_CAN_VIRTUAL}: python-can's virtual bus cannot be reached from "
                          "another process; use udp_multicast, socketcan or a hardware interface")


def bus_options_for(project: ProjectConfig, args: argparse.Namespace) -> tuple[BusOptions, Codebook]:
    """The bus settings of a command (command line over [bus] over the databases) and the databases."""
    codebook = load_codebook(project.databases, project.e2e, project.messages)
    return resolve_bus_options(project, given_bus_options(args), codebook), codebook
