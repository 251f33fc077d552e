"""`bench replay`: a log's frames go back onto a bus with the recorded spacing (udp_multicast, hop limit 0)."""

from __future__ import annotations

import os
import random
import statistics
import subprocess
import sys
import time
from pathlib import Path

import pytest

from bench.cli import main
from bench.log.recorder import Recorder
from bench.transport import open_bus
from tests.fakes import SPACING, ipv4_group, make_log
from tests.repo import ROOT


def replay(log: Path, channel: str, *extra: str, expect: int) -> tuple[list, subprocess.CompletedProcess]:
    """Run `bench replay` in its own process and receive what it sends."""
    with open_bus("udp_multicast", channel) as bus:
        process = subprocess.Popen([sys.executable, "-m", "bench", "replay", str(log), "--interface",
                                    "udp_multicast", "--channel", channel, *extra], cwd=ROOT,
                                   stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                   env={**os.environ, "COLUMNS": "200"})   # rich: one summary line
        got = []
        deadline = time.monotonic() + 30.0
        while len(got) < expect and time.monotonic() < deadline:
            msg = bus.recv(0.2)
            if msg is not None:
                got.append(msg)
        out, err = process.communicate(timeout=30)
    return got, subprocess.CompletedProcess(process.args, process.returncode, out, err)


def span(stamps: list[float]) -> float:
    """First to last frame as the frames' common pace gives it: the median of the slopes between every two
    frames (Theil-Sen) times their count less one. A replayer that drifts or plays at another speed changes most
    slopes; a frame held up by a busy host (it goes at once when late, bench/cli/replay.py) changes few of them.
    Taking the last frame's stamp less the first's judged one frame alone: 0.51 s for 0.39 s once in 20 runs at
    load 6."""
    slopes = [(stamps[j] - stamps[i]) / (j - i) for i in range(len(stamps)) for j in range(i + 1, len(stamps))]
    return statistics.median(slopes) * (len(stamps) - 1)


@pytest.mark.realtime
def test_replay_sends_the_logged_frames_with_their_spacing(tmp_path: Path) -> None:
    log = tmp_path / "run.mcap"
    sent = make_log(log)
    got, result = replay(log, ipv4_group(), "--direction", "tx", expect=len(sent))
    assert result.returncode == 0, result.stderr
    assert [(m.arbitration_id, bytes(m.data)) for m in got] == sent      # invalid frames too; no error frame
    stamps = [m.timestamp for m in got]                                    # kernel receive times
    gaps = [b - a for a, b in zip(stamps, stamps[1:])]
    assert statistics.median(gaps) == pytest.approx(SPACING, abs=0.002)
    assert span(stamps) == pytest.approx(39 * SPACING, abs=0.05)
    assert "sent 40 frames" in result.stderr and "1 error frames skipped" in result.stderr


@pytest.mark.realtime
def test_speed_and_direction(tmp_path: Path) -> None:
    log = tmp_path / "run.mcap"
    make_log(log)
    got, result = replay(log, ipv4_group(), "--direction", "rx", "--speed", "2", expect=40)
    assert result.returncode == 0, result.stderr
    assert [m.arbitration_id for m in got] == [0x400] * 40
    assert span([m.timestamp for m in got]) == pytest.approx(39 * SPACING / 2, abs=0.04)


@pytest.mark.parametrize(("argv", "needle"), [
    (["--interface", "embedded"], "embedded bus"),
    (["--speed", "0"], "--speed"),
    (["--speed", "inf"], "--speed"),
])
def test_bad_options_are_one_line_errors(tmp_path: Path, argv: list[str], needle: str,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    log = tmp_path / "run.mcap"
    make_log(log)
    assert main(["replay", str(log), *argv]) == 2
    err = capsys.readouterr().err
    assert needle in err and "Traceback" not in err


def test_missing_log_is_a_clear_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["replay", str(tmp_path / "none.mcap"), "--channel", ipv4_group()]) == 2
    assert "none.mcap" in capsys.readouterr().err


def test_replay_keeps_the_can_fd_flags(tmp_path: Path) -> None:
    """A replayed frame is the logged one: CAN FD (also at 8 bytes or fewer), BRS, ESI, a remote frame's length,
    extended ids; not a classic frame made of every frame of 8 bytes or fewer (issue 28). Played through
    bench replay's loop onto python-can's own virtual bus, in process, and received on a second handle."""
    import can

    from bench.cli.replay import Counts, play
    from bench.log.canio import log_reader

    logged = [   # (id, data, extended, fd, brs, esi, remote dlc)
        (0x101, bytes(range(12)), False, True, True, False, None),
        (0x102, bytes([1, 2, 3]), False, True, False, True, None),      # FD at 3 bytes
        (0x1ABCDE, bytes(range(64)), True, True, True, True, None),
        (0x103, bytes([9] * 8), False, False, False, False, None),      # classic
        (0x104, b"", False, False, False, False, 6),                     # remote, asks for 6 bytes
    ]
    log = tmp_path / "fd.mcap"
    with Recorder(log, []) as recorder:
        for i, (frame_id, data, extended, fd, brs, esi, dlc) in enumerate(logged):
            recorder.frame(1.0 + i * 0.001, frame_id, data, channel="can0", direction="tx", is_extended=extended,
                           is_fd=fd, bitrate_switch=brs, error_state_indicator=esi, is_remote=dlc is not None,
                           dlc=dlc)
    channel = f"replay-fd-{random.randrange(1 << 30)}"
    with can.Bus(interface="virtual", channel=channel, receive_own_messages=False) as sender, \
            can.Bus(interface="virtual", channel=channel) as receiver:
        counts = Counts()
        reader = log_reader(log)
        try:
            play(reader, sender, 100.0, "all", counts)
        finally:
            reader.stop()
        got = [receiver.recv(1.0) for _ in logged]
    assert counts.sent == len(logged) and counts.failed == counts.skipped == 0
    assert all(m is not None for m in got)
    assert [(m.arbitration_id, bytes(m.data), m.is_extended_id, m.is_fd, m.bitrate_switch, m.error_state_indicator,
             m.dlc if m.is_remote_frame else None) for m in got if m is not None] == logged
