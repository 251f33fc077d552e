"""bench/transport/periodic.py: restbus messages handed to the kernel's broadcast manager (BCM) on socketcan.

Two layers. Without CAN in the kernel (this host), a fake kernel stands in for SocketCAN: BCM tasks that send
their frames in turn on a timer, raw sockets with CAN_RAW_FILTER (inverted, joined) and loopback to the other
sockets. A station runs on it tick by tick through stable values, a single change, a ramp, stop_sending and
a fault plan; the frames "on the wire" must keep the contract (docs/spec/k-matrix.md: AliveCounter +1 per transmission,
CRC-8/SAE-J1850 Checksum, the DBC cycle) across every hand-over, and the station's log must hold exactly the
wire's frames. With CAN in the kernel (the vcan lane: scripts/vcan-lane --command 'python -m pytest
tests/bench/transport/test_periodic.py'), the same checks run against the real BCM on vcan0.
"""

from __future__ import annotations

import socket
import struct
import time
from collections import deque
from typing import Any

import can
import pytest

from bench import e2e
from bench.checks.monitor import Monitor
from bench.database.codec import Codebook
from bench.faults.plan import FaultPlan, parse_fault
from bench.sim.restbus import Restbus
from bench.sim.station import Station
from bench.transport import periodic
from tests.fakes import FakeBus
from tests.integration.vcan import IN_LANE, has_vcan
from tests.reference import COUNTER_VALUES, counter_of, intact
from tests.repo import VFRAMEFORMAT_DEFINITION

DT = 0.001


# -- a fake SocketCAN kernel -------------------------------------------------------------------------------
class FakeKernel:
    def __init__(self) -> None:
        self.now = 0.0
        self.sockets: list[FakeRawSocket] = []
        self.tasks: list[FakeTask] = []
        self.wire: list[tuple[float, int, bytes, str]] = []   # (time, id, data, "kernel" | "raw")

    def clock(self) -> float:
        return self.now

    def deliver(self, frame_id: int, data: bytes, source: str, sender: FakeRawSocket | None) -> None:
        self.wire.append((self.now, frame_id, bytes(data), source))
        raw = struct.pack("=IB3x8s", frame_id, len(data), bytes(data).ljust(8, b"\0"))
        for sock in self.sockets:
            if sock is not sender and sock.accepts(frame_id):
                sock.queue.append(raw)

    def advance(self, t: float) -> None:
        """Fire every task timer due up to t, in time order."""
        while True:
            due = [task for task in self.tasks if task.alive and task.next_t <= t + 1e-12]
            if not due:
                break
            task = min(due, key=lambda k: k.next_t)
            self.now = task.next_t
            task.fire()
        self.now = t


class FakeRawSocket:
    family, type = socket.AF_CAN, socket.SOCK_RAW      # a raw SocketCAN socket (bench.transport.capabilities asks)

    def __init__(self, kernel: FakeKernel) -> None:
        self.kernel = kernel
        self.filters: list[tuple[int, int]] | None = None    # None: accept every frame (no filter set)
        self.join = False
        self.queue: deque[bytes] = deque()
        kernel.sockets.append(self)

    def setsockopt(self, level: int, option: int, value: bytes) -> None:
        if option == socket.CAN_RAW_FILTER:
            self.filters = [struct.unpack_from("=II", value, i) for i in range(0, len(value), 8)]
        elif option == periodic.CAN_RAW_JOIN_FILTERS:
            self.join = bool(struct.unpack("=i", value)[0])

    def accepts(self, frame_id: int) -> bool:
        if self.filters is None:
            return True
        results = []
        for fid, mask in self.filters:
            match = (frame_id & mask) == (fid & ~periodic.CAN_INV_FILTER & mask)
            results.append(not match if fid & periodic.CAN_INV_FILTER else match)
        return bool(results) and (all(results) if self.join else any(results))

    def bind(self, address: Any) -> None:
        pass

    def setblocking(self, flag: bool) -> None:
        pass

    def close(self) -> None:
        pass

    def recv(self, size: int) -> bytes:
        if not self.queue:
            raise BlockingIOError
        return self.queue.popleft()

    def recvmsg(self, size: int, ancillary_size: int, flags: int = 0) -> tuple[bytes, list, int, Any]:
        """As SocketCAN gives a frame with SO_TIMESTAMPNS (the fake kernel's time as the receive time)."""
        frame = self.recv(size)
        seconds = int(self.kernel.now)
        stamp = struct.pack("@ll", seconds, int((self.kernel.now - seconds) * 1e9))
        return frame, [(socket.SOL_SOCKET, 35, stamp)], 0, ("vcan0",)


