"""Kernel periodic sending on SocketCAN: the broadcast manager (BCM) sends restbus messages whose payload stays.

Why: a frame the tick loop sends is late whenever the Python process is (a busy host, emulation, a slow
check in a test case); the kernel's BCM sends a cyclic frame on its own timer, however busy the process,
and costs the process nothing per frame. python-can exposes it as `bus.send_periodic(msgs, period)`; a
sequence of frames becomes one BCM task that sends them in turn (`nframes`).

How (docs/spec/e2e.md: the counter +1 per transmission, through the profile's range; the CRC over it):
- A message whose payload (every byte but the counter and the CRC) is unchanged for STABLE_CYCLES cycles is
  handed to the kernel as one frame per counter value (15 for Profile 11), c, c+1, ... (modulo the counter's
  range), each with its CRC: one whole counter cycle, so the kernel's walk through the frames is the counter
  sequence. c is the counter of the frame due now, which the kernel sends at once (STARTTIMER announces),
  then one frame per cycle time on its own timer.
- PRECHECK_S before each of the kernel's frames the values are compared with the ones it holds; a change
  rewrites the frames in place (`task.modify_data`) and goes out with that frame, as the tick scheduler
  would send it: the kernel keeps its position in the sequence and its timer, so counter and cycle run on.
- A message that changes CHANGES_TO_STOP cycles in a row, whose sending is stopped (stop_sending) or while a
  fault plan acts on the station's frames goes back to the tick scheduler. The task is deleted between two of
  its frames (at least STOP_MARGIN_S away from either), so no frame is in flight; the restbus counter then
  continues after the last frame the kernel sent, and its next frame is due one cycle after it.
- The log stays complete and exact: the kernel loops every frame it sends back to the raw sockets of the
  interface. A second raw socket of the station, filtered to the identifiers the kernel sends, reads them
  without python-can's per-frame overhead, and the station logs them as "tx" at the kernel's receive time of
  the echo (SO_TIMESTAMPNS: the moment the kernel sent it); the station's bus socket filters them out in the kernel
  (inverted filters joined with CAN_RAW_JOIN_FILTERS, Linux >= 4.1). A foreign sender on an identifier the
  kernel sends is therefore not seen while the kernel sends it.

Classical messages of 8 bytes and CAN FD messages of any length qualify, with a cycle time of at least MIN_CYCLE_S
and, when E2E-protected, a counter of at most MAX_FRAMES values (the kernel holds at most 256 frames per task;
Profile 7's 32-bit counter stays on the tick scheduler); an unprotected message is handed over as one frame. FD
frames go to the kernel with CAN_FD_FRAME (python-can's task sets it) and come back on an echo socket that takes
FD frames (CAN_RAW_FD_FRAMES). The echo socket lives as long as the station (it closes with the process).
Set BENCH_KERNEL_PERIODIC=0 in the environment to keep every message on the tick scheduler.
"""

from __future__ import annotations

import logging
import os
import socket
import struct
import time
from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING, Any

import can

from bench import canid
from bench.transport.socketcan_rx import SO_TIMESTAMPNS, FastReceiver, plain_socketcan

if TYPE_CHECKING:
    from bench.e2e import Protection
    from bench.sim.restbus import Restbus

log = logging.getLogger(__name__)

STABLE_CYCLES = 3        # unchanged cycles before a message is handed to the kernel
CHANGES_TO_STOP = 3      # consecutive changed cycles that send it back to the tick scheduler
STOP_MARGIN_S = 0.0015   # a task is deleted only this far from its frames (none in flight)
PRECHECK_S = 0.0015      # the values are compared this long before each of the kernel's frames
ECHO_WAIT_S = 0.02       # longest wait, at a hand-over, for the echo of the kernel's last frame
MIN_CYCLE_S = 4 * STOP_MARGIN_S
FRAME_LENGTH = 8         # classic CAN frames
MAX_FRAMES = 256         # frames one BCM task holds at most (the kernel's MAX_NFRAMES)
ENV_SWITCH = "BENCH_KERNEL_PERIODIC"
ECHO_READ_LIMIT = 1 << 16   # frames one look at the echo socket takes at most (it is read every tick)

# linux/can.h and linux/can/raw.h (Python's socket module lacks CAN_INV_FILTER)
CAN_INV_FILTER = 0x20000000
CAN_RAW_JOIN_FILTERS = 6
_FILTER = struct.Struct("=II")
_EXACT_STANDARD = canid.SFF_MASK | canid.EFF | canid.RTR   # mask: this 11-bit data frame and no other
_EXACT_EXTENDED = canid.EFF_MASK | canid.EFF | canid.RTR   # mask: this 29-bit data frame and no other
_clock = time.monotonic   # the kernel's BCM timers run on CLOCK_MONOTONIC too


