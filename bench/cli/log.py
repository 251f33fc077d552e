"""`bench log`: look into run logs (MCAP) without Foxglove, e.g. to see what a killed run left behind,
and export them to the formats other CAN tools read (BLF, ASC, candump, CSV) through python-can's writers."""

from __future__ import annotations

import argparse
import re
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import can
from rich.console import Console
from rich.table import Table

from bench.cli.common import table_console
from bench.errors import LogError
from bench.log.canio import frame_to_message
from bench.log.logread import LoggedFrame, LogSummary, read_frames, run_start, summarise

#: --format -> (python-can writer, file suffix). Direction (Rx/Tx) is carried by BLF (the DIR flag),
#: ASC ("Rx"/"Tx") and candump (python-can's trailing R/T); CSV has no column for it.
EXPORT_FORMATS: dict[str, tuple[type[can.io.generic.MessageWriter], str]] = {
    "blf": (can.BLFWriter, ".blf"),
    "asc": (can.ASCWriter, ".asc"),
    "candump": (can.CanutilsLogWriter, ".log"),
    "csv": (can.CSVWriter, ".csv"),
}
#: BLF's header holds its start time as a SYSTEMTIME; python-can writes it only for Unix times after 1990
#: (an all-zero one otherwise, which BLFReader reads back as 0).
BLF_UNIX_EPOCH_MIN = 631152000.0
_INTERFACE_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]*\Z")


def register(subparsers: Any) -> None:
    parser = subparsers.add_parser("log", help="inspect run logs (MCAP)", description=__doc__)
    actions = parser.add_subparsers(dest="log_command", required=True, metavar="ACTION")
    info = actions.add_parser("info", help="time span, frames, attachments and channels of a run log")
    info.add_argument("file", type=Path, help="the run log (.mcap), or a report folder (its logs; a merged "
                                              "folder's through its index logs.json), or that index")
    info.set_defaults(handler=info_handler)
    export = actions.add_parser("export", help="write a run log's raw frames as BLF, ASC, candump or CSV",
                                description="Write every raw frame of a run log (MCAP, also a killed run's) "
                                            "with its log time through python-can's writers.")
    export.add_argument("file", type=Path, help="the run log (.mcap)")
    export.add_argument("--format", "-f", required=True, choices=sorted(EXPORT_FORMATS), dest="fmt",
                        help="blf (Vector binary), asc (Vector ASCII), candump (candump -L log), csv (python-can CSV)")
    export.add_argument("--output", "-o", type=Path, default=None,
                        help="where to write (default: FILE with the format's suffix: .blf .asc .log .csv)")
    export.set_defaults(handler=export_handler)


def info_handler(args: argparse.Namespace) -> int:
    """Print a run log's summary; a LogError for a missing or non-MCAP file reaches the framework."""
    from bench.report.merge import log_files  # a merged report's index of its shards' logs

    console = table_console()
    for path in log_files(args.file):
        show(summarise(path), console)
    return 0


def export_handler(args: argparse.Namespace) -> int:
    output: Path = args.output or args.file.with_suffix(EXPORT_FORMATS[args.fmt][1])
    frames = export(args.file, output, args.fmt)
    Console(stderr=True).print(f"bench log export: {frames} frames from {args.file} to {output} ({args.fmt})",
                               highlight=False)
    return 0