class FakeTask:
    """A BCM TX_SETUP task: sends its frames in turn, the first at once (STARTTIMER announces)."""

    def __init__(self, kernel: FakeKernel, frames: list[can.Message], period: float) -> None:
        self.kernel, self.frames, self.period = kernel, list(frames), period
        self.index = 0
        self.alive = True
        self.next_t = kernel.now
        kernel.tasks.append(self)
        self.fire()

    def fire(self) -> None:
        frame = self.frames[self.index]
        self.kernel.deliver(frame.arbitration_id, bytes(frame.data), "kernel", None)
        self.index = (self.index + 1) % len(self.frames)
        self.next_t += self.period

    def modify_data(self, frames: list[can.Message]) -> None:   # the kernel keeps index and timer
        assert len(frames) == len(self.frames)
        self.frames = list(frames)

    def stop(self) -> None:
        self.alive = False


class SocketcanBus(FakeBus):
    """Like python-can's: a raw SocketCAN socket in `socket`, so that bench.transport takes it for socketcan; what it
    sends and receives goes through the fake kernel."""

    def __init__(self, kernel: FakeKernel) -> None:
        super().__init__("vcan0", socket=FakeRawSocket(kernel))
        self.channel = "vcan0"
        self.kernel = kernel

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self.kernel.deliver(msg.arbitration_id, bytes(msg.data), "raw", self.socket)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        try:
            raw = self.socket.recv(16)
        except BlockingIOError:
            return None, False
        can_id, length, data = struct.unpack("=IB3x8s", raw)
        return can.Message(arbitration_id=can_id, data=data[:length], is_extended_id=False), False

    def _send_periodic_internal(self, msgs: Any, period: float, duration: float | None = None,
                                autostart: bool = True, modifier_callback: Any = None) -> FakeTask:
        return FakeTask(self.kernel, list(msgs), period)


@pytest.fixture
def fake(monkeypatch: pytest.MonkeyPatch) -> FakeKernel:
    kernel = FakeKernel()
    monkeypatch.setattr(periodic, "_raw_socket", lambda: FakeRawSocket(kernel))
    monkeypatch.setattr(periodic, "_clock", kernel.clock)
    monkeypatch.delenv(periodic.ENV_SWITCH, raising=False)
    return kernel


def _station(codebook: Codebook, kernel: FakeKernel) -> Station:
    bus = SocketcanBus(kernel)
    station = Station("runner", bus, Restbus(codebook, {"DRIVER"}), Monitor(codebook, keep_history=True),
                      kernel.clock)
    assert station.kernel is not None
    return station


def _run(station: Station, kernel: FakeKernel, ticks: range, each=None) -> None:
    for tick in ticks:
        t = tick * DT
        kernel.advance(t)
        if each is not None:
            each(tick)
        station.tick(tick, t, DT)


def _check_wire(kernel: FakeKernel, codebook: Codebook, paused: dict[int, tuple[float, float]] | None = None) -> None:
    """Every identifier on the wire: valid checksum, counter +1 per frame, one frame per cycle (±1 tick)."""
    by_id: dict[int, list[tuple[float, bytes]]] = {}
    for t, frame_id, data, _ in kernel.wire:
        by_id.setdefault(frame_id, []).append((t, data))
    for frame_id, frames in by_id.items():
        period = codebook.by_id[frame_id].cycle_time
        for (t0, d0), (t1, d1) in zip(frames, frames[1:]):
            assert intact(frame_id, d1), (hex(frame_id), t1)
            assert counter_of(d1) == (counter_of(d0) + 1) % COUNTER_VALUES, (hex(frame_id), t0, t1)
            gap = t1 - t0
            window = (paused or {}).get(frame_id)
            if window is not None and window[0] <= t1 <= window[1] + period:
                continue
            assert period - DT - 1e-9 <= gap <= period + DT + 1e-9, (hex(frame_id), t0, t1, gap)