def _exact(frame_id: int) -> int:
    """The filter mask that takes exactly this identifier's data frames (11- or 29-bit)."""
    return _EXACT_EXTENDED if frame_id & canid.EFF else _EXACT_STANDARD


def _kernel_can_send(slot: Any) -> bool:
    """Whether the kernel may send a restbus message: plain cyclic, at least MIN_CYCLE_S, a classical frame of 8
    bytes or a CAN FD frame, and a counter cycle (E2E) of at most MAX_FRAMES frames."""
    codec = slot.codec
    protection = codec.protection
    return (slot.plain_cyclic and (codec.cycle_time or 0.0) >= MIN_CYCLE_S
            and (bool(codec.frame_id & canid.FD) or codec.length == FRAME_LENGTH)
            and (protection is None or protection.counter_modulo <= MAX_FRAMES))


def _raw_socket() -> socket.socket:
    return socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW)


def _payload(slot: Any, data: bytes) -> bytes:
    """The frame without its E2E fields (counter and CRC cleared) for a protected message, else the frame."""
    protection = slot.codec.protection
    return bytes(data) if protection is None else protection.payload(data)


def counter_cycle(protection: Protection, frame_id: int, data: bytes, first_counter: int) -> list[can.Message]:
    """One frame of one payload per counter value, first_counter, first_counter + 1, ... (modulo the profile's
    counter range), each with its CRC: what the BCM sends in turn."""
    frames = []
    for k in range(protection.counter_modulo):
        frame = bytearray(data)
        protection.protect(frame, first_counter + k)
        frames.append(can.Message(data=frame, **canid.message_kwargs(frame_id)))
    return frames


class _Task:
    __slots__ = ("slot", "frame_id", "task", "payload", "base", "period", "t0", "changes", "stopping",
                 "last_counter", "next_check", "checked")

    def __init__(self, slot: Any, frame_id: int, task: Any, payload: bytes, base: int, t0: float) -> None:
        self.slot = slot                 # the restbus' _Slot
        self.frame_id = frame_id
        self.task = task                 # python-can's CyclicSendTask (a BCM TX_SETUP)
        self.payload = payload
        self.base = base                 # the counter of frame 0 of the sequence
        self.period: float = slot.codec.cycle_time
        self.t0 = t0                     # _clock() when the kernel sent frame 0
        self.changes = 0                 # consecutive cycles whose payload changed
        self.stopping = False            # back to the tick scheduler at the next quiet moment
        self.last_counter: int | None = None   # the counter of the last frame seen back from the kernel
        self.next_check = t0             # _clock() of the next look at this task
        self.checked = 0                 # index of the kernel frame whose values were last checked


