"""The bench's MCAP run log as a python-can log format (suffix ".mcap").

Registered under python-can's entry points `can.io.message_writer` and `can.io.message_reader`, so
python-can's own tools read and write the bench's format: `python -m can.logger -f x.mcap` records a
bus into a log that `bench log info`, `bench log export` and `bench replay` read, `python -m can.player
x.mcap` and `can.LogReader("x.mcap")` play a bench run's log. Writing goes through `bench.log.recorder.Recorder`
and reading through `bench.log.logread.read_frames` (which tolerates a log cut by a kill), so the format is
exactly the one `bench run` writes.

Both take a file name or a binary file object, as python-can's own formats do (so `can.Logger("x.mcap.gz")`,
python-can's size-rotating logger and `can.logger --file-size` work), and keep what a `can.Message` says:
CAN FD (also at 8 bytes or fewer), BRS, ESI, a remote frame's DLC, and the channel as given (None, a
number or a name). docs/python-can-conformance.md lists what python-can's own tests check of them.

Without a DBC the log has the raw-frame channel only. With `dbc` (a path, several separated by commas;
on the logger's command line `--dbc=FILE.dbc`) every frame also goes through the bench's monitor:
it is checked (length, the E2E protection each message declares, ranges) and its decoded signals are
written to the decoded channels, as in a bench run. `config` (`--config=bench.toml`) applies that project's
[e2e] table over the databases' own protection, as `bench run` does; `e2e` gives such a table directly.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterator, Mapping
from io import BufferedIOBase
from pathlib import Path
from typing import Any, BinaryIO, TypedDict

import can
from can.io.generic import BinaryIOMessageReader, BinaryIOMessageWriter

from bench import canid
from bench.checks.monitor import CheckedFrame, Monitor
from bench.database.codec import load_codebook
from bench.errors import LogError
from bench.log.logread import LoggedFrame, read_frames
from bench.log.recorder import Recorder

NO_CHANNEL = ""       # the channel label of frames whose bus gives none (read back as None)


def frame_to_message(frame: LoggedFrame) -> can.Message:
    """A logged frame as a python-can message: log time, direction (is_rx), flags (remote, error, CAN FD, BRS,
    ESI) and channel kept. The one conversion of the bench: the .mcap reader, `bench log export` and
    `bench replay` (through the reader) all give frames this way."""
    channel: Any = frame.channel_number if frame.channel_number is not None else (frame.channel or None)
    return can.Message(   # a remote frame's record holds as many (zero) bytes as it requests: its DLC, no data
        timestamp=frame.t, arbitration_id=frame.arbitration_id, data=b"" if frame.is_remote else frame.data,
        dlc=len(frame.data),
        is_extended_id=frame.is_extended, is_remote_frame=frame.is_remote, is_error_frame=frame.is_error,
        is_fd=frame.is_fd, bitrate_switch=frame.bitrate_switch, error_state_indicator=frame.error_state_indicator,
        is_rx=frame.direction == "rx", channel=channel, check=False,
    )


def _channel(value: Any) -> tuple[str, int | None]:
    """A message's channel as the log's label and, for a numbered channel, its number."""
    if value is None:
        return NO_CHANNEL, None
    if isinstance(value, int) and not isinstance(value, bool):
        return str(value), value
    return str(value), None


def _paths(value: Any) -> list[Path]:
    if value is None or value == "":
        return []
    items = value.split(",") if isinstance(value, str) else list(value)
    return [Path(str(item).strip()) for item in items if str(item).strip()]


class _FrameKeywords(TypedDict):
    """The recorder's keywords for one received frame (Recorder.frame), besides time, id, data and verdict."""

    channel: str
    is_extended: bool
    is_error: bool
    is_remote: bool
    is_fd: bool
    bitrate_switch: bool
    error_state_indicator: bool
    channel_number: int | None
    dlc: int | None


