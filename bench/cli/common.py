"""Options shared by the subcommands that reach a bus."""

from __future__ import annotations

import argparse


def add_bus_options(parser: argparse.ArgumentParser, default_interface: str) -> None:
    parser.add_argument("--interface", "-i", default=default_interface,
                        help=f"python-can interface, or 'virtual' for the in-process virtual-time bus "
                             f"(default: {default_interface})")
    parser.add_argument("--channel", "-c", default=None, help="channel (e.g. vcan0, a multicast group)")
    parser.add_argument("--external", nargs="+", action="extend", default=[], metavar="NODE",
                        help="nodes that are real, not simulated ('all' = every node but the stimulus)")
    parser.add_argument("--fault", action="append", default=[], metavar="SPEC",
                        help="inject a fault: KIND:TARGET[:PARAM]@START[-END], e.g. drop:VCU_WheelCmd_FL@2-3 "
                             "(kinds: see bench/faults.py)")
    parser.add_argument("--config", default=None, help="the project's bench.toml (default: found from here)")
