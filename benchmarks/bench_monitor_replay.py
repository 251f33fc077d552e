"""The monitors' per-frame cost on B1's traffic: the frames both monitors of a B1 session (EV4WIS PIVOT) checked,
recorded once, then replayed into fresh monitors; CPU µs per `Monitor.on_frame`, best and median of 5.

    python benchmarks/bench_monitor_replay.py                     # this tree
    cd /tmp/before && PYTHONPATH=/tmp/before python benchmarks/bench_monitor_replay.py   # another tree
"""

from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import bench_virtual_time as bvt  # noqa: E402 - after this folder is on sys.path

import bench.checks.monitor as monitor_module  # noqa: E402
from bench.config import load_config  # noqa: E402
from bench.database.codec import load_codebook  # noqa: E402


def record(seconds: float) -> list[tuple[int, float, int, bytes, str]]:
    """(monitor, t, identifier, data, direction) of every frame a B1 session's monitors checked."""
    frames: list[tuple[int, float, int, bytes, str]] = []
    original = monitor_module.Monitor.on_frame

    def recording(self: monitor_module.Monitor, t: float, arbitration_id: int, data: bytes, direction: str,
                  is_extended: bool = False, is_error: bool = False) -> bool:
        frames.append((id(self), t, arbitration_id, bytes(data), direction))
        return original(self, t, arbitration_id, data, direction, is_extended, is_error)

    monitor_module.Monitor.on_frame = recording   # type: ignore[method-assign]
    try:
        bvt.session_no_log(seconds)
    finally:
        monitor_module.Monitor.on_frame = original   # type: ignore[method-assign]
    return frames


def main() -> int:
    frames = record(10.0)
    codebook = load_codebook(load_config().databases)
    owners = sorted({f[0] for f in frames})
    per_frame = []
    for _ in range(5):
        monitors = {k: monitor_module.Monitor(codebook, keep_history=k == owners[0]) for k in owners}
        cpu0 = time.process_time()
        for owner, t, frame_id, data, direction in frames:
            monitors[owner].on_frame(t, frame_id, data, direction)
        per_frame.append((time.process_time() - cpu0) / len(frames) * 1e6)
    print(f"{len(frames)} frames; µs CPU per on_frame: best {min(per_frame):.2f}, "
          f"median {statistics.median(per_frame):.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
