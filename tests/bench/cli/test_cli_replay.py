"""`bench replay` of an empty or cut log says so (issue 16, finding 11), rather than exiting 0 without a word."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from tests.fakes import ipv4_group, make_log
from tests.repo import ROOT


def replay(log: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bench", "replay", str(log), "--interface", "udp_multicast",
                           "--channel", ipv4_group(), "--speed", "10"], cwd=ROOT, capture_output=True, text=True,
                          timeout=120, env={**os.environ, "COLUMNS": "80"})


def test_empty_log_is_a_one_line_error(tmp_path: Path) -> None:
    log = tmp_path / "empty.mcap"
    log.write_bytes(b"")
    result = replay(log)
    assert result.returncode == 2, result.stdout + result.stderr
    [line] = result.stderr.strip().splitlines()
    assert line.startswith("bench replay: error:") and "no frames to replay" in line and "ends early" in line


def test_complete_log_without_frames_is_an_error(tmp_path: Path) -> None:
    from bench.log.recorder import Recorder

    log = tmp_path / "no-frames.mcap"
    with Recorder(log, []):
        pass
    result = replay(log)
    assert result.returncode == 2 and "no frames to replay" in result.stderr and "ends early" not in result.stderr


def test_cut_log_is_replayed_with_a_warning(tmp_path: Path) -> None:
    whole = tmp_path / "whole.mcap"
    make_log(whole)
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(whole.read_bytes()[: whole.stat().st_size * 2 // 3])
    result = replay(cut)
    assert result.returncode == 0, result.stdout + result.stderr
    lines = result.stderr.strip().splitlines()
    assert lines[0].startswith("bench replay: done, sent") and " 0 frames" not in lines[0]
    assert len(lines) == 2 and lines[1].startswith("bench replay: warning:") and "ends early" in lines[1]
    whole_result = replay(whole)
    assert whole_result.returncode == 0 and "warning" not in whole_result.stderr
