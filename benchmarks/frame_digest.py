"""SHA-256 of a run's logged frame sequence and decoded messages: proof that a change of the frame path left the
bus traffic as it was (two runs of the same cases, before and after, must print the same digests).

    python benchmarks/frame_digest.py /tmp/r/before/run.mcap /tmp/r/after/run.mcap

Times are taken relative to the log's first record (the log's origin is the wall clock at the run's start);
a frame counts with its bench time, identifier, data, direction and verdict; a decoded message with its bench
time, topic and JSON text.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path

from mcap.reader import make_reader


def digests(path: Path) -> dict[str, str | int]:
    frames, decoded = hashlib.sha256(), hashlib.sha256()
    n_frames = n_decoded = 0
    origin: int | None = None
    with open(path, "rb") as f:
        for _schema, channel, message in make_reader(f).iter_messages(log_time_order=False):
            if origin is None:
                origin = message.log_time
            t = message.log_time - origin
            if channel.topic == "/can/frames":
                record = json.loads(message.data)
                fields = (t, record["id"], record["data"], record["direction"], record["valid"], record["error"])
                frames.update(repr(fields).encode())
                n_frames += 1
            elif channel.topic.startswith("/can/decoded/"):
                decoded.update(f"{t} {channel.topic} ".encode() + message.data + b"\n")
                n_decoded += 1
    return {"frames": n_frames, "frames_sha256": frames.hexdigest(),
            "decoded": n_decoded, "decoded_sha256": decoded.hexdigest()}


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("mcap", nargs="+", type=Path, help="a run's MCAP log (two or more: compared)")
    paths = parser.parse_args(argv).mcap
    missing = [str(p) for p in paths if not p.is_file()]
    if missing:
        parser.error(f"no such file: {', '.join(missing)}")
    results = [digests(p) for p in paths]
    for path, result in zip(paths, results, strict=True):
        print(path, result)
    same = all(r == results[0] for r in results)
    if len(results) > 1:
        print("identical" if same else "DIFFERENT")
    return 0 if same else 1


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
