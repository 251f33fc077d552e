"""The log process's batch path (`Recorder.frames`, issue 18) writes what `frame()` then `decoded()` write per frame:
the same records in the same chunks, for repeated and distinct frames, invalid ones, payloads that do not decode
and frames the recorder refuses; with the cache of frame texts full or not, and through mcap's own writer."""

from __future__ import annotations

import math
import random
from pathlib import Path
from typing import Any

import pytest
from mcap.records import Metadata
from mcap.stream_reader import StreamReader

import bench.log.mcapfast
import bench.log.recorder
from bench.database.codec import Codebook, load_dbc
from bench.errors import BenchError
from bench.log.logread import read_decoded, read_frames
from bench.log.recorder import Recorder
from tests.repo import BENCH_DBC, CHASSIS_DBC

ORIGIN_NS = 1_764_000_000_123_456_789
Frame = tuple[float, int, Any, str, bool, str]


def frames_of(codebook: Codebook, count: int, seed: int) -> list[Frame]:
    """A bus-like sequence: a few payloads per message, often repeated (as on the bench's bus), some frames
    invalid with a reason, some sent, a few unknown ids, short payloads (no decode) and a bytearray."""
    rng = random.Random(seed)
    codecs = sorted(codebook.by_id.values(), key=lambda codec: codec.message.frame_id)
    pools = {codec.message.frame_id: [rng.randbytes(codec.message.length) for _ in range(3)] for codec in codecs}
    pools[0x7A1] = [rng.randbytes(8)]   # an id in no database: a frame record only
    ids = list(pools)
    out: list[Frame] = []
    t = 0.0
    for i in range(count):
        t += rng.choice((0.0, 0.0005, 0.001))
        frame_id = rng.choice(ids)
        data: Any = rng.choice(pools[frame_id]) if rng.random() < 0.9 else rng.randbytes(len(pools[frame_id][0]))
        valid, error = (False, rng.choice(("checksum", "counter jump"))) if rng.random() < 0.05 else (True, "")
        if rng.random() < 0.02:
            data = data[:1]   # too short to decode: the frame is logged, its decoded record refused
        if i % 97 == 0:
            data = bytearray(data)
        out.append((t, frame_id, data, rng.choice(("rx", "rx", "tx")), valid, error))
    return out


def per_frame(path: Path, frames: list[Frame], codebook: Codebook, batch: int, chunk_size: int = 4096) -> int:
    """What bench.log.logproc wrote before the batch path: frame() and decoded() per frame; the refusals."""
    recorder = Recorder(path, [load_dbc(CHASSIS_DBC), load_dbc(BENCH_DBC)], flush_interval=math.inf,
                        chunk_size=chunk_size)
    recorder.set_origin(ORIGIN_NS, "virtual")
    refused = 0
    for start in range(0, len(frames), batch):
        for t, frame_id, data, direction, valid, error in frames[start:start + batch]:
            try:
                recorder.frame(t, frame_id, data, channel="bench", direction=direction, valid=valid, error=error)
                codec = codebook.by_id.get(frame_id) if valid else None
                if codec is not None:
                    recorder.decoded(t, codec.name, codec.decode(data))
            except (BenchError, ValueError, TypeError):
                refused += 1
        recorder.step(frames[start][0], 2, "case", f"batch {start}")
        recorder.flush()
    recorder.close()
    return refused


def batched(path: Path, frames: list[Frame], codebook: Codebook, batch: int, chunk_size: int = 4096) -> list[str]:
    recorder = Recorder(path, [load_dbc(CHASSIS_DBC), load_dbc(BENCH_DBC)], flush_interval=math.inf,
                        chunk_size=chunk_size)
    recorder.set_origin(ORIGIN_NS, "virtual")
    problems: list[str] = []
    for start in range(0, len(frames), batch):
        problems += recorder.frames(frames[start:start + batch], channel="bench", codecs=codebook.by_id)
        recorder.step(frames[start][0], 2, "case", f"batch {start}")
        recorder.flush()
    recorder.close()
    return problems


