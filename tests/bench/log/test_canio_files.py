"""The ".mcap" python-can format with file objects, where python-can's own ReaderWriterTest does not look
(scripts/python-can-suite runs that): gzip through can.Logger/can.LogReader, python-can's size-rotating
logger, and a log read from the middle of a stream."""

from __future__ import annotations

import io
from pathlib import Path

import can

from bench.log.canio import MCAPReader, MCAPWriter
from bench.log.logread import read_frames


def messages(count: int) -> list[can.Message]:
    return [can.Message(timestamp=100.0 + i * 0.001, arbitration_id=0x100 + i, data=bytes([i % 256] * 8),
                        is_extended_id=False, channel="vcan0") for i in range(count)]


def key(msg: can.Message) -> tuple:
    return (round(msg.timestamp, 9), msg.arbitration_id, bytes(msg.data), msg.channel, msg.is_fd)


def test_gzip_through_python_cans_logger_and_reader(tmp_path: Path) -> None:
    path = tmp_path / "x.mcap.gz"
    sent = messages(50)
    with can.Logger(str(path)) as writer:
        assert isinstance(writer, MCAPWriter)
        for msg in sent:
            writer(msg)
    with can.LogReader(str(path)) as reader:
        assert isinstance(reader, MCAPReader)
        got = list(reader)
    assert [key(m) for m in got] == [key(m) for m in sent]


class McapRotatingLogger(can.SizedRotatingLogger):
    """python-can 4.6.1's SizedRotatingLogger only rotates its built-in formats (a fixed class-level set, so
    `can.logger --file-size` refuses ".mcap" before any writer exists); this subclass adds ".mcap" to show
    that the bench's writer rotates once allowed: it is a SizedMessageWriter and file objects work."""

    _supported_formats = {*can.SizedRotatingLogger._supported_formats, ".mcap"}


def test_size_rotating_logger_writes_whole_logs(tmp_path: Path) -> None:
    sent = messages(1000)
    with McapRotatingLogger(str(tmp_path / "rot.mcap"), max_bytes=10_000) as logger:
        for msg in sent:
            logger(msg)
            logger.writer.recorder.flush()     # chunks on disk now, so file_size() grows and the logger rotates
    files = sorted(tmp_path.glob("*.mcap"))
    assert len(files) > 1
    got = [m for file in files for m in MCAPReader(file)]
    assert sorted(key(m) for m in got) == [key(m) for m in sent]


class KeptBuffer(io.BytesIO):
    """A BytesIO that outlives close() (the writer closes its file, as python-can's writers do)."""

    def close(self) -> None:
        if not self.closed:
            self.kept = self.getvalue()
        super().close()


def test_reader_reads_a_stream_from_where_it_stands(tmp_path: Path) -> None:
    buffer = KeptBuffer()
    buffer.write(b"prefix")
    sent = messages(5)
    with MCAPWriter(buffer) as writer:
        for msg in sent:
            writer(msg)
    assert buffer.closed
    data = buffer.kept
    stream = io.BytesIO(data)
    stream.seek(len(b"prefix"))
    assert [key(m) for m in MCAPReader(stream)] == [key(m) for m in sent]
    assert len(list(read_frames(io.BytesIO(data[len(b"prefix"):])))) == 5