class MCAPWriter(BinaryIOMessageWriter):
    """Writes received messages into a bench MCAP log (python-can writer for ".mcap").

    `file` is a path or a binary file object (which stop() closes, as python-can's writers do)."""

    def __init__(self, file: str | os.PathLike[str] | BinaryIO | BufferedIOBase, *, dbc: Any = None,
                 channel: Any = None, append: bool = False, flush_interval: float = 0.5,
                 config: str | os.PathLike[str] | None = None, e2e: Mapping[str, Mapping[str, Any]] | None = None,
                 **kwargs: Any) -> None:
        if append:
            raise ValueError(f"{file}: an MCAP log cannot be appended to; write a new file")
        dbc_paths = _paths(dbc)
        overrides = dict(e2e or {})
        if config:
            from bench.config import load_config

            overrides = {**load_config(Path(config)).e2e, **overrides}
        codebook = load_codebook(dbc_paths, overrides) if dbc_paths else None   # DatabaseError names a bad file
        databases = [db for _, db in codebook.databases] if codebook else []
        super().__init__(file, mode="wb")
        try:
            self.recorder = Recorder(self.file, databases, attachments=dbc_paths, flush_interval=flush_interval)
        except BaseException:
            self.file.close()
            raise
        self.default_channel = channel           # the channel of messages that carry none
        self.monitor = Monitor(codebook, sink=self._sink) if codebook else None
        self._last_t = 0.0
        self._extra: _FrameKeywords | None = None   # the recorder's keywords for the frame in the monitor's hands

    def on_message_received(self, msg: can.Message) -> None:
        t = msg.timestamp
        if not (isinstance(t, (int, float)) and math.isfinite(t) and t >= 0.0):
            t = self._last_t          # a bus without timestamps: keep the order, never a bad time
        self._last_t = t
        channel, number = _channel(self.default_channel if msg.channel is None else msg.channel)
        direction = "rx" if msg.is_rx else "tx"
        data = bytes(msg.data)
        extra = _FrameKeywords(channel=channel, is_extended=msg.is_extended_id, is_error=msg.is_error_frame,
                               is_remote=msg.is_remote_frame, is_fd=msg.is_fd, bitrate_switch=msg.bitrate_switch,
                               error_state_indicator=msg.error_state_indicator, channel_number=number,
                               dlc=msg.dlc if msg.is_remote_frame else None)
        if self.monitor is None or msg.is_remote_frame:
            self.recorder.frame(t, msg.arbitration_id, data, direction=direction, **extra)
            return
        self._extra = extra
        self.monitor.on_frame(t, canid.of_message(msg), data, direction)

    def _sink(self, frame: CheckedFrame) -> None:
        if self._extra is None:   # the monitor calls back only from on_frame, which sets the keywords first
            raise RuntimeError("MCAPWriter: a frame from the monitor before any was received")
        self.recorder.frame(frame.t, canid.arbitration_id(frame.frame_id), frame.data, direction=frame.direction,
                            valid=frame.valid,
                            error=frame.reason, **self._extra)
        if frame.values is not None and frame.codec is not None:
            self.recorder.decoded(frame.t, frame.codec.name, frame.values)

    def stop(self) -> None:
        """Write the log's summary and footer and close the file (idempotent)."""
        self.recorder.close()
        self.file.close()

    def file_size(self) -> int:
        """Bytes on disk so far (python-can's size-rotating logger asks); the open chunk is not counted."""
        return self.file.tell()


def log_reader(path: str | os.PathLike[str]) -> MCAPReader:
    """A run log's reader: python-can's one registered for ".mcap", so what `bench replay` reads is what
    `can.LogReader` and `python -m can.player` read; a file named otherwise is read as a run log all the same
    (MCAPReader). A missing or foreign file is a LogError here."""
    if Path(path).suffix.lower() == ".mcap":
        reader = can.LogReader(path)
        if not isinstance(reader, MCAPReader):   # another package registered ".mcap": not a bench log reader
            reader.stop()
            raise LogError(f"{path}: python-can reads .mcap with {type(reader).__name__}, not the bench's "
                           "MCAPReader (bench.log.canio); is the bench installed (pip install -e .)?")
        return reader
    return MCAPReader(path)


class MCAPReader(BinaryIOMessageReader):
    """Reads the raw frames of a bench MCAP log (python-can reader for ".mcap"), also of a killed run.

    `file` is a path or a binary file object, read from where it stands; stop() closes it."""

    def __init__(self, file: str | os.PathLike[str] | BinaryIO, **kwargs: Any) -> None:
        stream: BinaryIO
        if isinstance(file, (str, os.PathLike)):
            try:
                stream = open(file, "rb")  # noqa: SIM115 - closed by stop()
            except OSError as exc:
                raise LogError(f"{file}: cannot read run log: {exc.strerror}") from None
        else:
            stream = file
        self.file = stream
        try:
            self._frames = read_frames(stream)
            # Read the head now, so that a foreign file fails here (LogError) and not mid-iteration.
            self._first = next(self._frames, None)
        except BaseException:
            self.file.close()
            raise

    def __iter__(self) -> Iterator[can.Message]:
        if self._first is None:
            return
        first, self._first = self._first, None
        yield frame_to_message(first)
        for frame in self._frames:
            yield frame_to_message(frame)

    def stop(self) -> None:
        self._frames.close()
        self.file.close()
