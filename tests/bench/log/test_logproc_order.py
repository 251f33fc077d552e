"""The log process gets each batch's frames apart from its other items (steps, metadata, the time origin; issue 18):
the file must still hold every record in the order the run handed it over, a step between the frames it came
between, and the same records as the Recorder called directly in that order."""

from __future__ import annotations

import math
from pathlib import Path

from mcap.reader import make_reader
from mcap.records import Metadata
from mcap.stream_reader import StreamReader

import bench.log.logproc
from bench.database.codec import load_codebook, load_dbc
from bench.log.logproc import LogProcess
from bench.log.recorder import Recorder
from tests.repo import BENCH_DBC, CHASSIS_DBC

ORIGIN_NS = 1_764_000_000_000_000_000


def items() -> list[tuple[str, tuple[object, ...]]]:
    """A run's calls: the origin first, frames of two ids, a step and a fault's metadata between frames, a step
    right after a hand-over's last frame, an invalid frame with its reason."""
    codebook = load_codebook([CHASSIS_DBC, BENCH_DBC])
    codecs = sorted(codebook.by_id.values(), key=lambda codec: codec.message.frame_id)[:2]
    calls: list[tuple[str, tuple[object, ...]]] = [("origin", (ORIGIN_NS, False))]
    for i in range(300):
        codec = codecs[i % 2]
        data = bytes([i % 256]) + bytes(codec.message.length - 1)
        valid, error = (False, "checksum") if i % 50 == 7 else (True, "")
        calls.append(("frame", (i * 0.001, codec.message.frame_id, data, "rx", valid, error)))
        if i % 97 == 3:
            calls.append(("step", (i * 0.001, 2, "case", f"after frame {i}")))
        if i == 150:
            calls.append(("metadata", ("bench.fault", {"at": str(i)})))
    return calls


def file_order(path: Path) -> list[tuple[str, int, bytes]]:
    """Every message of the file in file order: topic, log time, data."""
    with path.open("rb") as file:
        reader = make_reader(file)
        return [(channel.topic, message.log_time, message.data)
                for _, channel, message in reader.iter_messages(log_time_order=False)]


def test_the_log_process_keeps_the_order_of_steps_and_frames(tmp_path: Path) -> None:
    calls = items()
    path = tmp_path / "run.mcap"
    log = LogProcess(path, [CHASSIS_DBC, BENCH_DBC], "bench")
    for number, (kind, args) in enumerate(calls):
        getattr(log, kind)(*args)
        if number in (40, 41, 200):   # hand-overs that end with a frame, with a step, and one more
            log._hand_over()
    log.close()

    reference = tmp_path / "direct.mcap"
    codebook = load_codebook([CHASSIS_DBC, BENCH_DBC])
    recorder = Recorder(reference, [load_dbc(CHASSIS_DBC), load_dbc(BENCH_DBC)], flush_interval=math.inf)
    for kind, args in calls:
        if kind == "origin":
            recorder.set_origin(int(args[0]), "virtual")   # type: ignore[call-overload]
        elif kind == "frame":
            recorder.frames([args], channel="bench", codecs=codebook.by_id)
        elif kind == "step":
            recorder.step(*args)   # type: ignore[arg-type]
        else:
            recorder.metadata(*args)   # type: ignore[arg-type]
    recorder.close()

    got, expected = file_order(path), file_order(reference)
    assert got == expected
    steps = [k for k, (topic, _, _) in enumerate(got) if topic == "/bench/steps"]
    assert len(steps) == 4
    # frame i's records (frame + decoded when valid) come before the step logged after it
    frames_before = [sum(1 for topic, _, _ in got[:k] if topic == "/can/frames") for k in steps]
    assert frames_before == [4, 101, 198, 295]
    with path.open("rb") as file:
        names = [r.name for r in StreamReader(file).records if isinstance(r, Metadata)]
    assert "bench.fault" in names and "bench.clock" in names
    assert bench.log.logproc.BATCH_FRAMES > 300   # the hand-overs above are the test's, not the size limit's