def export(source: Path, output: Path, fmt: str) -> int:
    """Write every raw frame of `source` to `output` in `fmt`; returns the number of frames.

    Timestamps are the log times (ASC writes them relative to its first frame, whose time is in its
    header; BLF in 1 ns steps from its start time). Channels: BLF and ASC number them (1, 2, ... in the
    file, in order of first appearance); candump keeps an interface-like name (the part after the bench's
    "interface:" prefix, e.g. vcan0) or numbers them can0, can1, ... Invalid frames are exported too:
    they were on the bus.
    """
    writer_class, _ = EXPORT_FORMATS[fmt]
    if output.resolve() == Path(source).resolve():
        raise LogError(f"{output}: the export would overwrite the run log itself; choose another --output")
    frames = read_frames(source)
    first = next(frames, None)          # a missing or non-MCAP source fails here, before the output exists
    try:
        if writer_class is can.ASCWriter:
            writer: can.io.generic.MessageWriter = _ASCWriter(output, _start_date(source, first))
        else:
            writer = writer_class(output)
    except OSError as exc:
        raise LogError(f"{output}: cannot write: {exc.strerror or exc}") from None
    if isinstance(writer, can.BLFWriter) and first is not None and first.t < BLF_UNIX_EPOCH_MIN:
        # Bench time is not a Unix time: BLF's header then says "no start time" (zero), so the frames must be
        # written relative to 0 too, or reading back would shift them by the first frame's time.
        writer.start_timestamp = 0.0
    channels: dict[str, int] = {}
    count = 0
    try:
        for frame in ([first] if first is not None else []):
            count += _write(writer, frame, fmt, channels)
        for frame in frames:
            count += _write(writer, frame, fmt, channels)
    except OSError as exc:
        raise LogError(f"{output}: cannot write: {exc.strerror or exc}") from None
    finally:
        writer.stop()
    return count


class _ASCWriter(can.ASCWriter):
    """python-can's ASC writer with the header's `date` the run's start: python-can writes the time the file is
    created, which for an export is the export's time, not the measurement's."""

    def __init__(self, file: Path, date: datetime | None) -> None:
        self._date = date
        super().__init__(file)

    def _format_header_datetime(self, dt: datetime) -> str:
        if self._date is not None:   # the first call: the `date` line (then: the first frame's, as given)
            dt, self._date = self._date, None
        return super()._format_header_datetime(dt)


def _start_date(source: Path, first: LoggedFrame | None) -> datetime | None:
    """The run's start as ASC writes dates (local time, as python-can writes the first frame's): bench time 0 of
    a bench run's log, else the first frame's time when it is a Unix time; None (the export's time) otherwise."""
    start = run_start(source)
    if start is None and first is not None and first.t >= BLF_UNIX_EPOCH_MIN:
        start = first.t
    return None if start is None else datetime.fromtimestamp(start)


def _write(writer: can.io.generic.MessageWriter, frame: LoggedFrame, fmt: str, channels: dict[str, int]) -> int:
    message = frame_to_message(frame)
    index = channels.setdefault(frame.channel, len(channels))
    if fmt == "candump":
        name = frame.channel.rsplit(":", 1)[-1]
        message.channel = name if _INTERFACE_NAME.match(name) else f"can{index}"
    else:
        message.channel = index          # BLF and ASC write channel + 1 (their channels start at 1)
    writer.on_message_received(message)
    return 1


def _date(seconds: float) -> str:
    """A Unix time as an ISO 8601 date in UTC, to the microsecond: 2026-11-27T13:30:05.123456+00:00."""
    return datetime.fromtimestamp(seconds, UTC).isoformat(timespec="microseconds")


def show(summary: LogSummary, console: Console) -> None:
    facts = Table.grid(padding=(0, 2))
    facts.add_column(style="bold")
    facts.add_column()
    facts.add_row("File", str(summary.path))
    facts.add_row("Status", "[green]complete[/]" if summary.complete
                  else "[yellow]truncated[/] (no footer: killed run or cut file)")
    if summary.start is None or summary.end is None:
        facts.add_row("Time", "no messages")
    elif summary.origin is not None or summary.start >= BLF_UNIX_EPOCH_MIN:   # Unix times: dates
        span = f"{_date(summary.start)} … {_date(summary.end)} (duration {summary.end - summary.start:.6f} s)"
        if summary.origin is not None:
            span += (f"; bench time {summary.start - summary.origin:.6f} s … {summary.end - summary.origin:.6f} s, "
                     f"bench time 0 at {_date(summary.origin)}")
        facts.add_row("Time", span)
    else:
        facts.add_row("Time", f"{summary.start:.6f} s … {summary.end:.6f} s "
                              f"(duration {summary.end - summary.start:.6f} s)")
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
