"""The log's fast path: MCAP Message records and message indexes packed in one go, into mcap's writer; and
read back without a call per field.

mcap's pure-Python writer builds a Message object per message and writes its five fields one by one through a
BytesIO; the log writes two messages per frame, and that was the largest part of its cost (docs/performance.md,
issue 18). This module writes the same bytes itself, into the writer's open chunk, and keeps the writer's chunk
index and statistics as `Writer.add_message` does, through the writer's private state: the only place of the
bench that touches mcap's internals (tests/integration/test_layering.py checks that), and only for the mcap
releases it was checked against (SUPPORTED, the same as pyproject.toml's pin). tests/bench/log/test_recorder.py and
test_recorder_batch.py compare its files with mcap's public writer's, record by record; any other release, or
a writer whose state is not what these releases have, gets None here and the recorder writes through
`Writer.add_message`.

Reading (`read_records`) needs no internals: mcap's `StreamReader` reads every field of every record with a call
of its own, message indexes included, which made reading a log slower than writing it; `read_records` splits
the stream and its chunks with one unpack per record and leaves the rarer records to mcap's own `read`.
tests/bench/log/test_mcapfast.py compares its records with `StreamReader`'s, on whole and cut logs.
"""

from __future__ import annotations

import bisect
import io
import itertools
import operator
import struct
from collections import deque
from collections.abc import Callable, Iterator
from functools import cache
from importlib.metadata import PackageNotFoundError, version
from typing import Any

from mcap._chunk_builder import ChunkBuilder
from mcap.data_stream import ReadDataStream
from mcap.exceptions import InvalidMagic
from mcap.opcode import Opcode
from mcap.records import (
    Attachment,
    AttachmentIndex,
    Channel,
    Chunk,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    McapRecord,
    Message,
    MessageIndex,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)
from mcap.stream_reader import get_chunk_data_stream
from mcap.writer import Writer

from bench.log.format import MAGIC

SUPPORTED = ("1.6.",)   # mcap releases (version prefixes) whose writer state the fast path knows
RECORD_OVERHEAD = 31  # bytes of an MCAP Message record besides its data


@cache
def supported() -> bool:
    """Whether the installed mcap is a release the fast path was checked against."""
    try:
        return version("mcap").startswith(SUPPORTED)
    except PackageNotFoundError:   # pragma: no cover - mcap imported but not installed as a distribution
        return False


def records_size(payloads: list[bytes]) -> int:
    """Bytes of the MCAP Message records of these payloads."""
    return sum(map(len, payloads)) + RECORD_OVERHEAD * len(payloads)


def record_ends(payloads: list[bytes]) -> list[int]:
    """Where each payload's record ends, counted from the first one's start."""
    return list(itertools.accumulate(map(operator.add, map(len, payloads), itertools.repeat(RECORD_OVERHEAD))))


_MESSAGE_HEAD = struct.Struct("<BQHIQQ")   # opcode, record length, channel id, sequence, log time, publish time
_MESSAGE_FIELDS = 22    # bytes of a Message record's fields before its data
_MESSAGE_OPCODE = int(Opcode.MESSAGE)   # mcap's, as a plain int for the per-message paths


class _MessageIndex(MessageIndex):
    """mcap's MessageIndex written in one pack (mcap's writes each entry's two fields one by one)."""

    def write(self, stream: Any) -> None:
        size = 16 * len(self.records)
        stream.write(struct.pack(f"<BQHI{size // 8}Q", int(Opcode.MESSAGE_INDEX), 6 + size, self.channel_id, size,
                                 *itertools.chain.from_iterable(self.records)))


