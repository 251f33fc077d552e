"""The ".mcap" python-can log format (bench.log.canio): python-can's logger and player speak the bench's run log.

Issue 7, acceptance 3 (first half): `python -m can.logger -f x.mcap` records from a bus and `bench log info
x.mcap` reads it. udp_multicast traffic stays on this host: every bus here has hop limit 0 (the logger's
and player's through `--bus-kwargs hop_limit=0`, the test's through `bench.transport.open_bus`).
"""

from __future__ import annotations

import os
import random
import re
import select
import signal
import subprocess
import sys
import time
from pathlib import Path

import can
import pytest

from bench.errors import LogError
from bench.log.canio import MCAPReader, MCAPWriter
from bench.log.logread import read_decoded, read_frames
from bench.log.recorder import Recorder
from bench.transport import open_bus
from tests.fakes import ipv4_group
from tests.repo import BENCH_DBC, CHASSIS_DBC, ROOT

ENV = {**os.environ, "PYTHONUNBUFFERED": "1", "COLUMNS": "200"}


def frames_to_send(count: int) -> list[can.Message]:
    """Distinct ids and payloads (standard and extended ids), so a lost or reordered frame shows."""
    return [can.Message(arbitration_id=(0x100 + i) if i % 5 else (0x18DA0000 + i), is_extended_id=not i % 5,
                        data=bytes([i, 255 - i, 1, 2, 3, 4, 5, i % 7][: 1 + i % 8])) for i in range(count)]


def wait_for_output(process: subprocess.Popen, needle: bytes, timeout: float) -> bytes:
    """Read the process's stdout (raw, unbuffered) until `needle` appears (the logger says when it listens)."""
    assert process.stdout is not None
    fd = process.stdout.fileno()
    seen = b""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and needle not in seen:
        ready, _, _ = select.select([fd], [], [], 0.2)
        if ready:
            chunk = os.read(fd, 4096)
            if not chunk:
                break
            seen += chunk
    assert needle in seen, f"no {needle!r} from {process.args}: {seen!r}"
    return seen


@pytest.mark.realtime
def test_can_logger_records_a_bench_log(tmp_path: Path) -> None:
    channel = ipv4_group()
    # A port of its own: python-can's logger cannot restrict its socket to its group (IP_MULTICAST_ALL), and
    # on the default port it would also hear any other bench on this host.
    port = random.randint(44000, 44999)
    log = tmp_path / "x.mcap"
    logger = subprocess.Popen([sys.executable, "-m", "can.logger", "-i", "udp_multicast", "-c", channel,
                               "--bus-kwargs", "hop_limit=0", f"port={port}", "-f", str(log)], cwd=tmp_path,
                              env=ENV, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, bufsize=0)
    sent = frames_to_send(60)
    try:
        wait_for_output(logger, b"Can Logger", timeout=30)
        first_send = time.time()
        with can.Bus(interface="udp_multicast", channel=channel, hop_limit=0, port=port) as bus:
            for msg in sent:
                bus.send(msg)
                time.sleep(0.002)
        time.sleep(0.5)
        last_read = time.time()
    finally:
        logger.send_signal(signal.SIGINT)
        try:
            out, _ = logger.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            logger.kill()                    # a logger that ignored Ctrl-C must not outlive the test
            logger.communicate()
            raise
    assert logger.returncode == 0, out.decode(errors="replace")

    info = subprocess.run([sys.executable, "-m", "bench", "log", "info", str(log)], cwd=ROOT, env=ENV,
                          capture_output=True, text=True, timeout=60)
    assert info.returncode == 0, info.stderr
    assert re.search(r"Frames\s+60 \(0 invalid\)", info.stdout), info.stdout
    assert "complete" in info.stdout

    reader = can.LogReader(str(log))
    assert isinstance(reader, MCAPReader)
    with reader:
        got = list(reader)
    assert [(m.arbitration_id, m.is_extended_id, bytes(m.data)) for m in got] == \
           [(m.arbitration_id, m.is_extended_id, bytes(m.data)) for m in sent]
    assert all(m.is_rx for m in got)
    # The log holds the receive times python-can gave each frame: wall-clock times inside the sending window,
    # about 2 ms apart. Their order is not asserted: the kernel stamps a frame when it is read rather than when
    # it arrived while the host's receive timestamping is still being switched on (a socket's first frames),
    # so the first stamp may lie after the second (seen in CI: +45 ms).
    stamps = [m.timestamp for m in got]
    assert all(first_send - 0.01 <= t <= last_read + 0.01 for t in stamps), (first_send, stamps, last_read)
    gaps = sorted(b - a for a, b in zip(stamps, stamps[1:], strict=False))
    assert 0.001 < gaps[len(gaps) // 2] < 0.05, gaps                        # the median gap: ~2 ms per frame


def test_can_player_plays_a_bench_log(tmp_path: Path) -> None:
    channel = ipv4_group()
    log = tmp_path / "run.mcap"
    with Recorder(log, []) as recorder:
        for i in range(30):
            recorder.frame(2.0 + i * 0.005, 0x200 + i % 3, bytes([i] * 8), channel="can0", direction="tx")
    with open_bus("udp_multicast", channel) as bus:
        # "--" ends --bus-kwargs' list; the player takes everything after its input file as extra arguments
        player = subprocess.run([sys.executable, "-m", "can.player", "-i", "udp_multicast", "-c", channel,
                                 "--bus-kwargs", "hop_limit=0", "--", str(log)], cwd=tmp_path, env=ENV,
                                capture_output=True, text=True, timeout=60)
        assert player.returncode == 0, player.stdout + player.stderr
        got = []
        deadline = time.monotonic() + 5.0
        while len(got) < 30 and time.monotonic() < deadline:
            msg = bus.recv(0.2)
            if msg is not None:
                got.append(msg)
    assert [(m.arbitration_id, bytes(m.data)) for m in got] == [(0x200 + i % 3, bytes([i] * 8)) for i in range(30)]


def test_writer_with_a_dbc_checks_and_decodes_like_a_run(tmp_path: Path) -> None:
    """With dbc=..., frames get the monitor's verdict and decoded channels (the run log's format)."""
    from bench.database.codec import load_codebook
    from bench.sim.restbus import Restbus
    codebook = load_codebook([CHASSIS_DBC])
    restbus = Restbus(codebook, ["WHL_FL"])
    restbus.set("WHL_Status_FL", SteerAngle=12.5)
    slot = restbus.slots["WHL_Status_FL"]
    frame_id = codebook["WHL_Status_FL"].frame_id
    log = tmp_path / "decoded.mcap"
    with can.Logger(str(log), dbc=f"{CHASSIS_DBC},{BENCH_DBC}") as writer:
        assert isinstance(writer, MCAPWriter)
        for i in range(5):
            writer(can.Message(timestamp=10.0 + i * 0.01, arbitration_id=frame_id, data=restbus.build(slot),
                               is_extended_id=False))
        bad = bytearray(restbus.build(slot))
        protection = codebook["WHL_Status_FL"].protection
        assert protection is not None
        bad[protection.crc.first_byte] ^= 0xFF                 # wrong CRC
        writer(can.Message(timestamp=10.05, arbitration_id=frame_id, data=bad, is_extended_id=False))
        writer(can.Message(timestamp=10.06, arbitration_id=0x7FF, data=b"\x01", is_extended_id=False))
    frames = list(read_frames(log))
    assert [f.valid for f in frames] == [True] * 5 + [False, False]
    assert frames[5].error.startswith("E2E ERROR") and frames[6].error == "unknown identifier"
    decoded = list(read_decoded(log, "WHL_Status_FL"))
    assert len(decoded) == 5 and all(values["SteerAngle"] == 12.5 for _, _, values in decoded)


def test_reader_is_tolerant_of_a_cut_log_and_clear_about_a_foreign_file(tmp_path: Path) -> None:
    log = tmp_path / "run.mcap"
    recorder = Recorder(log, [], flush_interval=3600.0)    # chunks only where flushed below
    for i in range(200):
        recorder.frame(i * 0.001, 0x100, bytes(8), channel="can0", direction="rx")
        if i == 99:
            recorder.flush()
            first_chunk_end = log.stat().st_size
    recorder.flush()
    data = log.read_bytes()          # no footer yet: like a SIGKILLed run
    recorder.close()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: first_chunk_end + 40])     # inside the second chunk
    with can.LogReader(str(cut)) as reader:
        got = [m.timestamp for m in reader]
    assert got == pytest.approx([i * 0.001 for i in range(100)])
    foreign = tmp_path / "notes.mcap"
    foreign.write_text("not a log")
    with pytest.raises(LogError, match="not an MCAP run log"):
        can.LogReader(str(foreign))
    with pytest.raises(ValueError, match="cannot be appended"):
        MCAPWriter(tmp_path / "again.mcap", append=True)