class KernelPeriodic:
    """The BCM side of one station's restbus on a socketcan bus."""

    def __init__(self, bus: Any, restbus: Restbus) -> None:
        self.bus = bus
        self.restbus = restbus
        self.slots = {slot.codec.send_id: slot for slot in restbus.slots.values() if _kernel_can_send(slot)}
        self.tasks: dict[int, _Task] = {}
        self._last: dict[int, bytes] = {}
        self._stable: dict[int, int] = {}
        self.enabled = True
        self.started = self.modified = self.stopped = 0
        self.error = ""
        self.pending_echoes: list[tuple[int, bytes, float]] = []
        # Set by the wall clock's wait when one poll() over the stations' sockets found the echo socket empty:
        # the next read is skipped (a system call saved per tick, costly in a UML guest; docs/vcan-lane.md).
        self.echo_idle = False
        # The per-tick look's clock (time.monotonic's scale): the station gives the wall clock's latest read,
        # so that a tick costs no extra read; None: a read of _clock.
        self.clock: Callable[[], float] | None = None
        self.echo = _raw_socket()
        try:
            self.echo.setsockopt(socket.SOL_CAN_RAW, socket.CAN_RAW_FILTER, b"")   # nothing until a task starts
            self.echo.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)   # the log's time: the kernel's send
            if any(frame_id & canid.FD for frame_id in self.slots):
                self.echo.setsockopt(socket.SOL_CAN_RAW, socket.CAN_RAW_FD_FRAMES, 1)
            self.echo.bind((bus.channel,))
            self.echo.setblocking(False)
            bus.socket.setsockopt(socket.SOL_CAN_RAW, CAN_RAW_JOIN_FILTERS, struct.pack("=i", 1))
        except OSError:
            self.echo.close()
            raise
        self._echo_rx = FastReceiver(self.echo)

    @classmethod
    def attach(cls, bus: can.BusABC, restbus: Restbus) -> KernelPeriodic | None:
        """A KernelPeriodic for a socketcan bus without filters of its own (unless switched off by
        BENCH_KERNEL_PERIODIC=0); None for every other bus or when the kernel refuses the sockets."""
        if not plain_socketcan(bus) or os.environ.get(ENV_SWITCH, "1") == "0":
            return None
        try:
            return cls(bus, restbus)
        except OSError as exc:
            log.warning("kernel periodic sending unavailable on %s (%s): the restbus sends every frame itself",
                        getattr(bus, "channel", bus), exc)
            return None

    # -- send side (the station's tick) -------------------------------------------------------------
    def offer(self, frame_id: int, data: bytes, faulty: bool) -> bool:
        """A frame due now (the restbus' schedule); True when the kernel sends it: then the station neither
        sends nor logs it (the log gets the kernel's frame when it comes back)."""
        task = self.tasks.get(frame_id)
        if task is not None:
            if faulty and not task.stopping:
                task.stopping, task.next_check = True, _clock()
            elif not task.stopping and _payload(task.slot, data) != task.payload:
                self._changed(task, data)        # missed by check() (a late tick): on the kernel's next frame
            return True
        slot = self.slots.get(frame_id)
        if slot is None or faulty or not self.enabled:
            return False
        payload = _payload(slot, data)
        if self._last.get(frame_id) == payload:
            stable = self._stable.get(frame_id, 0) + 1
        else:
            stable = 0
            self._last[frame_id] = payload
        self._stable[frame_id] = stable
        if stable < STABLE_CYCLES:
            return False
        return self._start(slot, frame_id, data, payload)

    def check(self, faulty: bool) -> None:
        """Every tick. PRECHECK_S before each of the kernel's frames, the message's values are compared with
        the frames the kernel holds and rewritten when they changed (so a change goes out with that frame,
        as the tick scheduler would send it); a task to stop (sending stopped, a fault plan active, too many
        changes) is deleted at its next quiet moment."""
        if not self.tasks:
            return
        now = _clock() if self.clock is None else self.clock()
        for task in list(self.tasks.values()):
            if (faulty or not task.slot.enabled) and not task.stopping:
                task.stopping, task.next_check = True, now
            if now >= task.next_check:
                self._look(task, now)

    def _look(self, task: _Task, now: float) -> None:
        period = task.period
        index = int((now - task.t0) / period) + 1          # the kernel's next frame
        t_next = task.t0 + index * period
        if task.stopping:
            if self.clock is not None:   # the margins need the present, not the tick's latest read (rare)
                now = _clock()
                index = int((now - task.t0) / period) + 1
                t_next = task.t0 + index * period
            if STOP_MARGIN_S <= now - (t_next - period) and t_next - now >= STOP_MARGIN_S:
                self._stop(task)
            else:
                task.next_check = t_next + STOP_MARGIN_S if t_next - now < STOP_MARGIN_S else now
            return
        if t_next - now <= PRECHECK_S and task.checked != index:
            task.checked = index
            slot, counter = task.slot, task.slot.counter
            try:
                data = self.restbus.build(slot)      # the values now (its counter is the kernel's business)
            except Exception:                      # a bad value: the restbus' own build stops the sender at due
                data = None
            slot.counter = counter
            stopping = False
            if data is not None and _payload(slot, data) != task.payload:
                stopping = self._changed(task, data)
            else:
                task.changes = 0
            if stopping:
                task.next_check = now
                return
            index += 1
        task.next_check = task.t0 + index * period - PRECHECK_S

    def _changed(self, task: _Task, data: bytes) -> bool:
        """Rewrite the task's frames; whether the task is now to stop."""
        task.changes += 1
        self._modify(task, data)
        if task.changes >= CHANGES_TO_STOP:
            task.stopping, task.next_check = True, _clock()
        return task.stopping

    def _frames(self, slot: Any, frame_id: int, data: bytes, base: int) -> list[can.Message]:
        if slot.codec.protection is not None:
            return counter_cycle(slot.codec.protection, frame_id, data, base)
        return [can.Message(data=data, **canid.message_kwargs(frame_id))]

    def _start(self, slot: Any, frame_id: int, data: bytes, payload: bytes) -> bool:
        protection = slot.codec.protection
        base = 0 if protection is None else protection.counter_of(data)
        frames = self._frames(slot, frame_id, data, base)
        self.tasks[frame_id] = placeholder = _Task(slot, frame_id, None, payload, base, _clock())
        try:
            self._set_filters()   # before the kernel's first frame: it must reach the echo socket
            task = self.bus.send_periodic(frames, slot.codec.cycle_time)
        except (can.CanError, OSError, ValueError, NotImplementedError) as exc:
            del self.tasks[frame_id]
            try:
                self._set_filters()
            except OSError:
                pass
            self._disable(f"send_periodic of {slot.codec.name} failed: {exc}")
            return False
        placeholder.task = task
        placeholder.t0 = placeholder.next_check = _clock()
        self.started += 1
        return True

    def _modify(self, task: _Task, data: bytes) -> None:
        slot = task.slot
        try:
            task.task.modify_data(self._frames(slot, task.frame_id, data, task.base))
        except (can.CanError, OSError, ValueError) as exc:
            task.stopping, task.next_check = True, _clock()
            self._disable(f"modify_data of {slot.codec.name} failed: {exc}")
            return
        task.payload = _payload(slot, data)
        self.modified += 1

    def _stop(self, task: _Task) -> None:
        """Delete the BCM task (no frame in flight) and hand the counter back to the restbus."""
        try:
            task.task.stop()
        except (can.CanError, OSError) as exc:
            self._disable(f"stopping the task of {task.slot.codec.name} failed: {exc}")
        self.pending_echoes = list(self.echoes())    # its last frames, before its filter goes
        self._await_last_echo(task)
        del self.tasks[task.frame_id]
        try:
            self._set_filters()
        except OSError as exc:
            self._disable(f"setting the socket filters failed: {exc}")
        protection = task.slot.codec.protection
        if protection is not None:
            last = task.base - 1 if task.last_counter is None else task.last_counter
            task.slot.counter = protection.next_counter(last % protection.counter_modulo)
        self._stable[task.frame_id] = 0
        self.stopped += 1

    def _await_last_echo(self, task: _Task) -> None:
        """The kernel's loopback of its last frame may still be on its way to the echo socket (a busy machine
        delivers it from a softirq that may run late): without it the restbus would send that frame's
        counter again. The kernel started at t0 and sends one frame per period, so by now it can have
        sent frame `possible - 1` at most; wait (sleeping, which lets the kernel deliver) up to ECHO_WAIT_S for
        that frame's echo. When it does not come, the kernel did not send it (the stop came first)."""
        protection = task.slot.codec.protection
        if protection is None:
            return
        possible = int((_clock() - task.t0) / task.period) + 1
        expected = (task.base + possible - 1) % protection.counter_modulo
        deadline = time.monotonic() + ECHO_WAIT_S
        while task.last_counter != expected and time.monotonic() < deadline:
            time.sleep(0.0005)
            self.pending_echoes += list(self._read_echoes())

    def _disable(self, why: str) -> None:
        if self.enabled:   # said once: from now on the restbus sends every frame itself
            log.warning("kernel periodic sending off on %s: %s; the restbus sends every frame itself",
                        getattr(self.bus, "channel", self.bus), why)
        self.enabled = False
        self.error = why

    def _set_filters(self) -> None:
        """The echo socket takes exactly the kernel's identifiers; the bus socket everything else."""
        ids = sorted(self.tasks)
        self.echo.setsockopt(socket.SOL_CAN_RAW, socket.CAN_RAW_FILTER,
                             b"".join(_FILTER.pack(i & canid.CAN_ID, _exact(i)) for i in ids))
        inverted = [_FILTER.pack((i & canid.CAN_ID) | CAN_INV_FILTER, _exact(i)) for i in ids] or [_FILTER.pack(0, 0)]
        self.bus.socket.setsockopt(socket.SOL_CAN_RAW, socket.CAN_RAW_FILTER, b"".join(inverted))

    # -- receive side (the station's tick) ------------------------------------------------------------
    def echoes(self) -> Iterator[tuple[int, bytes, float]]:
        """The frames the kernel sent since the last call, as (identifier, data, receive timestamp), in order."""
        if self.pending_echoes:
            pending, self.pending_echoes = self.pending_echoes, []
            yield from pending
        yield from self._read_echoes()

    def _read_echoes(self) -> Iterator[tuple[int, bytes, float]]:
        """What the echo socket holds now (noting each task's last counter)."""
        if not self.tasks:
            return      # the echo socket's filter is empty
        if self.echo_idle:
            self.echo_idle = False
            return      # found empty just now (bench.sim.clock.WallClock.wait_until)
        tasks = self.tasks
        for frame in self._echo_rx.frames(0.0, ECHO_READ_LIMIT):
            frame_id, data = frame.frame_id, frame.data
            task = tasks.get(frame_id)
            if task is not None:
                codec = task.slot.codec
                if codec.protection is not None and len(data) in (codec.length, codec.frame_length):  # FD: a DLC's
                    task.last_counter = codec.protection.counter_of(data)
            yield frame_id, data, frame.timestamp