def fast_adder(writer: Writer) -> Callable[[int, int, bytes], None] | None:
    """`writer.add_message(channel_id, ns, payload, ns)` in one pack and one write per message, with the same
    bytes, chunk index and statistics. None (the caller then uses `add_message`) for an mcap release not in
    SUPPORTED or a writer whose private state is not what those releases have."""
    if not supported():
        return None
    builder = getattr(writer, "_Writer__chunk_builder", None)
    stats = getattr(writer, "_Writer__statistics", None)
    limit = getattr(writer, "_Writer__chunk_size", None)
    if type(builder) is not ChunkBuilder or type(stats) is not Statistics or type(limit) is not int:
        return None
    if not all(hasattr(builder, name) for name in ("record_writer", "message_indices", "num_messages",
                                                       "message_start_time", "message_end_time")):
        return None
    counts = stats.channel_message_counts
    indices = builder.message_indices
    pack = _MESSAGE_HEAD.pack

    def add(channel_id: int, ns: int, payload: bytes) -> None:
        records = builder.record_writer
        offset = records.count
        records.write(pack(_MESSAGE_OPCODE, _MESSAGE_FIELDS + len(payload), channel_id, 0, ns, ns) + payload)
        if stats.message_count == 0 or ns < stats.message_start_time:
            stats.message_start_time = ns
        if ns > stats.message_end_time:
            stats.message_end_time = ns
        counts[channel_id] += 1
        stats.message_count += 1
        if builder.num_messages == 0 or ns < builder.message_start_time:
            builder.message_start_time = ns
        if ns > builder.message_end_time:
            builder.message_end_time = ns
        index = indices.get(channel_id)
        if index is None:
            index = indices[channel_id] = _MessageIndex(channel_id=channel_id, records=[])
        index.records.append((ns, offset))
        builder.num_messages += 1
        if records.count > limit:   # as add_message does (the recorder's own limit usually comes first)
            writer.flush()  # type: ignore[no-untyped-call]   # mcap's Writer.flush carries no annotations

    return add


def fast_bulk_adder(writer: Writer) -> Callable[[list[int], list[int], list[bytes]], None] | None:
    """`fast_adder`'s work for many messages at once (one write, C-level packing), with the same bytes, chunk
    index and statistics; the caller keeps the messages of one call inside one chunk. None: as `fast_adder`."""
    if fast_adder(writer) is None:
        return None
    builder: ChunkBuilder = getattr(writer, "_Writer__chunk_builder")   # noqa: B009 - private, checked above
    stats: Statistics = getattr(writer, "_Writer__statistics")          # noqa: B009
    limit: int = getattr(writer, "_Writer__chunk_size")                 # noqa: B009
    counts = stats.channel_message_counts
    indices = builder.message_indices
    pack = _MESSAGE_HEAD.pack
    repeat = itertools.repeat
    add = operator.add

    def add_many(channels: list[int], nss: list[int], payloads: list[bytes]) -> None:
        # mcap's writer closes its chunk after the record that takes it past its own limit (only a chunk that
        # holds many schemas, with a small chunk_size, gets there first): split the messages where it would
        if builder.record_writer.count + records_size(payloads) <= limit:
            add_within(channels, nss, payloads)   # the usual case (the recorder's own limit comes first)
            return
        start = 0
        ends = record_ends(payloads)
        while True:
            stop = bisect.bisect_right(ends, limit - builder.record_writer.count + (ends[start - 1] if start else 0),
                                       start) + 1
            if stop >= len(payloads):
                break
            add_within(channels[start:stop], nss[start:stop], payloads[start:stop])
            start = stop
        add_within(channels[start:], nss[start:], payloads[start:])

    def add_within(channels: list[int], nss: list[int], payloads: list[bytes]) -> None:
        records = builder.record_writer
        sizes = list(map(len, payloads))
        heads = map(pack, repeat(_MESSAGE_OPCODE), map(add, sizes, repeat(_MESSAGE_FIELDS)), channels, repeat(0), nss,
                    nss)
        offsets = itertools.accumulate(map(add, sizes, repeat(RECORD_OVERHEAD)), initial=records.count)
        # each record as one piece (head + payload): joining half as many pieces costs a third (bytes.join
        # takes a buffer of each), and operator functions, not bound int.__add__, are called without a tuple
        records.write(b"".join(map(add, heads, payloads)))
        first, last = min(nss), max(nss)
        if stats.message_count == 0 or first < stats.message_start_time:
            stats.message_start_time = first
        if last > stats.message_end_time:
            stats.message_end_time = last
        if builder.num_messages == 0 or first < builder.message_start_time:
            builder.message_start_time = first
        if last > builder.message_end_time:
            builder.message_end_time = last
        # each message's (time, offset) onto its channel's index, in order, by map over list.append
        entries: dict[int, list[tuple[int, int]]] = {}
        for channel_id in dict.fromkeys(channels):   # in order of first appearance, as mcap's writes them
            index = indices.get(channel_id)
            if index is None:
                index = indices[channel_id] = _MessageIndex(channel_id=channel_id, records=[])
            entries[channel_id] = index.records
            counts[channel_id] -= len(index.records)   # + the index's length below: the channel's new messages
        deque(map(list.append, map(entries.__getitem__, channels), zip(nss, offsets)), 0)
        for channel_id, records_of_channel in entries.items():
            counts[channel_id] += len(records_of_channel)
        stats.message_count += len(payloads)
        builder.num_messages += len(payloads)
        if records.count > limit:
            writer.flush()  # type: ignore[no-untyped-call]   # mcap's Writer.flush carries no annotations

    return add_many


