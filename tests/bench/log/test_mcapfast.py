"""`bench.log.mcapfast.read_records` against mcap's own `StreamReader`: the same records, in the same order, for a
bench log, logs of mcap's writer with each compression and with unchunked messages, and any cut of a log (the
public reader then ends with `EndOfFile` where the fast one does)."""

from __future__ import annotations

import io
from collections.abc import Callable

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from mcap.exceptions import EndOfFile, InvalidMagic, McapError
from mcap.records import McapRecord, MessageIndex
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer

from bench.log.mcapfast import read_records
from tests.bench.log.test_recorder import write_log


def read_exactly(stream: io.BytesIO) -> Callable[[int], bytes]:
    """`stream.read` raising `EndOfFile` at a short read, as bench.log.logread's file wrapper does."""
    def read(size: int) -> bytes:
        got = stream.read(size)
        if len(got) < size:
            raise EndOfFile()
        return got
    return read


def public(data: bytes) -> tuple[list[McapRecord], type[Exception] | None]:
    """mcap's records (less message indexes) and the error it stopped with, if any."""
    records: list[McapRecord] = []
    try:
        for record in StreamReader(io.BytesIO(data)).records:
            if not isinstance(record, MessageIndex):
                records.append(record)
    except McapError as exc:
        return records, type(exc)
    except Exception:   # a cut chunk reaches mcap's reader as a short chunk: a struct or decompression error
        return records, EndOfFile
    return records, None


def fast(data: bytes) -> tuple[list[McapRecord], type[Exception] | None]:
    records: list[McapRecord] = []
    try:
        for record in read_records(read_exactly(io.BytesIO(data))):
            records.append(record)
    except McapError as exc:
        return records, type(exc)
    return records, None


def mcap_writer_log(compression: CompressionType, use_chunking: bool) -> bytes:
    out = io.BytesIO()
    writer = Writer(out, compression=compression, use_chunking=use_chunking, chunk_size=700)
    writer.start(profile="x", library="test")
    schema = writer.register_schema("s", "jsonschema", b"{}")
    channels = [writer.register_channel(f"/t{i}", "json", schema, {"k": str(i)}) for i in range(3)]
    for i in range(120):
        writer.add_message(channels[i % 3], log_time=i * 1000, data=b'{"i":%d}' % i, publish_time=i * 999,
                           sequence=i)
        if i == 60:
            writer.add_attachment(log_time=5, create_time=6, name="a.txt", media_type="text/plain", data=b"hi")
            writer.add_metadata("m", {"a": "b"})
    writer.finish()
    return out.getvalue()


@pytest.fixture(scope="module")
def bench_log(tmp_path_factory: pytest.TempPathFactory) -> bytes:
    tmp = tmp_path_factory.mktemp("fast")
    path = tmp / "run.mcap"
    write_log(path, tmp, count=200, chunk_size=1500)
    return path.read_bytes()


def test_a_bench_log_reads_as_mcap_reads_it(bench_log: bytes) -> None:
    records, error = fast(bench_log)
    assert error is None
    assert (records, error) == public(bench_log)
    assert len(records) > 400     # messages of 200 frames and their decoded records, and more


@pytest.mark.parametrize("compression", [CompressionType.NONE, CompressionType.LZ4, CompressionType.ZSTD])
@pytest.mark.parametrize("use_chunking", [True, False])
def test_mcaps_own_writer_reads_back_alike(compression: CompressionType, use_chunking: bool) -> None:
    data = mcap_writer_log(compression, use_chunking)
    records, error = fast(data)
    assert error is None and len(records) > 120
    assert (records, error) == public(data)


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(fraction=st.floats(0.0, 1.0))
def test_any_cut_gives_the_same_records_as_mcaps_reader(bench_log: bytes, fraction: float) -> None:
    data = bench_log[: int(fraction * len(bench_log))]
    records, error = fast(data)
    expected, expected_error = public(data)
    assert records == expected
    assert (error is None) == (expected_error is None)


def test_a_foreign_magic_is_refused_as_mcap_refuses_it() -> None:
    data = b"NOTMCAP!" + bytes(40)
    assert fast(data) == public(data) == ([], InvalidMagic)
