"""The bench's MCAP run log as a python-can log format (suffix ".mcap").

Registered under python-can's entry points `can.io.message_writer` and `can.io.message_reader`, so
python-can's own tools read and write the bench's format: `python -m can.logger -f x.mcap` records a
bus into a log that `bench log info`, `bench log export` and `bench replay` read, `python -m can.player
x.mcap` and `can.LogReader("x.mcap")` play a bench run's log. Writing goes through `bench.recorder.Recorder`
and reading through `bench.logread.read_frames` (which tolerates a log cut by a kill), so the format is
exactly the one `bench run` writes.

Without a DBC the log has the raw-frame channel only. With `dbc` (a path, several separated by commas;
on the logger's command line `--dbc=dbc/chassis.dbc`) every frame also goes through the bench's monitor:
it is checked (length, the contract's E2E checksum and counter, ranges) and its decoded signals are
written to the decoded channels, as in a bench run.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import can
from can.io.generic import MessageReader, MessageWriter

from bench.codec import MessageCodec, load_codebook
from bench.logread import LoggedFrame, read_frames
from bench.monitor import Monitor
from bench.recorder import Recorder

SUFFIX = ".mcap"
DEFAULT_CHANNEL = "can0"       # the channel label of frames whose bus gives none


def frame_to_message(frame: LoggedFrame) -> can.Message:
    """A logged frame as a python-can message: log time, direction (is_rx) and channel label kept."""
    return can.Message(
        timestamp=frame.t, arbitration_id=frame.arbitration_id, data=frame.data, dlc=len(frame.data),
        is_extended_id=frame.is_extended, is_remote_frame=frame.is_remote, is_error_frame=frame.is_error,
        is_fd=len(frame.data) > 8, is_rx=frame.direction == "rx", channel=frame.channel or None,
        check=False,
    )


def _paths(value: Any) -> list[Path]:
    if value is None or value == "":
        return []
    items = value.split(",") if isinstance(value, str) else list(value)
    return [Path(str(item).strip()) for item in items if str(item).strip()]


class MCAPWriter(MessageWriter):
    """Writes received messages into a bench MCAP log (python-can writer for ".mcap")."""

    def __init__(self, file: str | os.PathLike[str], *, dbc: Any = None, channel: str | None = None,
                 append: bool = False, flush_interval: float = 0.5, **kwargs: Any) -> None:
        if append:
            raise ValueError(f"{file}: an MCAP log cannot be appended to; write a new file")
        if not isinstance(file, (str, os.PathLike)):
            raise TypeError(f"MCAPWriter writes to a file name, not {type(file).__name__}")
        dbc_paths = _paths(dbc)
        codebook = load_codebook(dbc_paths) if dbc_paths else None   # DatabaseError names a bad file
        databases = [db for _, db in codebook.databases] if codebook else []
        self.recorder = Recorder(Path(file), databases, attachments=dbc_paths, flush_interval=flush_interval)
        self.default_channel = str(channel) if channel is not None else DEFAULT_CHANNEL
        self.monitor = Monitor(codebook, sink=self._sink) if codebook else None
        self._last_t = 0.0
        self._flags = (DEFAULT_CHANNEL, False, False, False)   # channel, extended, error, remote of the frame in hand

    def on_message_received(self, msg: can.Message) -> None:
        t = msg.timestamp
        if not (isinstance(t, (int, float)) and math.isfinite(t) and t >= 0.0):
            t = self._last_t          # a bus without timestamps: keep the order, never a bad time
        self._last_t = t
        channel = self.default_channel if msg.channel is None else str(msg.channel)
        direction = "rx" if msg.is_rx else "tx"
        data = bytes(msg.data)
        if self.monitor is None or msg.is_remote_frame:
            self.recorder.frame(t, msg.arbitration_id, data, channel=channel, direction=direction,
                                is_extended=msg.is_extended_id, is_error=msg.is_error_frame,
                                is_remote=msg.is_remote_frame)
            return
        self._flags = (channel, msg.is_extended_id, msg.is_error_frame, msg.is_remote_frame)
        self.monitor.on_frame(t, msg.arbitration_id, data, direction, msg.is_extended_id, msg.is_error_frame)

    def _sink(self, t: float, arbitration_id: int, data: bytes, direction: str, valid: bool, reason: str,
              codec: MessageCodec | None, values: Mapping[str, float] | None) -> None:
        channel, extended, error, remote = self._flags
        self.recorder.frame(t, arbitration_id, data, channel=channel, direction=direction, is_extended=extended,
                            is_error=error, is_remote=remote, valid=valid, error=reason)
        if values is not None and codec is not None:
            self.recorder.decoded(t, codec.name, values)

    def stop(self) -> None:
        """Write the log's summary and footer (idempotent)."""
        self.recorder.close()


class MCAPReader(MessageReader):
    """Reads the raw frames of a bench MCAP log (python-can reader for ".mcap"), also of a killed run."""

    def __init__(self, file: str | os.PathLike[str], **kwargs: Any) -> None:
        if not isinstance(file, (str, os.PathLike)):
            raise TypeError(f"MCAPReader reads a file name, not {type(file).__name__}")
        self._frames = read_frames(file)
        # Open the file now, so that a missing or foreign file fails here (LogError) and not mid-iteration.
        self._first = next(self._frames, None)

    def __iter__(self) -> Iterator[can.Message]:
        if self._first is None:
            return
        first, self._first = self._first, None
        yield frame_to_message(first)
        for frame in self._frames:
            yield frame_to_message(frame)

    def stop(self) -> None:
        self._frames.close()