def records(path: Path) -> list[Any]:
    """Every record of the file, chunks as they are, without the metadata that holds its creation time."""
    with path.open("rb") as file:
        out = list(StreamReader(file, skip_magic=False, emit_chunks=True).records)
    return [r for r in out if not (isinstance(r, Metadata) and r.name == "bench")]


@pytest.mark.parametrize("cache", [bench.log.recorder._TEXT_CACHE, 7])
@pytest.mark.parametrize("fast", [True, False], ids=["packed", "mcap-add_message"])
def test_a_batch_writes_what_frame_and_decoded_write(
    tmp_path: Path, codebook: Codebook, monkeypatch: pytest.MonkeyPatch, cache: int, fast: bool,
) -> None:
    monkeypatch.setattr(bench.log.recorder, "_TEXT_CACHE", cache)
    if not fast:
        monkeypatch.setattr(bench.log.mcapfast, "supported", lambda: False)   # mcap's public writer
    frames = frames_of(codebook, 3000, seed=cache)
    reference, batch = tmp_path / "per_frame.mcap", tmp_path / "batch.mcap"
    refused = per_frame(reference, frames, codebook, batch=700)
    problems = batched(batch, frames, codebook, batch=700)

    expected, got = records(reference), records(batch)
    assert sum(type(r).__name__ == "Chunk" for r in got) > 10   # the chunk boundaries are compared too
    assert got == expected
    assert refused > 0 and len(problems) == refused
    assert all("bytes" in problem for problem in problems)   # each a short payload that did not decode
    assert len(list(read_frames(batch))) == len(frames)


def test_a_refused_frame_writes_nothing_and_says_why(tmp_path: Path, codebook: Codebook) -> None:
    codec = next(iter(codebook.by_id.values()))
    good = (0.001, codec.message.frame_id, bytes(codec.message.length), "rx", True, "")
    frames: list[Frame] = [good, (0.002, codec.message.frame_id, b"\0" * 8, "up", True, ""),
                           (-1.0, codec.message.frame_id, b"\0" * 8, "rx", True, ""),
                           (0.003, 0x800, b"", "rx", True, ""), good]   # 11-bit beyond 0x7FF (bench.canid)
    path = tmp_path / "refused.mcap"
    recorder = Recorder(path, [load_dbc(CHASSIS_DBC), load_dbc(BENCH_DBC)])
    problems = recorder.frames(frames, channel="bench", codecs=codebook.by_id)
    recorder.close()
    assert len(problems) == 3
    assert "direction" in problems[0] and "time -1.0" in problems[1] and "above 0x7FF" in problems[2]
    assert all(problem.startswith(f"run log {path}: bad frame ") for problem in problems)   # frame()'s text
    assert [f.t for f in read_frames(path)] == [0.001, 0.001]
    assert [name for _, name, _ in read_decoded(path)] == [codec.name, codec.name]


def test_batches_inside_one_chunk_write_what_frame_and_decoded_write(tmp_path: Path, codebook: Codebook) -> None:
    """Batches that end no chunk (the log process's usual case: chunks of 1 MiB, batches of 2000 frames) take
    `_write_many`'s path without a split; the chunks then end at the flushes only."""
    frames = [frame for frame in frames_of(codebook, 3000, seed=11) if type(frame[2]) is bytes]
    reference, batch = tmp_path / "per_frame.mcap", tmp_path / "batch.mcap"
    refused = per_frame(reference, frames, codebook, batch=500, chunk_size=1 << 20)
    problems = batched(batch, frames, codebook, batch=500, chunk_size=1 << 20)
    expected, got = records(reference), records(batch)
    assert sum(type(r).__name__ == "Chunk" for r in got) == -(-len(frames) // 500)   # one per batch (its flush)
    assert got == expected
    assert len(problems) == refused > 0
