"""`bench monitor`: a live view of every message on a bus, checked as the bench checks it.

Per message: identifier, name, sender, measured rate and cycle time (p50 / max over a sliding window)
against the DBC cycle time, the last valid decoded values, the end-to-end state (counts of checksum,
counter, length and range errors) and the timeout state; above it the totals (frames, invalid frames,
unknown identifiers). Every frame goes through `bench.checks.monitor.Monitor`, the same checks as a bench run.

Frame times are the interface's receive timestamps (the kernel's on socketcan and udp_multicast), so the
measured cycle times do not depend on when this process gets to read or draw; python-can's `Notifier` reads
the bus in its own thread and only queues frames (a `can.BufferedReader`). Works on any python-can interface;
it only listens.
"""

from __future__ import annotations

import argparse
import math
import time
from collections import Counter, deque
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import can
from rich import box
from rich.console import Console, Group, JustifyMethod
from rich.live import Live
from rich.table import Table
from rich.text import Text

from bench import canid
from bench.canid import IDENTITY
from bench.checks.monitor import TIMEOUT_CYCLES, MessageState, Monitor
from bench.cli.common import add_bus_options, bus_options_for, reject_in_process
from bench.config import load_config
from bench.database.codec import MessageCodec
from bench.errors import BenchError, ConfigError
from bench.transport import UDP_MULTICAST_DEFAULT_GROUP, open_bus

REFRESH = 0.25          # s between screen updates
DEFAULT_WINDOW = 2.0    # s of frames the rate and cycle columns are measured over
RATE_WARN = 0.10        # a measured rate further than this fraction from the DBC's is highlighted
OFFSET_BLOCK = 5.0      # s: the interface-to-host clock offset is re-estimated over blocks this long
E2E_KINDS = ("checksum", "counter", "state", "length", "range", "decode")   # the monitor's reasons (.invalid)


class MonitorError(BenchError):
    """The bus failed while monitoring."""