_RECORD_HEAD = struct.Struct("<BQ")          # opcode, record length
_MESSAGE_FIELDS_HEAD = struct.Struct("<HIQQ")   # channel id, sequence, log time, publish time
_READERS: dict[int, Callable[[ReadDataStream], McapRecord]] = {
    Opcode.ATTACHMENT: Attachment.read, Opcode.ATTACHMENT_INDEX: AttachmentIndex.read, Opcode.CHANNEL: Channel.read,
    Opcode.CHUNK_INDEX: ChunkIndex.read, Opcode.DATA_END: DataEnd.read, Opcode.FOOTER: Footer.read,
    Opcode.HEADER: Header.read, Opcode.METADATA: Metadata.read, Opcode.METADATA_INDEX: MetadataIndex.read,
    Opcode.SCHEMA: Schema.read, Opcode.STATISTICS: Statistics.read, Opcode.SUMMARY_OFFSET: SummaryOffset.read,
}


def read_records(read: Callable[[int], bytes]) -> Iterator[McapRecord]:
    """The records of an MCAP stream as mcap's `StreamReader(...).records` gives them (a chunk's records in place
    of the chunk, up to the footer and its closing magic), less the message indexes, which nothing reads.

    `read(n)` returns n bytes or raises mcap's `EndOfFile`; a bad magic raises `InvalidMagic`, as mcap's does."""
    _read_magic(read)
    while True:
        opcode, length = _RECORD_HEAD.unpack(read(_RECORD_HEAD.size))
        body = read(length)
        if opcode == _MESSAGE_OPCODE:
            yield _message(body, 0, length)
        elif opcode == Opcode.CHUNK:
            yield from _chunk_records(Chunk.read(_stream(body)))
        elif opcode in _READERS:
            record = _READERS[opcode](_stream(body))
            yield record
            if isinstance(record, Footer):
                _read_magic(read)
                return


def _chunk_records(chunk: Chunk) -> Iterator[McapRecord]:
    """A chunk's records, as mcap's `breakup_chunk` gives them."""
    stream, size = get_chunk_data_stream(chunk)
    data = stream.read(size)
    at = 0
    while at < size:
        opcode, length = _RECORD_HEAD.unpack_from(data, at)
        at += _RECORD_HEAD.size
        end = at + length
        if opcode == _MESSAGE_OPCODE:
            yield _message(data, at, end)
        elif opcode == Opcode.CHANNEL:
            yield Channel.read(_stream(data[at:end]))
        elif opcode == Opcode.SCHEMA:
            yield Schema.read(_stream(data[at:end]))
        at = end


def _message(data: bytes, at: int, end: int) -> Message:
    channel_id, sequence, log_time, publish_time = _MESSAGE_FIELDS_HEAD.unpack_from(data, at)
    return Message(channel_id=channel_id, log_time=log_time, data=data[at + _MESSAGE_FIELDS:end],
                   publish_time=publish_time, sequence=sequence)


def _stream(body: bytes) -> ReadDataStream:
    return ReadDataStream(io.BytesIO(body))


def _read_magic(read: Callable[[int], bytes]) -> None:
    magic = read(len(MAGIC))
    if magic != MAGIC:
        raise InvalidMagic(tuple(magic))
