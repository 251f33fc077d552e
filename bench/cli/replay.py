"""`bench replay`: send a run log's frames onto a bus with the recorded timing.

Why: to feed a real ECU or another bench process exactly what a run saw (a fault found in the field,
a campaign's stimulus) without the plant. Every raw frame is sent as logged, invalid ones included
(a replayed fault must stay a fault); error frames cannot be sent and are skipped. Frame i leaves at
(t_i - t_0) / speed after the first, t being the log time; a frame that is late (the host was busy)
goes at once, so delays never add up. Reading is streamed, so a log of any length (or a killed run's)
starts at once.
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import can
from rich.console import Console
from rich.markup import escape

from bench.bus import UDP_MULTICAST_DEFAULT_GROUP, open_bus
from bench.cli.common import add_bus_options, bus_options_for, reject_in_process
from bench.config import load_config
from bench.errors import ConfigError, LogError
from bench.log.logread import MAGIC, read_frames

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


def run(args: argparse.Namespace) -> int:
    console = Console(stderr=True, soft_wrap=True)
    reject_in_process(args.interface)
    if not (math.isfinite(args.speed) and args.speed > 0):
        raise ConfigError(f"--speed: {args.speed} is not a positive number")
    project = load_config(Path(args.config) if args.config else None)
    options, _ = bus_options_for(project, args)
    frames = read_frames(args.file)
    first = next(frames, None)                 # a missing or non-MCAP file fails here, before the bus opens
    if first is None:
        cut = "" if log_is_complete(args.file) else " (the log ends early: a killed run's, or cut)"
        raise LogError(f"{args.file}: no frames to replay{cut}")
    bus = open_bus(args.interface, args.channel, options)
    sent = skipped = failed = 0
    wall0 = time.perf_counter()
    interrupted = False
    try:
        t0: float | None = None
        for frame in _chain(first, frames):
            if args.direction != "all" and frame.direction != args.direction:
                continue
            if frame.is_error:
                skipped += 1
                continue
            if t0 is None:
                t0, wall0 = frame.t, time.perf_counter()
            _wait_until(wall0 + (frame.t - t0) / args.speed)
            message = can.Message(arbitration_id=frame.arbitration_id, data=frame.data, dlc=len(frame.data),
                                  is_extended_id=frame.is_extended, is_remote_frame=frame.is_remote,
                                  is_fd=len(frame.data) > 8, check=False)
            try:
                bus.send(message)
                sent += 1
            except can.CanError:
                failed += 1            # a full queue or bus-off: counted and reported, the replay goes on
    except KeyboardInterrupt:
        interrupted = True
    finally:
        bus.shutdown()
    took = time.perf_counter() - wall0
    state = "interrupted" if interrupted else "done"
    extra = f", {skipped} error frames skipped" if skipped else ""
    extra += f", [red]{failed} failed to send[/]" if failed else ""
    console.print(f"bench replay: {state}, sent {sent} frames in {took:.2f} s{extra}", highlight=False)
    if not interrupted and not log_is_complete(args.file):
        console.print(f"[yellow]bench replay: warning:[/] {escape(str(args.file))} ends early (no footer: a killed "
                      "run's log, or cut); its frames up to the cut were sent", highlight=False)
    if interrupted:
        return 130
    return 1 if failed else 0


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


def _chain(first: Any, rest: Iterator[Any]) -> Iterator[Any]:
    if first is not None:
        yield first
    yield from rest


def _wait_until(deadline: float) -> None:
    """Sleep until `deadline` (perf_counter time). No busy wait: the host is shared with the plant, and
    the kernel's sleep overshoot (~0.1 ms) is small against CAN cycle times."""
    remaining = deadline - time.perf_counter()
    if remaining > 0:
        time.sleep(remaining)
