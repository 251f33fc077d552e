"""`bench plant` as its own process on a SocketCAN vcan0, judged by an independent python-can receiver.

Runs where the kernel has vcan0: in the vcan lane (scripts/vcan-lane --command, which .ci/run runs in a QEMU
guest on machines without SocketCAN) and on any Linux host with vcan0 up. Elsewhere it skips, except inside
the lane (VCAN_CHANNEL set), where a missing vcan0 is a failure: the lane must never pass by skipping.

What is checked, from the kernel's receive timestamps of a receiver that only collects (and judges after):
every frame of the plant keeps the contract (docs/spec/k-matrix.md: AliveCounter +1 per frame, CRC-8/SAE-J1850 over
identifier and data, tests/reference.py), every message of the vehicle's network is there at its DBC cycle
time (p50 within 5 %, as Case.check_cycle_times), no frame of another vehicle's network is on the bus, and the
plant's own status line reports no invalid frame.
"""

from __future__ import annotations

import signal
import statistics
import subprocess
import sys

import can
import pytest

from bench.codec import load_codebook
from bench.config import load_config
from plant.factory import messages_of, vehicles
from tests.reference import contract_checksum
from tests.repo import ROOT
from tests.vcan import CHANNEL, IN_LANE, has_vcan

WARM_UP_S = 2.0     # s after the plant's first frame before judging (its BCM tasks start after 3 cycles)
WINDOW_S = 6.0      # s of bus judged


if not has_vcan():
    if IN_LANE:
        raise RuntimeError(f"the vcan lane set VCAN_CHANNEL={CHANNEL}, but this kernel has no such SocketCAN "
                           "interface")
    pytest.skip(f"needs SocketCAN and {CHANNEL} (the vcan lane runs it: scripts/vcan-lane)", allow_module_level=True)


def test_plant_process_keeps_the_contract_on_vcan() -> None:
    codebook = load_codebook(load_config().databases)
    receiver = can.Bus(interface="socketcan", channel=CHANNEL, receive_own_messages=False)
    plant = subprocess.Popen([sys.executable, "-m", "bench", "plant", "--interface", "socketcan", "--channel", CHANNEL,
                              "--vehicle", "EV4WIS", "--duration", str(WARM_UP_S + WINDOW_S + 30)],
                             cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    frames: list[can.Message] = []
    try:
        first = receiver.recv(120.0)        # the plant imports and starts (slow in an emulated guest)
        assert first is not None, "no frame from bench plant within 120 s"
        start = first.timestamp + WARM_UP_S
        while True:
            msg = receiver.recv(5.0)
            assert msg is not None, "bench plant went quiet"
            if msg.timestamp >= start + WINDOW_S:
                break
            if msg.timestamp >= start:
                frames.append(msg)
    finally:
        receiver.shutdown()
        plant.send_signal(signal.SIGINT)
        output, _ = plant.communicate(timeout=60)
    assert plant.returncode == 0, output
    assert "invalid 0" in output and "invalid at" not in output, output

    by_id: dict[int, list[can.Message]] = {}
    for msg in frames:
        by_id.setdefault(msg.arbitration_id, []).append(msg)
    network = messages_of("EV4WIS")
    others = frozenset().union(*(messages_of(v) for v in vehicles())) - network
    seen = {codebook.by_id[i].name for i in by_id if i in codebook.by_id}
    assert network <= seen, f"missing from the bus: {sorted(network - seen)}"
    assert not seen & others, f"another vehicle's messages on the bus: {sorted(seen & others)}"
    for frame_id, msgs in by_id.items():
        codec = codebook.by_id[frame_id]
        if codec.e2e:
            for a, b in zip(msgs, msgs[1:]):
                assert b.data[6] & 0x0F == ((a.data[6] & 0x0F) + 1) % 16, f"{codec.name}: counter"
            bad = [m for m in msgs if m.data[7] != contract_checksum(frame_id, bytes(m.data))]
            assert not bad, f"{codec.name}: {len(bad)} frames with a wrong checksum"
        if codec.cycle_time:
            intervals = [b.timestamp - a.timestamp for a, b in zip(msgs, msgs[1:])]
            p50 = statistics.median(intervals)
            assert abs(p50 - codec.cycle_time) <= 0.05 * codec.cycle_time, \
                f"{codec.name}: p50 {p50 * 1000:.2f} ms, DBC {codec.cycle_time * 1000:g} ms"
            assert len(msgs) >= 0.9 * WINDOW_S / codec.cycle_time, f"{codec.name}: {len(msgs)} frames"
