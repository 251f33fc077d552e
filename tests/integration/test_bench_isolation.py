"""Issue 25, acceptance 1: two benches on one host, each on its own multicast group of the same family (IPv4, and
IPv6), side by side: 0 foreign frames in either run log.

Each `bench run` (runner and plant, real time, udp_multicast with the bench's hop limit 0) logs every frame its
runner sends (tx) and receives (rx). On its own group only its runner sends the stimulus messages (DRV_*,
BENCH_*), and its runner's own frames are logged once, as tx; so an rx frame of a stimulus identifier in a log is
the other bench's. The other bench's plant frames would be invalid frames (a second counter sequence) and "two
senders"; both runs count 0. Before bench/transport/udp.py limited IPv6 sockets to their group: about 1 000 invalid
frames in each of two 1 s runs on two IPv6 groups.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from bench.config import load_config
from bench.database.codec import load_codebook
from bench.log.logread import read_frames
from tests.fakes import ipv4_group, ipv6_available, ipv6_group
from tests.repo import ROOT

CASE = '''
import os


def test_side_by_side(bench):
    bench.start_scenario(Vehicle="EV4WIS")
    bench.set("DRV_MotionRequest", DriveMode="NORMAL", TargetSpeed=float(os.environ["MARK_SPEED"]))
    bench.run(1.0)
    bench.expect_true("ran", True)
'''


@pytest.mark.parametrize("family", ["IPv4", "IPv6"])
def test_two_benches_side_by_side_log_no_frame_of_each_other(family: str, tmp_path: Path) -> None:
    if family == "IPv6":
        ipv6_available()
    make = ipv6_group if family == "IPv6" else ipv4_group
    groups = [make(), make()]
    while groups[1] == groups[0]:
        groups[1] = make()
    (tmp_path / "test_pair.py").write_text(CASE, encoding="utf-8")
    runs = []
    for i, group in enumerate(groups):
        out = tmp_path / f"bench{i}"
        env = {**os.environ, "MARK_SPEED": f"{0.5 + i:.1f}"}
        runs.append((out, subprocess.Popen(
            [sys.executable, "-m", "bench", "run", str(tmp_path / "test_pair.py"), "--interface", "udp_multicast",
             "--channel", group, "--out", str(out)], cwd=ROOT, env=env, stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT, text=True)))
    outputs = [process.communicate(timeout=300)[0] for _, process in runs]
    project = load_config()
    stimulus_ids = {codec.frame_id for codec in load_codebook(project.databases).sent_by(project.stimulus)}
    for (out, process), output, group in zip(runs, outputs, groups):
        assert process.returncode == 0, output
        result = json.loads((out / "results.json").read_text(encoding="utf-8"))
        frames = list(read_frames(out / "run.mcap"))
        foreign = [f for f in frames if f.direction == "rx" and f.arbitration_id in stimulus_ids]
        assert len(frames) > 1000, f"{group}: {len(frames)} frames logged: the test would prove nothing"
        assert foreign == [], f"{group}: {len(foreign)} stimulus frames of the other bench logged: {foreign[:3]}"
        assert (result["invalid_frames"], result["findings"]) == (0, []), (group, result["invalid_frames"],
                                                                           result["findings"])
