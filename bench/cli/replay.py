"""`bench replay`: send a run log's frames onto a bus with the recorded timing.

Why: to feed a real ECU or another bench process exactly what a run saw (a fault found in the field,
a campaign's stimulus) without the plant. Every raw frame is sent as logged, invalid ones included
(a replayed fault must stay a fault), with its CAN FD flags; error frames cannot be sent and are skipped.
The log is read through python-can's registered ".mcap" reader (bench.log.canio) and timed by python-can's
`MessageSync`: frame i leaves at (t_i - t_0) / speed after the start; a frame that is late (the host was busy)
goes at once, so delays never add up. Reading is streamed, so a log of any length (or a killed run's)
starts at once.
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import can
from rich.console import Console
from rich.markup import escape

from bench.cli.common import add_bus_options, bus_options_for, reject_in_process
from bench.config import load_config
from bench.errors import ConfigError, LogError
from bench.log.canio import log_reader
from bench.log.format import MAGIC
from bench.transport import UDP_MULTICAST_DEFAULT_GROUP, open_bus

DIRECTIONS = ("tx", "rx", "all")


def register(sub: Any) -> None:
    parser = sub.add_parser("replay", help="replay a run log (MCAP) onto a bus with the recorded timing",
                            description=__doc__)
    parser.add_argument("file", type=Path, help="the run log (.mcap)")
    add_bus_options(parser, "udp_multicast",
                    f"channel (e.g. can0, PCAN_USBBUS1; udp_multicast default {UDP_MULTICAST_DEFAULT_GROUP})")
    parser.add_argument("--speed", type=float, default=1.0, help="time factor: 2 plays twice as fast (default 1)")
    parser.add_argument("--direction", choices=DIRECTIONS, default="all",
                        help="only the frames the logging bench sent (tx), received (rx), or all (default)")
    parser.set_defaults(handler=run)


@dataclass
class Counts:
    sent: int = 0
    skipped: int = 0     # error frames: they cannot be sent
    failed: int = 0      # a full queue or bus-off


def run(args: argparse.Namespace) -> int:
    console = Console(stderr=True, soft_wrap=True)
    reject_in_process(args.interface)
    if not (math.isfinite(args.speed) and args.speed > 0):
        raise ConfigError(f"--speed: {args.speed} is not a positive number")
    project = load_config(Path(args.config) if args.config else None)
    options, _ = bus_options_for(project, args)
    reader = log_reader(args.file)             # a missing or non-MCAP file fails here, before the bus opens
    counts = Counts()
    wall0 = time.perf_counter()
    interrupted = False
    try:
        messages = iter(reader)
        first = next(messages, None)
        if first is None:
            cut = "" if log_is_complete(args.file) else " (the log ends early: a killed run's, or cut)"
            raise LogError(f"{args.file}: no frames to replay{cut}")
        bus = open_bus(args.interface, args.channel, options)
        try:
            wall0 = time.perf_counter()
            play(_chain(first, messages), bus, args.speed, args.direction, counts)
        except KeyboardInterrupt:
            interrupted = True
        finally:
            bus.shutdown()
    finally:
        reader.stop()
    took = time.perf_counter() - wall0
    state = "interrupted" if interrupted else "done"
    extra = f", {counts.skipped} error frames skipped" if counts.skipped else ""
    extra += f", [red]{counts.failed} failed to send[/]" if counts.failed else ""
    console.print(f"bench replay: {state}, sent {counts.sent} frames in {took:.2f} s{extra}", highlight=False)
    if not interrupted and not log_is_complete(args.file):
        console.print(f"[yellow]bench replay: warning:[/] {escape(str(args.file))} ends early (no footer: a killed "
                      "run's log, or cut); its frames up to the cut were sent", highlight=False)
    if interrupted:
        return 130
    return 1 if counts.failed else 0


def play(messages: Iterable[can.Message], bus: can.BusABC, speed: float, direction: str, counts: Counts) -> None:
    """Send the messages of a log (as python-can's readers give them) with their recorded timing, `speed` times
    as fast, only those of `direction` (tx, rx or all); a late frame goes at once."""
    # skip=inf: MessageSync's default shortens a pause longer than 60 s; a replay keeps every pause
    for message in can.MessageSync(_sendable(messages, speed, direction, counts), timestamps=True, skip=math.inf):
        try:
            bus.send(message)
            counts.sent += 1
        except can.CanError:
            counts.failed += 1            # a full queue or bus-off: counted and reported, the replay goes on


def _sendable(messages: Iterable[can.Message], speed: float, direction: str, counts: Counts
              ) -> Iterator[can.Message]:
    """The messages to send, their times divided by `speed`, their channel the bus's own (python-can's socketcan
    would send on the logged channel's name)."""
    for message in messages:
        if direction != "all" and ("rx" if message.is_rx else "tx") != direction:
            continue
        if message.is_error_frame:
            counts.skipped += 1
            continue
        message.timestamp /= speed
        message.channel = None
        yield message


def log_is_complete(path: Path) -> bool:
    """Whether a run log ends as a closed MCAP file does: with the magic after its footer. A killed run's
    log, or a copy cut short, lacks it; the stream reader then ends quietly at the cut."""
    try:
        with path.open("rb") as file:
            size = file.seek(0, 2)
            if size < 2 * len(MAGIC):
                return False
            file.seek(size - len(MAGIC))
            return file.read(len(MAGIC)) == MAGIC
    except OSError:
        return False


def _chain(first: can.Message, rest: Iterator[can.Message]) -> Iterator[can.Message]:
    yield first
    yield from rest
