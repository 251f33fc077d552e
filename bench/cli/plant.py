"""`bench plant`: the plant and every simulated ECU on a bus, in real time, until stopped.

Another process (`bench run --external all ...`, a real ECU, any python-can program) drives it.
"""

from __future__ import annotations

import argparse
import math
import signal
import time
from pathlib import Path

from rich.console import Console

from bench import canid
from bench.canid import IDENTITY
from bench.checks.monitor import Monitor
from bench.cli.common import add_bus_options, add_node_options, given_bus_options, reject_in_process
from bench.config import RunSettings, load_config
from bench.errors import ConfigError, Inconclusive
from bench.faults.plan import CASE, CASE_PREFIX, Fault, parse_fault
from bench.session import BenchSession

STATUS_PERIOD = 5.0   # s between status lines
INVALID_SHOWN = 3     # invalid frames described per status line
#: --fault's help here: bench plant runs no cases, so its windows count from its own start only
FAULT_HELP = ("inject a fault into the frames the plant sends: KIND:TARGET[:PARAM]@START[-END], START and END in s "
              "from bench plant's start (an open END lasts until it stops), e.g. drop:SOME_MESSAGE@3.5-3.8; "
              f"not {CASE_PREFIX}: bench plant runs no cases and refuses it (docs/reliability.md)")


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = sub.add_parser("plant", help="run the plant and the simulated ECUs on a bus in real time",
                            description="Run the plant and every simulated ECU on a bus in real time "
                                        "until SIGINT/SIGTERM or --duration.")
    add_bus_options(parser, "udp_multicast")
    add_node_options(parser, helps={"fault": FAULT_HELP})
    parser.add_argument("--vehicle", default=None, help="vehicle of the plant at start (a scenario may change it)")
    parser.add_argument("--duration", type=float, default=None, help="stop after S seconds")
    parser.set_defaults(handler=run)


def _report_invalid(console: Console, monitor: Monitor, shown: int) -> int:
    """Print what was wrong with the frames that became invalid since the last status line (the first
    few of them), so that a user of an external ECU sees why, not only how many. Returns the new count."""
    new = monitor.invalid_frames - shown
    if new > 0:
        records = monitor.invalid_log[-new:]
        # a message with two senders is said once (_report_duplicates), not with its counter errors
        own = [r for r in records if r.frame_id & IDENTITY not in monitor.duplicates]
        for record in own[:INVALID_SHOWN]:
            console.print(f"  invalid at t={record.t:.3f} s: {record.message} ({canid.text(record.frame_id)}): "
                          f"{record.reason}", highlight=False, markup=False)
        if len(own) > INVALID_SHOWN:
            console.print(f"  ... and {len(own) - INVALID_SHOWN} more", highlight=False)
        if len(own) < len(records):
            console.print(f"  ... and {len(records) - len(own)} of messages with two senders", highlight=False)
    return monitor.invalid_frames


def _report_duplicates(console: Console, monitor: Monitor, shown: set[int]) -> None:
    """Say each identifier with two senders once, with its evidence (bench.checks.monitor.DuplicateSender)."""
    for frame_id, found in sorted(monitor.duplicates.items()):
        if frame_id not in shown:
            shown.add(frame_id)
            console.print(f"  {found.describe()} (from t={found.t:.3f} s)", highlight=False, markup=False)


def plant_faults(specs: list[str]) -> list[Fault]:
    """The --fault specs of `bench plant`: ConfigError (one line) for a `case+` window, which counts from each
    case's start; the plant process runs no cases, so such a fault would never act (it dropped nothing)."""
    faults = [parse_fault(spec) for spec in specs]
    for spec, fault in zip(specs, faults, strict=True):
        if fault.relative == CASE:
            raise ConfigError(f"--fault {spec!r}: {CASE_PREFIX} counts from each case's start, which only `bench run` "
                              f"knows; bench plant runs no cases, so the fault would never act: give the window in s "
                              f"from bench plant's start (e.g. {fault.kind}:{fault.target}@{fault.start:g}-"
                              f"{'' if math.isinf(fault.end) else f'{fault.end:g}'})")
    return faults


def run(args: argparse.Namespace) -> int:
    console = Console(stderr=True)
    reject_in_process(args.interface)
    if args.duration is not None and not (math.isfinite(args.duration) and args.duration > 0):
        raise ConfigError(f"--duration: {args.duration} is not a positive number of seconds")
    project = load_config(Path(args.config) if args.config else None)
    if args.vehicle is not None and project.plant is None:
        raise ConfigError(f"--vehicle {args.vehicle}: {project.path} names no plant ([bench] plant), so there is no "
                          "vehicle to choose")
    settings = RunSettings(interface=args.interface, channel=args.channel, external=args.external,
                           vehicle=args.vehicle, bus=given_bus_options(args))
    faults = plant_faults(args.fault)
    session = BenchSession(project, settings, role="plant")
    try:
        session.faults.extend(faults)   # a fault on frames this process does not send: one line, before the start
    except ConfigError:
        session.close()
        raise
    stop = {"now": False}

    def request_stop(signum: int, frame: object) -> None:
        stop["now"] = True

    signal.signal(signal.SIGINT, request_stop)
    signal.signal(signal.SIGTERM, request_stop)
    plant = session.plant
    assert plant is not None
    what = "" if project.plant is not None else " (no plant: each from its database's start values)"
    console.print(f"bench plant: simulating {', '.join(sorted(plant.restbus.nodes))}{what} on "
                  f"{args.interface} {session.channel or ''}; Ctrl-C to stop", highlight=False)
    session.start()
    end = args.duration if args.duration is not None else math.inf
    wall0 = time.monotonic()
    next_status = STATUS_PERIOD
    shown = 0   # invalid frames of the plant's monitor already reported (monitor.invalid_frames)
    duplicates: set[int] = set()   # identifiers with two senders already reported
    behind = 0   # times the watchdog found the plant's ticks behind the wall clock (bench.sim.clock.Scheduler)
    try:
        while not stop["now"] and session.now() < end:
            try:
                session.run_until(min(end, session.scheduler.now + 0.1), lambda: stop["now"])
            except Inconclusive as exc:   # the watchdog: the plant went on from the wall clock's tick
                behind += 1
                console.print(f"bench plant: {exc}; went on from the wall clock's tick ({behind} times)",
                              highlight=False)
            if session.now() >= next_status:
                next_status += STATUS_PERIOD
                console.print(f"t={session.now():7.1f} s  sent {plant.sent}  received "
                              f"{plant.monitor.frames - plant.sent}  invalid {plant.monitor.invalid_frames}  "
                              f"max lag {getattr(session.clock, 'max_lag', 0.0) * 1000:.1f} ms"
                              + (f"  two senders {len(plant.monitor.duplicates)}" if plant.monitor.duplicates else ""),
                              highlight=False)
                _report_duplicates(console, plant.monitor, duplicates)
                shown = _report_invalid(console, plant.monitor, shown)
    finally:
        session.close()
    _report_duplicates(console, plant.monitor, duplicates)   # also when it stopped before a status line
    console.print(f"bench plant: stopped after {time.monotonic() - wall0:.1f} s, sent {plant.sent} frames")
    return 0
