"""The run log's writing cost per frame, and the choices behind it (issue 18): writers, encodings, compression.

The frames of one short run (EV4WIS, PIVOT, S s of bench time, through bench.run.BenchRun) are read back from
its MCAP and written again, in this process, the way the log process writes them (bench/log/logproc.py: the raw
frame's record, a decode, the decoded record), CPU time per frame, median of 3:
  - the recorder as it is (bench/log/recorder.py with bench/log/mcapfast.py: one pack per message record and
    per message index);
  - the same with mcap's own `Writer.add_message` (the recorder's fallback; what it did before);
  - `Recorder.frames` per batch of 2000, what the log process does since issue 18 (the same records);
and the parts, on the same frames: decode; the decoded values as JSON by the json module, by the recorder's
%-template, and by orjson when installed (not a dependency: for comparison only); the frame's JSON; chunk
compression of the records, zstd at levels 3 (mcap's default, the recorder's), 1 and -1, lz4 and none, with the
bytes per frame each gives. Baseline: the recorder through mcap's add_message, measured in the same run.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import common


def _cpu_per_frame(work: Callable[[], Any], frames: int, repeat: int = 3) -> tuple[float, Any]:
    """Median CPU µs per frame of `work()` over `repeat` runs, and the last run's result."""
    times, result = [], None
    for _ in range(repeat):
        start = time.process_time()
        result = work()
        times.append(time.process_time() - start)
    return statistics.median(times) / frames * 1e6, result


def record_frames(seconds: float, out: Path) -> Path:
    """A short run's log (B2 of bench_virtual_time: the run's log process writes it)."""
    import bench_virtual_time

    bench_virtual_time.run_with_log(seconds, out)
    return out / "run.mcap"