def register(sub: Any) -> None:
    parser = sub.add_parser("monitor", help="live view of every message on a bus (rates, values, E2E, timeouts)",
                            description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_bus_options(parser, "udp_multicast",
                    f"channel (e.g. can0, PCAN_USBBUS1; udp_multicast default {UDP_MULTICAST_DEFAULT_GROUP})")
    parser.add_argument("--duration", type=float, default=None, help="stop after S seconds (default: Ctrl-C)")
    parser.add_argument("--window", type=float, default=DEFAULT_WINDOW,
                        help=f"s of frames for the rate and cycle columns (default {DEFAULT_WINDOW:g})")
    parser.set_defaults(handler=run)


# -- time ------------------------------------------------------------------------------------------------
class TimeBase:
    """Frame times in s since the first frame, on the interface's clock; `now()` maps the host clock onto it.

    Interfaces stamp frames with their own clocks (the kernel's wall clock, a device counter). The offset
    host − frame time is smallest for the frames read soonest; its minimum over a block of OFFSET_BLOCK s
    is the mapping for the next block, so a slow drift between the two clocks cannot fake timeouts.
    Interfaces without timestamps (0) are stamped with the host clock when read.
    """

    def __init__(self) -> None:
        self.origin: float | None = None
        self.use_stamps = True
        self.offset: float | None = None
        self._block_min = math.inf
        self._block_end = OFFSET_BLOCK

    def stamp(self, stamp: float, host: float) -> float:
        if self.origin is None:
            self.use_stamps = isinstance(stamp, (int, float)) and math.isfinite(stamp) and stamp > 0
            self.origin = stamp if self.use_stamps else host
        t = (stamp if self.use_stamps else host) - self.origin
        offset = host - t
        self._block_min = min(self._block_min, offset)
        self.offset = offset if self.offset is None else min(self.offset, offset)
        if host >= self._block_end:
            self.offset, self._block_min = self._block_min, math.inf
            self._block_end = host + OFFSET_BLOCK
        return t

    def now(self, host: float) -> float:
        return 0.0 if self.offset is None else host - self.offset


# -- receiving -------------------------------------------------------------------------------------------
class _Arrivals(can.Listener):
    """The host time each frame arrived (the Notifier calls it just before the BufferedReader, in its thread), and
    the first error of the bus."""

    def __init__(self, clock: Callable[[], float]) -> None:
        self.clock = clock
        self.times: deque[float] = deque()
        self.error: Exception | None = None

    def on_message_received(self, msg: can.Message) -> None:
        self.times.append(self.clock())

    def on_error(self, exc: Exception) -> None:
        if self.error is None:
            self.error = exc
        time.sleep(0.05)   # the Notifier goes on reading after a handled error: no busy loop until the view stops


class Reception:
    """The bus read by python-can's `Notifier` in its thread into a `can.BufferedReader`, each frame with the host
    time it arrived; nothing else happens there, so it keeps up while the screen is drawn."""

    def __init__(self, bus: can.BusABC, clock: Callable[[], float], source: str) -> None:
        self.source = source
        self.reader = can.BufferedReader()
        self._arrivals = _Arrivals(clock)
        # the arrival time first: the frame is in the reader only once its time is in the list
        self.notifier = can.Notifier(bus, [self._arrivals, self.reader], timeout=0.1)

    def drain(self) -> Iterator[tuple[float, can.Message]]:
        """(host time, message) of every frame received so far; MonitorError once the bus failed."""
        times = self._arrivals.times
        while (msg := self.reader.get_message(0)) is not None:
            yield times.popleft(), msg
        if self._arrivals.error is not None:
            raise MonitorError(f"{self.source}: receiving failed: {self._arrivals.error}")

    def stop(self) -> None:
        self.notifier.stop(timeout=1.0)


class LiveMonitor:
    """The monitor of the bus and what the screen needs besides it (unknown ids, trimmed counts)."""

    def __init__(self, monitor: Monitor, window: float) -> None:
        self.monitor = monitor
        self.window = window
        self.time = TimeBase()
        self.unknown: Counter[str] = Counter()

    def feed(self, host: float, msg: can.Message) -> None:
        t = self.time.stamp(msg.timestamp, host)
        frame_id = canid.of_message(msg)
        ok = self.monitor.on_frame(t, frame_id, bytes(msg.data), "rx" if msg.is_rx else "tx")
        if not ok and frame_id & IDENTITY not in self.monitor.states:
            self.unknown["error frame" if msg.is_error_frame else canid.text(frame_id)] += 1

    def tick(self, host: float) -> float:
        """Timeouts up to now (the monitor keeps its own lists bounded). Returns now on the frames' time base."""
        now = self.time.now(host)
        self.monitor.check_timeouts(now)
        return now

    @property
    def invalid_frames(self) -> int:
        return self.monitor.invalid_frames


def window_stats(state: MessageState, now: float, window: float) -> tuple[float, float, float]:
    """(rate Hz, p50 s, max s) of the intervals that ended within the last `window` s; NaN without any."""
    if state.last_seen is None:
        return math.nan, math.nan, math.nan
    t = state.last_seen
    recent: list[float] = []
    for interval in reversed(state.intervals):
        if t < now - window:
            break
        recent.append(interval)
        t -= interval
    if not recent:
        return math.nan, math.nan, math.nan
    recent.sort()
    mean = sum(recent) / len(recent)
    n = len(recent)
    p50 = recent[n // 2] if n % 2 else 0.5 * (recent[n // 2 - 1] + recent[n // 2])
    return (1.0 / mean if mean > 0 else math.inf), p50, recent[-1]


# -- drawing ---------------------------------------------------------------------------------------------
def values_text(codec: MessageCodec, values: dict[str, float] | None) -> str:
    if values is None:
        return "–"
    parts = []
    for name, value in values.items():
        if name in codec.e2e_signals:   # the counter and the checksum: shown in the E2E column, not here
            continue
        names = {raw: label for label, raw in codec.by_name[name].choices.items()}
        label = names.get(int(value)) if value == int(value) else None
        parts.append(f"{name}={label or f'{value:.4g}'}")
    return " ".join(parts)


def e2e_text(state: MessageState) -> Text:
    """The message's protection as AUTOSAR names it: its profile and the E2E state machine's state, then the
    check statuses other than OK and the other reasons frames were rejected (unprotected messages say so)."""
    protection = state.codec.protection
    head = "unprotected" if state.rx is None or protection is None else f"{protection.profile} {state.rx.state.value}"
    statuses = [f"{name} {count}" for name, count in state.e2e_status.items() if name != "OK" and count]
    if not state.invalid and not statuses:
        return Text(head, style="dim" if state.rx is None else "green")
    order = {kind: i for i, kind in enumerate(E2E_KINDS)}          # known kinds first, any other after them
    parts = [f"{kind} {count}" for kind, count in sorted(state.invalid.items(), key=lambda kv: order.get(kv[0], 99))
             if count and kind not in ("checksum", "counter", "state")]
    return Text(" ".join([head, *statuses, *parts]), style="bold red" if state.invalid else "yellow")


def timeout_text(state: MessageState, monitor: Monitor, now: float) -> Text:
    if state.codec.cycle_time is None:
        return Text("–", style="dim")
    count = f" ({len(state.timeouts)}×)" if state.timeouts else ""
    if state.last_valid is None:
        return Text("no valid frame", style="yellow")
    if monitor.timed_out(state.codec.name, now):
        return Text(f"TIMEOUT{count}", style="bold red")
    return Text(f"ok{count}", style="yellow" if count else "green")


def _number(value: float, digits: int = 1) -> str:
    return "–" if not math.isfinite(value) else f"{value:.{digits}f}"


def render(live: LiveMonitor, now: float, source: str, elapsed: float) -> Group:
    monitor = live.monitor
    table = Table(box=box.MINIMAL, header_style="bold", pad_edge=False, expand=True)
    columns: tuple[tuple[str, JustifyMethod], ...] = (
        ("ID", "left"), ("Message", "left"), ("Sender", "left"), ("Frames", "right"), ("Rate Hz", "right"),
        ("DBC Hz", "right"), ("p50 ms", "right"), ("max ms", "right"), ("DBC ms", "right"), ("E2E", "left"),
        ("Timeout", "left"))
    for name, justify in columns:
        table.add_column(name, justify=justify, no_wrap=True)
    table.add_column("Values", no_wrap=True, overflow="ellipsis", ratio=1)   # the rest of the width
    seen = 0
    for frame_id in sorted(monitor.states):
        state = monitor.states[frame_id]
        if not state.frames:
            continue
        seen += 1
        codec = state.codec
        rate, p50, worst = window_stats(state, now, live.window)
        cycle = codec.cycle_time
        rate_style = ""
        if cycle and math.isfinite(rate) and abs(rate * cycle - 1.0) > RATE_WARN:
            rate_style = "bold yellow"
        table.add_row(
            canid.text(frame_id), codec.name, ",".join(codec.senders), str(state.frames),
            Text(_number(rate), style=rate_style), _number(1.0 / cycle) if cycle else "–",
            _number(p50 * 1000, 2), _number(worst * 1000, 2), f"{cycle * 1000:g}" if cycle else "–",
            e2e_text(state), timeout_text(state, monitor, now), values_text(codec, state.latest))
    invalid = live.invalid_frames
    header = Text.assemble(
        ("bench monitor ", "bold"), (source, "cyan"), f"   t={elapsed:6.1f} s   frames {monitor.frames}   ",
        (f"invalid {invalid}", "bold red" if invalid else "green"), "   ",
        (f"unknown ids {len(live.unknown)}", "bold yellow" if live.unknown else ""),
        f"   messages {seen}/{len(monitor.states)}   window {live.window:g} s   "
        f"timeout {TIMEOUT_CYCLES}× cycle   joined mid-stream: a message's first frame starts its E2E counter")
    parts: list[Any] = [header, table]
    if live.unknown:
        top = ", ".join(f"{key} ×{count}" for key, count in live.unknown.most_common(8))
        parts.append(Text(f"unknown: {top}", style="yellow"))
    for found in sorted(monitor.duplicates.values(), key=lambda d: d.frame_id):   # findings before symptoms
        parts.append(Text(f"{found.describe()} (from {found.t:.3f} s, {found.frames} frames)", style="bold red"))
    if monitor.invalid_log:
        last = monitor.invalid_log[-3:]
        parts.append(Text("last invalid: " + "; ".join(f"{f.message} {f.reason} at {f.t:.3f} s" for f in last),
                          style="red"))
    if not seen:
        parts.append(Text("waiting for frames …", style="dim"))
    return Group(*parts)


# -- command ---------------------------------------------------------------------------------------------
def run(args: argparse.Namespace) -> int:
    reject_in_process(args.interface)
    if args.duration is not None and not (math.isfinite(args.duration) and args.duration > 0):
        raise ConfigError(f"--duration: {args.duration} is not a positive number of seconds")
    if not (math.isfinite(args.window) and 0.05 <= args.window <= 600):
        raise ConfigError(f"--window: {args.window} is not a number of seconds in [0.05, 600]")
    project = load_config(Path(args.config) if args.config else None)
    options, codebook = bus_options_for(project, args)
    monitor = Monitor(codebook, keep_history=False)
    monitor.join_mid_stream()   # the bus runs already: a first frame's counter is no fault of its sender
    live = LiveMonitor(monitor, args.window)
    bus = open_bus(args.interface, args.channel, options)
    channel = args.channel or (UDP_MULTICAST_DEFAULT_GROUP if args.interface == "udp_multicast" else "")
    source = f"{args.interface} {channel}".strip()
    host0 = time.monotonic()

    def host() -> float:
        return time.monotonic() - host0

    reception = Reception(bus, host, f"{args.interface} {args.channel or ''}".strip())
    console = Console()
    end = args.duration if args.duration is not None else math.inf
    try:
        with Live(render(live, 0.0, source, 0.0), console=console, auto_refresh=False,
                  vertical_overflow="crop") as screen:
            while True:
                for host_time, msg in reception.drain():
                    live.feed(host_time, msg)
                elapsed = host()
                now = live.tick(elapsed)
                screen.update(render(live, now, source, elapsed), refresh=True)
                if elapsed >= end:
                    break
                time.sleep(min(REFRESH, max(0.0, end - elapsed)))
    except KeyboardInterrupt:
        pass
    finally:
        reception.stop()
        bus.shutdown()
    return 0