#: one frame of each kind python-can has: what it was must survive the log (issue 34: the log stored error frames as
#: data frames of id 0 that a replay would have sent)
KINDS = {
    "11-bit data": can.Message(arbitration_id=0x123, data=b"\x01\x02", is_extended_id=False),
    "29-bit data": can.Message(arbitration_id=0x18FF2010, data=bytes(8), is_extended_id=True),
    "error frame": can.Message(arbitration_id=0x004, data=b"\x00\x04\x00\x00\x00\x00\x00\x00", is_error_frame=True,
                               is_extended_id=False),
    "remote frame": can.Message(arbitration_id=0x321, is_remote_frame=True, dlc=4, is_extended_id=False),
    "29-bit remote frame": can.Message(arbitration_id=0x1ABCDE, is_remote_frame=True, dlc=2, is_extended_id=True),
    "CAN FD with BRS and ESI": can.Message(arbitration_id=0x200, data=bytes(range(64)), is_fd=True, bitrate_switch=True,
                                          error_state_indicator=True, is_extended_id=False),
    "CAN FD without BRS": can.Message(arbitration_id=0x18DA10F1, data=bytes(12), is_fd=True, is_extended_id=True),
}


def _kind(msg: can.Message) -> tuple[object, ...]:
    return (msg.arbitration_id, msg.is_extended_id, msg.is_error_frame, msg.is_remote_frame, msg.dlc, msg.is_fd,
            msg.bitrate_switch, msg.error_state_indicator, bytes(msg.data), msg.is_rx)


@pytest.mark.parametrize("kind", list(KINDS))
def test_every_frame_kind_survives_python_cans_writer_and_reader(tmp_path: Path, kind: str) -> None:
    sent = KINDS[kind]
    sent.timestamp, sent.is_rx = 1.25, False
    path = tmp_path / "kinds.mcap"
    with can.Logger(str(path)) as writer:
        assert isinstance(writer, MCAPWriter)
        writer.on_message_received(sent)
    with can.LogReader(str(path)) as reader:
        got = list(reader)
    assert [_kind(m) for m in got] == [_kind(sent)]
    assert got[0].timestamp == pytest.approx(1.25, abs=1e-9)