def measure(result: common.Result, args: argparse.Namespace) -> None:
    import zstandard

    import bench.log.format
    import bench.log.mcapfast
    import bench.log.recorder
    from bench.config import load_config
    from bench.database.codec import load_codebook, load_dbc
    from bench.log.logread import read_frames

    seconds = 2.0 if args.quick else 10.0
    source = record_frames(seconds, args.work / "source")
    frames = [(f.t, f.arbitration_id, f.data, f.direction, f.valid, f.error) for f in read_frames(source)]
    n = len(frames)
    databases = load_config().databases
    codebook = load_codebook(databases)
    by_id = codebook.by_id
    loaded = [load_dbc(p) for p in databases]

    def write_log() -> int:
        """What bench/log/logproc.py's loop does per frame."""
        path = args.work / "written.mcap"
        recorder = bench.log.recorder.Recorder(path, loaded, attachments=databases)
        for t, frame_id, data, direction, valid, error in frames:
            recorder.frame(t, frame_id, data, channel="bench", direction=direction, valid=valid, error=error)
            codec = by_id.get(frame_id) if valid else None
            if codec is not None:
                recorder.decoded(t, codec.name, codec.decode(data))
        recorder.close()
        return path.stat().st_size

    fast, size = _cpu_per_frame(write_log, n)
    supported = bench.log.mcapfast.supported
    bench.log.mcapfast.supported = lambda: False   # the recorder on mcap's public Writer.add_message alone
    try:
        slow, _ = _cpu_per_frame(write_log, n)
    finally:
        bench.log.mcapfast.supported = supported
    base = "the recorder through mcap's Writer.add_message"
    result.add("log writing, the recorder per frame (frame + decode + decoded)", fast, "µs CPU per frame", slow, base,
               note=f"{n} frames of {seconds:g} s of bench time; {size / n:.0f} bytes per frame in the file")

    def write_batched() -> int:
        """What bench/log/logproc.py does since issue 18: Recorder.frames per batch (the same records)."""
        path = args.work / "batched.mcap"
        recorder = bench.log.recorder.Recorder(path, loaded, attachments=databases)
        for start in range(0, n, 2000):
            recorder.frames(frames[start:start + 2000], channel="bench", codecs=by_id)
        recorder.close()
        return path.stat().st_size

    batched, batched_size = _cpu_per_frame(write_batched, n)
    distinct = len({(frame_id, data) for _, frame_id, data, _, _, _ in frames})
    result.add("log writing, Recorder.frames in batches of 2000 (the log process)", batched, "µs CPU per frame", fast,
               "the recorder per frame", note=f"{distinct / n:.0%} of the frames distinct; "
                                              f"{batched_size / n:.0f} bytes per frame in the file")

    codecs = [by_id[frame_id] for _, frame_id, _, _, valid, _ in frames if valid and frame_id in by_id]
    payloads = [data for _, frame_id, data, _, valid, _ in frames if valid and frame_id in by_id]
    decode, values = _cpu_per_frame(lambda: [c.decode(d) for c, d in zip(codecs, payloads)], n)
    result.add("decode (each frame once, as the log process decodes it)", decode,
               "µs CPU per frame")
    encoder = json.JSONEncoder(allow_nan=False, separators=(",", ":"))
    by_json, texts = _cpu_per_frame(lambda: [encoder.encode(v).encode() for v in values], n)
    entries = {c.name: bench.log.recorder._Decoded(c.message) for c in codecs}
    names = [c.name for c in codecs]
    by_template, texts2 = _cpu_per_frame(
        lambda: [(entries[m].template % tuple(v.values())).encode() for m, v in zip(names, values)], n)
    same = "the same bytes" if texts == texts2 else "DIFFERENT bytes"
    result.add("decoded values as JSON: the recorder's %-template", by_template, "µs CPU per frame", by_json,
               "the json module (compact)", note=same)
    try:
        import orjson
    except ImportError:
        pass
    else:
        by_orjson, _ = _cpu_per_frame(lambda: [orjson.dumps(v) for v in values], n)
        result.add("decoded values as JSON: orjson (not a dependency)", by_orjson, "µs CPU per frame", by_json,
                   "the json module (compact)", note="writes 1e-5 where json writes 1e-05: other text")

    records = b"".join(texts)   # the decoded records' bytes, then the frames'
    frame_texts = []
    for t, frame_id, data, direction, valid, error in frames:
        ns = int(t * 1e9 + 0.5)
        padded = data + bench.log.format.PAD[len(data)] if len(data) < 8 else data
        frame_texts.append((bench.log.format.FRAME_JSON % (
            ns // 1_000_000_000, ns % 1_000_000_000, '"bench"', frame_id, "false", "false", "false", len(padded),
            ",".join(bench.log.format.DECIMAL[b] for b in padded), '"bench"', direction,
            "true" if valid else "false", json.dumps(error), "")).encode())
    records += b"".join(frame_texts)
    chunk = records[: 1 << 20]   # one chunk of the recorder's size (CHUNK_BYTES)
    scale = len(records) / len(chunk)
    zstd3 = _compression(lambda: zstandard.ZstdCompressor(level=3).compress(chunk), n / scale)
    result.add("chunk compression zstd level 3 (mcap's default, kept)", zstd3[0], "µs CPU per frame",
               note=f"{zstd3[1] * scale / n:.1f} bytes per frame (uncompressed {len(records) / n:.0f})")
    options: list[tuple[str, Callable[[], bytes]]] = [
        ("zstd level 1", lambda: zstandard.ZstdCompressor(level=1).compress(chunk)),
        ("zstd level -1", lambda: zstandard.ZstdCompressor(level=-1).compress(chunk)),
    ]
    try:
        import lz4.frame
    except ImportError:
        pass
    else:
        options.append(("lz4 (frame)", lambda: bytes(lz4.frame.compress(chunk))))
    options.append(("none", lambda: chunk))
    for name, compress in options:
        cost, size_out = _compression(compress, n / scale)
        result.add(f"chunk compression {name}", cost, "µs CPU per frame", zstd3[0], "zstd level 3",
                   note=f"{size_out * scale / n:.1f} bytes per frame")


def _compression(compress: Callable[[], bytes], frames: float) -> tuple[float, int]:
    cost, out = _cpu_per_frame(lambda: [compress() for _ in range(5)], int(frames * 5))
    return cost, len(out[0])


if __name__ == "__main__":
    raise SystemExit(common.main("log_write", "Issue 18: the run log's writing cost per frame", measure, doc=__doc__))