def _no_frame_rejected(monitor: Monitor) -> None:
    """No frame on the wire was rejected (each message's first frame after power-up is valid, only held back
    while the E2E state machine goes from NODATA to INIT, docs/spec/e2e.md: no invalid frame either)."""
    assert [r.reason for r in monitor.invalid_log] == [] and monitor.invalid_frames == 0


def test_counter_cycle_covers_every_counter_with_its_checksum() -> None:
    data = bytes([1, 2, 3, 4, 5, 6, 0, 0x30 | 9])
    protection = e2e.Protection("P11", data_id=0x102, offset=48)
    frames = periodic.counter_cycle(protection, 0x102, data, 9)
    assert [counter_of(f.data) for f in frames] == [(9 + k) % COUNTER_VALUES for k in range(COUNTER_VALUES)]
    for f in frames:
        assert f.data[7] & 0xF0 == 0x30 and bytes(f.data[:6]) == data[:6]
        assert intact(0x102, bytes(f.data))


def test_stable_messages_go_to_the_kernel_and_the_log_is_the_wire(codebook: Codebook, fake: FakeKernel) -> None:
    station = _station(codebook, fake)
    _run(station, fake, range(1, 1001))
    kernel = station.kernel
    assert set(kernel.tasks) == {0x100, 0x101, 0x102}      # DRV_Steering, DRV_Pedals, DRV_MotionRequest
    sources = {source for _, _, _, source in fake.wire[-30:]}
    assert sources == {"kernel"}
    _check_wire(fake, codebook)
    _no_frame_rejected(station.monitor)
    logged = station.monitor.frames
    assert abs(logged - len(fake.wire)) <= 3                # the last tick's frames may be read on the next
    assert station.sent == logged


def test_changes_modify_or_hand_back_and_the_counter_runs_on(codebook: Codebook, fake: FakeKernel) -> None:
    station = _station(codebook, fake)
    angles: list[tuple[float, float]] = []

    def stimulus(tick: int) -> None:
        if tick == 300:                        # one change: the kernel's frames are rewritten in place
            station.restbus.set("DRV_Steering", HandWheelAngle=12.5)
            angles.append((tick * DT, 12.5))
        if 500 <= tick < 700:                  # a ramp: back to the tick scheduler
            station.restbus.set("DRV_Steering", HandWheelAngle=round(0.1 * (tick - 500), 1))
        if tick == 700:
            angles.append((tick * DT, 19.9))

    _run(station, fake, range(1, 1201), stimulus)
    kernel = station.kernel
    assert kernel.modified >= 1 and kernel.stopped >= 1 and kernel.started >= 4
    assert 0x100 in kernel.tasks                # stable again after the ramp: the kernel sends it again
    _check_wire(fake, codebook)
    _no_frame_rejected(station.monitor)
    steering = [(t, d) for t, i, d, s in fake.wire if i == 0x100]
    ramp_sources = {s for t, i, d, s in fake.wire if i == 0x100 and 0.56 <= t <= 0.69}
    assert ramp_sources == {"raw"}             # during the ramp the tick scheduler sends
    codec = codebook.by_id[0x100]
    for t_change, value in angles:             # every change is on the wire within one cycle
        after = [codec.decode(d)["HandWheelAngle"] for t, d in steering if t_change < t <= t_change + 0.011]
        assert after and abs(after[-1] - value) < 0.05, (t_change, after)


def test_stop_sending_and_faults_hand_back_to_the_scheduler(codebook: Codebook, fake: FakeKernel) -> None:
    station = _station(codebook, fake)

    def stimulus(tick: int) -> None:
        if tick == 400:
            station.restbus.stop_sending("DRV_Pedals")
        if tick == 600:
            station.restbus.resume_sending("DRV_Pedals")
        if tick == 800:
            plan = FaultPlan(codebook)
            plan.add(parse_fault("bitflip:DRV_MotionRequest:0@2.0-2.5"))
            station.faults = plan

    _run(station, fake, range(1, 1001), stimulus)
    pedals = [t for t, i, _, _ in fake.wire if i == 0x101]
    assert not [t for t in pedals if 0.4025 < t < 0.6]          # silent within 2 ms of stop_sending
    _check_wire(fake, codebook, paused={0x101: (0.4, 0.6)})
    assert not station.kernel.tasks                              # a fault plan: every message on the scheduler
    assert {s for t, _, _, s in fake.wire if t > 0.81} == {"raw"}
    _no_frame_rejected(station.monitor)


