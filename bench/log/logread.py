"""Reading run logs (MCAP, written by `bench.log.recorder`, format bench.log.format) back, also of killed runs.

Why a streaming read for every file rather than the indexed reader: a run killed with
SIGKILL leaves no footer and a cut last chunk, and the same code path must then give every
message of the whole chunks before the cut; file order is also the order the bench wrote.
The records come from `bench.log.mcapfast.read_records` (mcap's `StreamReader`'s records, read faster).
A short read would be handed on (a cut record then fails later as a `struct.error` or a zstd error,
depending on where the cut is), so the file is wrapped to turn any short read into mcap's own
`EndOfFile`: a cut at any byte ends the iteration quietly, at the last whole record.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import struct
from collections.abc import Generator, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

from mcap.exceptions import EndOfFile, McapError
from mcap.reader import make_reader
from mcap.records import Attachment, Channel, Footer, McapRecord, Message, Metadata

from bench.errors import LogError
from bench.log.format import (
    CLOCK_METADATA,
    COUNTS_METADATA,
    DECODED_PREFIX,
    FRAMES_TOPIC,
    MAGIC,
    STEPS_TOPIC,
    VALID_FALSE,
    VALID_TRUE,
)
from bench.log.mcapfast import read_records

__all__ = ["MAGIC", "LoggedFrame", "LogSummary", "read_decoded", "read_frames", "read_steps", "run_start",
           "summarise"]
_EXACT_NS = 1 << 53   # log times below it convert to float exactly
_decode_json = json.JSONDecoder().decode   # json.loads less its per-call encoding sniffing (the log is UTF-8)


@dataclass
class LoggedFrame:
    """One frame of `/can/frames`; `data` without the padding, `t_ns` the exact log time."""

    t: float
    arbitration_id: int
    data: bytes
    channel: str
    direction: str
    is_extended: bool
    is_error: bool
    valid: bool
    error: str
    is_remote: bool = False
    t_ns: int = 0
    is_fd: bool = False
    bitrate_switch: bool = False
    error_state_indicator: bool = False
    channel_number: int | None = None      # the channel as the bus gave it, when a number


@dataclass
class LogSummary:
    """What `bench log info` shows. `complete` is False for a log without footer (killed or cut run)."""

    path: Path
    channels: dict[str, int] = field(default_factory=dict)  # topic -> message count
    start: float | None = None
    end: float | None = None
    frames: int = 0
    invalid_frames: int = 0
    attachments: list[str] = field(default_factory=list)
    complete: bool = False
    origin: float | None = None     # epoch s of bench time 0 (bench runs log epoch times); None: not said
    metadata: list[tuple[str, dict[str, str]]] = field(default_factory=list)   # e.g. bench.fault records


class _WholeReads:
    """A binary file whose short reads raise `EndOfFile`, so every cut looks alike to the reader."""

    def __init__(self, file: IO[bytes]) -> None:
        self._file = file
        here = file.tell()
        self._size = file.seek(0, os.SEEK_END)   # also of a file object without a descriptor (gzip, BytesIO)
        file.seek(here)

    def read(self, size: int = -1) -> bytes:
        if size is not None and size > self._size - self._file.tell():
            raise EndOfFile()   # a length beyond the end: a cut (or a damaged length), never a huge read
        data = self._file.read(size)
        if size is not None and 0 < size and len(data) < size:
            raise EndOfFile()
        return data


class _Scan:
    """The records of a log in file order, ending quietly at a cut; `complete` once the footer and end magic are read.

    `source` is a path or a binary file object read from where it stands (python-can's readers take both);
    one that cannot seek (a pipe) is read into memory first."""

    def __init__(self, source: str | os.PathLike[str] | IO[bytes]) -> None:
        self._stream: IO[bytes] | None = None
        if hasattr(source, "read"):
            stream: Any = source
            self.path = Path(str(getattr(stream, "name", "<stream>")))
            try:
                if not stream.seekable():
                    stream = io.BytesIO(stream.read())
                self._stream, self._start = stream, stream.tell()
                head = stream.read(len(MAGIC))
                stream.seek(self._start)
            except OSError as exc:
                raise LogError(f"{self.path}: cannot read run log: {exc}") from None
        else:
            self.path = Path(source)
            try:
                with self.path.open("rb") as file:
                    head = file.read(len(MAGIC))
            except OSError as exc:
                raise LogError(f"{self.path}: cannot read run log: {exc.strerror}") from None
        self.complete = False
        self.topics: dict[int, str] = {}  # channel id -> topic
        self.origin_ns = 0                # log time of bench time 0 (metadata bench.sim.clock), read on the way
        if not isinstance(head, bytes):
            raise LogError(f"{self.path}: a run log is read from a binary file, not {type(source).__name__}")
        if not MAGIC.startswith(head):  # a log cut inside its magic is an empty log, not a foreign file
            raise LogError(f"{self.path}: not an MCAP run log")

    def _open(self) -> Any:
        if self._stream is None:
            return self.path.open("rb")
        self._stream.seek(self._start)
        return contextlib.nullcontext(self._stream)   # the caller's file: it closes it

    def __iter__(self) -> Iterator[McapRecord]:
        footer = False
        with self._open() as file:
            try:
                for record in read_records(_WholeReads(file).read):
                    if isinstance(record, Channel):
                        self.topics[record.id] = record.topic
                    elif isinstance(record, Metadata) and record.name == CLOCK_METADATA:
                        with contextlib.suppress(KeyError, ValueError):
                            self.origin_ns = int(record.metadata["origin_ns"])
                    elif isinstance(record, Footer):
                        footer = True
                    yield record
            except McapError:  # EndOfFile at a cut; a bad trailing magic or absurd record length likewise ends the log
                return
            except Exception as exc:  # damaged bytes inside a record (compression, structure): a clear error
                raise LogError(f"{self.path}: damaged run log at byte {file.tell()}: "
                               f"{type(exc).__name__}: {exc}") from None
        self.complete = footer  # the records stop after the footer's end magic


def _messages(scan: _Scan, wanted: Any) -> Iterator[tuple[str, Message]]:
    """(topic, message) of the messages whose topic satisfies `wanted(topic)`."""
    ids: set[int] = set()
    for record in scan:
        if isinstance(record, Message):
            if record.channel_id in ids:
                yield scan.topics.get(record.channel_id, ""), record
        elif isinstance(record, Channel) and wanted(record.topic):
            ids.add(record.id)


def read_frames(path: str | Path | IO[bytes]) -> Generator[LoggedFrame, None, None]:
    """The raw frames of a log, in the order logged (`path` may also be a binary file object)."""
    scan = _Scan(path)
    path = scan.path
    for _, message in _messages(scan, FRAMES_TOPIC.__eq__):
        try:
            d = _decode_json(message.data.decode())
            channel = d.get("channel")
            if channel is None:         # a log of another writer: ROS's header only
                channel = d.get("header", {}).get("frame_id", "")
            dlc = int(d["dlc"])
            ns = message.log_time
            if ns < _EXACT_NS:
                t = ns / 1e9            # exact int to float: one rounding, the nearest float
            else:                       # a wall-clock time: whole seconds apart, or the int loses its last bits
                seconds, ns = divmod(ns, 1_000_000_000)
                t = seconds + ns / 1e9
            number = d.get("channel_number")
            frame = LoggedFrame(
                t=t, arbitration_id=int(d["id"]), data=bytes(d["data"][:dlc]),
                channel=str(channel), direction=d.get("direction", "rx"), is_extended=bool(d["is_extended"]),
                is_error=bool(d["is_error"]), valid=bool(d.get("valid", True)), error=str(d.get("error", "")),
                is_remote=bool(d["is_rtr"]), t_ns=message.log_time, is_fd=bool(d.get("is_fd", dlc > 8)),
                bitrate_switch=bool(d.get("bitrate_switch", False)),
                error_state_indicator=bool(d.get("error_state_indicator", False)),
                channel_number=None if number is None else int(number))
        except (ValueError, KeyError, TypeError, AttributeError) as exc:
            raise LogError(f"{path}: damaged frame record at {message.log_time} ns: "
                           f"{type(exc).__name__}: {exc}") from None
        yield frame


def _json(path: str | Path, record: Message) -> Any:
    try:
        return json.loads(record.data)
    except ValueError as exc:   # JSONDecodeError and UnicodeDecodeError
        raise LogError(f"{path}: damaged record at {record.log_time} ns: {exc}") from None


def read_decoded(path: str | Path, message: str | None = None) -> Iterator[tuple[float, str, dict[str, Any]]]:
    """(t, message name, signals) of the decoded messages, all or only `message`'s; t is bench time
    (the log time less the log's origin: a bench run logs epoch times)."""
    if message is None:
        wanted: Any = lambda topic: topic.startswith(DECODED_PREFIX)  # noqa: E731
    else:
        wanted = (DECODED_PREFIX + message).__eq__
    scan = _Scan(path)
    for topic, record in _messages(scan, wanted):
        yield (record.log_time - scan.origin_ns) / 1e9, topic[len(DECODED_PREFIX):], _json(path, record)


def read_steps(path: str | Path) -> Iterator[dict[str, Any]]:
    """The test steps and verdicts, as the foxglove.Log dicts logged."""
    for _, message in _messages(_Scan(path), STEPS_TOPIC.__eq__):
        yield _json(path, message)


def summarise(path: str | Path) -> LogSummary:
    """Counts, time span and attachments of a log, and whether it is complete: from the summary section and the
    invalid-frame count a bench log ends with (a few reads, whatever the log's length), else by reading every
    record (a cut log, one another program wrote)."""
    indexed = _indexed_summary(Path(path))
    return indexed if indexed is not None else _scanned_summary(path)


def _scanned_summary(path: str | Path) -> LogSummary:
    """`summarise` by reading every record."""
    scan = _Scan(path)
    summary = LogSummary(path=scan.path)
    start = end = None
    for record in scan:
        if isinstance(record, Message):
            topic = scan.topics.get(record.channel_id, f"(channel {record.channel_id})")
            summary.channels[topic] = summary.channels.get(topic, 0) + 1
            start = record.log_time if start is None else min(start, record.log_time)
            end = record.log_time if end is None else max(end, record.log_time)
            if topic == FRAMES_TOPIC:
                summary.frames += 1
                if not _valid(record.data):
                    summary.invalid_frames += 1
        elif isinstance(record, Channel):
            summary.channels.setdefault(record.topic, 0)
        elif isinstance(record, Attachment):
            summary.attachments.append(record.name)
        elif isinstance(record, Metadata) and record.name != COUNTS_METADATA:
            summary.metadata.append((record.name, dict(record.metadata)))
    summary.start = None if start is None else start / 1e9
    summary.end = None if end is None else end / 1e9
    summary.complete = scan.complete
    summary.origin = scan.origin_ns / 1e9 if scan.origin_ns else None
    return summary


def _indexed_summary(path: Path) -> LogSummary | None:
    """The summary of a complete bench log from its summary section (statistics, channels, attachment and metadata
    indexes) and its COUNTS_METADATA; None when it has no such section or record (then every record is read)."""
    _Scan(path)   # the clear errors of a missing or foreign file
    try:
        with path.open("rb") as file:
            reader = make_reader(file)
            summary = reader.get_summary()
            if summary is None or summary.statistics is None:
                return None
            metadata = [(m.name, dict(m.metadata)) for m in reader.iter_metadata()]
    except (McapError, OSError, ValueError, struct.error):   # a damaged summary: the records will say more
        return None
    counts = next((data for name, data in metadata if name == COUNTS_METADATA), None)
    if counts is None:
        return None
    stats = summary.statistics
    out = LogSummary(path=path, complete=True)
    out.channels = {channel.topic: stats.channel_message_counts.get(cid, 0) for cid, channel in
                    sorted(summary.channels.items())}
    if stats.message_count:
        out.start, out.end = stats.message_start_time / 1e9, stats.message_end_time / 1e9
    out.frames = out.channels.get(FRAMES_TOPIC, 0)
    out.invalid_frames = int(counts.get("invalid_frames", 0))
    out.attachments = [index.name for index in sorted(summary.attachment_indexes, key=lambda a: a.offset)]
    out.metadata = [(name, data) for name, data in metadata if name != COUNTS_METADATA]
    clock = next((data for name, data in metadata if name == CLOCK_METADATA), None)
    with contextlib.suppress(KeyError, ValueError, TypeError):
        out.origin = int(clock["origin_ns"]) / 1e9 if clock else None
    return out


def run_start(path: str | Path) -> float | None:
    """Epoch s of the run's bench time 0: the clock metadata a bench run writes before its first frame (read up to
    that frame, not the whole log); None when the log has none before it (not a bench run's log)."""
    scan = _Scan(path)
    for record in scan:
        if scan.origin_ns:
            return scan.origin_ns / 1e9
        if isinstance(record, Message):
            return None
    return None


def _valid(data: bytes) -> bool:
    """A frame's `valid` flag, without parsing the JSON the recorder writes compactly."""
    if VALID_TRUE in data:
        return True
    if VALID_FALSE in data:
        return False
    try:
        return bool(json.loads(data).get("valid", True))
    except (ValueError, AttributeError):
        return False   # a damaged frame record counts as invalid