def test_other_buses_and_the_switch_keep_the_scheduler(codebook: Codebook, fake: FakeKernel,
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    virtual = can.Bus(interface="virtual", channel="periodic-test")
    try:
        assert periodic.KernelPeriodic.attach(virtual, Restbus(codebook, {"DRIVER"})) is None
    finally:
        virtual.shutdown()
    monkeypatch.setenv(periodic.ENV_SWITCH, "0")
    assert periodic.KernelPeriodic.attach(SocketcanBus(fake), Restbus(codebook, {"DRIVER"})) is None


# -- the real kernel (vcan lane) --------------------------------------------------------------------------
# Inside the vcan lane (VCAN_CHANNEL set) it never skips: a lane without vcan0 must fail, not pass empty.
@pytest.mark.skipif(not has_vcan("vcan0") and not IN_LANE,
                    reason="needs SocketCAN and vcan0 (the vcan lane runs it: scripts/vcan-lane)")
@pytest.mark.realtime
def test_real_bcm_on_vcan(codebook: Codebook) -> None:
    """The real BCM: a station on vcan0 through stable values, a change and a ramp; an independent
    socket sees every frame (counter, checksum, cycle) and the station's log holds the same frames."""
    bus = can.Bus(interface="socketcan", channel="vcan0", receive_own_messages=False)
    watcher = can.Bus(interface="socketcan", channel="vcan0", can_filters=[{"can_id": 0x100, "can_mask": 0x7FC}])
    t0 = time.monotonic()
    station = Station("runner", bus, Restbus(codebook, {"DRIVER"}), Monitor(codebook), lambda: time.monotonic() - t0)
    try:
        assert station.kernel is not None
        seen: dict[int, list[can.Message]] = {}

        def watch(timeout: float = 0.0) -> None:
            while (msg := watcher.recv(timeout)) is not None:
                seen.setdefault(msg.arbitration_id, []).append(msg)

        tick = 0
        while (t := time.monotonic() - t0) < 3.0:
            watch()
            if tick == 1500:
                station.restbus.set("DRV_Steering", HandWheelAngle=5.0)
            if 2000 <= tick < 2300:
                station.restbus.set("DRV_Steering", HandWheelAngle=round(0.1 * (tick - 2000), 1))
            tick += 1
            station.tick(tick, t, DT)
            time.sleep(max(0.0, t0 + tick * DT - time.monotonic()))
        kernel = station.kernel
        assert kernel.started >= 3 and kernel.stopped >= 1
        for task in list(kernel.tasks.values()):   # the kernel would send on: stop it, then read what it sent
            task.task.stop()
        before_read = time.time()
        for frame_id, data, stamp in kernel.echoes():
            station.monitor.on_frame(time.monotonic() - t0, frame_id, data, "tx")
            assert before_read - 1.0 < stamp <= before_read, "the echo's kernel receive time (SO_TIMESTAMPNS)"
        watch(0.05)
        for frame_id, frames in seen.items():
            for a, b in zip(frames, frames[1:]):
                assert counter_of(b.data) == (counter_of(a.data) + 1) % COUNTER_VALUES, hex(frame_id)
                assert intact(frame_id, bytes(b.data))
        _no_frame_rejected(station.monitor)
        assert abs(station.monitor.frames - sum(len(f) for f in seen.values())) <= 6
    finally:
        bus.shutdown()
        watcher.shutdown()


FD_DBC = f"""VERSION ""
NS_ :
BS_:
BU_: ECU
BO_ 288 FdP05: 32 ECU
 SG_ Crc : 0|16@1+ (1,0) [0|65535] "" Vector__XXX
 SG_ Counter : 16|8@1+ (1,0) [0|255] "" Vector__XXX
 SG_ Value : 24|16@1+ (1,0) [0|65535] "" Vector__XXX
BO_ 2566844672 FdPlain: 64 ECU
 SG_ Tail : 496|16@1+ (1,0) [0|65535] "" Vector__XXX
BA_DEF_ BO_ "GenMsgCycleTime" INT 0 65535;
{VFRAMEFORMAT_DEFINITION}
BA_DEF_ BO_ "E2E_Profile" ENUM "None","P01","P02","P05","P07","P11";
BA_DEF_ BO_ "E2E_DataID" INT 0 65535;
BA_DEF_DEF_ "GenMsgCycleTime" 0;
BA_DEF_DEF_ "VFrameFormat" "StandardCAN_FD";
BA_DEF_DEF_ "E2E_Profile" "None";
BA_DEF_DEF_ "E2E_DataID" 0;
BA_ "GenMsgCycleTime" BO_ 288 10;
BA_ "GenMsgCycleTime" BO_ 2566844672 20;
BA_ "VFrameFormat" BO_ 2566844672 15;
BA_ "E2E_Profile" BO_ 288 3;
BA_ "E2E_DataID" BO_ 288 4660;
"""


@pytest.mark.skipif(not has_vcan("vcan0") and not IN_LANE,
                    reason="needs SocketCAN and vcan0 (the vcan lane runs it: scripts/vcan-lane)")
@pytest.mark.realtime
def test_real_bcm_sends_can_fd_frames() -> None:
    """CAN FD through the kernel's broadcast manager (vcan0 with MTU 72): a 32-byte message under E2E Profile 5 (its
    256 counter values are one task's frames) and a 64-byte 29-bit one; an independent socket sees each as FD with
    the bit rate switch and its length, every P05 frame passes autosar-e2e's check with its counter one up, and the
    station's log (the echo socket) holds as many frames."""
    import cantools
    from e2e import p05

    codebook = Codebook([("fd.dbc", cantools.database.load_string(FD_DBC, "dbc"))])
    bus = can.Bus(interface="socketcan", channel="vcan0", fd=True, receive_own_messages=False)
    watcher = can.Bus(interface="socketcan", channel="vcan0", fd=True)
    t0 = time.monotonic()
    station = Station("runner", bus, Restbus(codebook, {"ECU"}), Monitor(codebook), lambda: time.monotonic() - t0)
    try:
        assert station.kernel is not None and set(station.kernel.slots) == {
            codebook["FdP05"].send_id, codebook["FdPlain"].send_id}
        seen: dict[int, list[can.Message]] = {}
        tick = 0
        while (t := time.monotonic() - t0) < 2.0:
            while (msg := watcher.recv(0.0)) is not None:
                seen.setdefault(msg.arbitration_id, []).append(msg)
            tick += 1
            station.tick(tick, t, DT)
            time.sleep(max(0.0, t0 + tick * DT - time.monotonic()))
        kernel = station.kernel
        assert kernel.started == 2
        for task in list(kernel.tasks.values()):
            task.task.stop()
        for frame_id, data, _ in kernel.echoes():
            station.monitor.on_frame(time.monotonic() - t0, frame_id, data, "tx")
        while (msg := watcher.recv(0.05)) is not None:
            seen.setdefault(msg.arbitration_id, []).append(msg)
        p05_frames, plain = seen[0x120], seen[0x18FEF100]
        shape = {(m.is_fd, m.bitrate_switch, m.is_extended_id, len(m.data)) for m in p05_frames}
        assert shape == {(True, True, False, 32)}
        assert {(m.is_fd, m.bitrate_switch, m.is_extended_id, len(m.data)) for m in plain} == {(True, True, True, 64)}
        assert all(p05.e2e_p05_check(bytearray(m.data), 0x1234) for m in p05_frames)
        counters = [m.data[2] for m in p05_frames]
        assert all((b - a) % 256 == 1 for a, b in zip(counters, counters[1:]))
        assert len(p05_frames) >= 150 and len(plain) >= 75
        _no_frame_rejected(station.monitor)
        assert abs(station.monitor.frames - len(p05_frames) - len(plain)) <= 4
    finally:
        bus.shutdown()
        watcher.shutdown()
