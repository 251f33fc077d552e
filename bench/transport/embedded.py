"""The embedded bus: the bench's own bus, in process and in virtual time (the default).

`VirtualTimeBus` is a python-can `BusABC` registered as the interface `embedded`. Unlike
python-can's `virtual` interface it keeps the sender's timestamp (the bench's virtual time; it never
stamps the wall clock) and has no threads of its own: frames are handed over in the order they were
sent, so that a campaign gives the same frame sequence on every run. Otherwise it behaves as python-can's
buses do (docs/python-can-conformance.md): every receiver gets its own copy of a frame, stamped with the
receiving bus's channel and `is_rx`; `recv(timeout)` sleeps until a frame arrives; a shut-down bus raises
`can.CanOperationError`; a bus dropped without `shutdown()` is collected and stops receiving.
"""

from __future__ import annotations

import threading
import time
import weakref
from collections import deque
from collections.abc import Iterable, Iterator
from typing import Any

import can

from bench import canid
from bench.transport.base import Frame, PythonCanTransport, ReceivedFrame

_new_message = object.__new__


def _copy(msg: can.Message, channel: Any, is_rx: bool) -> can.Message:
    """The receiver's own copy of `msg` (fresh data buffer), with its channel and direction.

    Not `copy.deepcopy`: this is the bench's hot path (one copy per frame and receiver), and a plain
    slot copy costs a fraction of Message(...) or deepcopy."""
    copy = _new_message(can.Message)
    copy.timestamp = msg.timestamp
    copy.arbitration_id = msg.arbitration_id
    copy.is_extended_id = msg.is_extended_id
    copy.is_remote_frame = msg.is_remote_frame
    copy.is_error_frame = msg.is_error_frame
    copy.channel = channel
    copy.dlc = msg.dlc
    copy.data = bytearray(msg.data)
    copy.is_fd = msg.is_fd
    copy.is_rx = is_rx
    copy.bitrate_switch = msg.bitrate_switch
    copy.error_state_indicator = msg.error_state_indicator
    return copy


def _message(frame: Frame, channel: Any, is_rx: bool) -> can.Message:
    """A receiver's can.Message of a raw frame, as `_copy` makes one of a sent can.Message."""
    msg = _new_message(can.Message)
    msg.timestamp = frame.timestamp
    frame_id = frame.frame_id
    msg.arbitration_id = canid.arbitration_id(frame_id)
    msg.is_extended_id = bool(frame_id & canid.EFF)
    msg.is_remote_frame = bool(frame_id & canid.RTR)
    msg.is_error_frame = bool(frame_id & canid.ERR)
    msg.channel = channel
    msg.dlc = len(frame.data)
    msg.data = bytearray(frame.data)
    msg.is_fd = bool(frame_id & canid.FD)
    msg.is_rx = is_rx
    msg.bitrate_switch = bool(frame_id & canid.BRS)
    msg.error_state_indicator = bool(frame_id & canid.ESI)
    return msg


class _Inbox(deque[can.Message | Frame]):
    """One bus's pending frames. The channel registry holds inboxes, never buses, so a dropped bus is
    collected. `qsize()`/`empty()` as python-can's virtual bus exposes its `queue`."""

    __slots__ = ("channel", "closed", "waiters", "ready")

    def __init__(self, channel: Any) -> None:
        super().__init__()
        self.channel = channel
        self.closed = False
        self.waiters = 0                     # threads sleeping in recv: only then does send() notify
        self.ready = threading.Condition(threading.Lock())

    def qsize(self) -> int:
        return len(self)

    def empty(self) -> bool:
        return not self

    def wake(self) -> None:
        with self.ready:
            self.ready.notify_all()


class _Channel:
    """The inboxes on one channel name; `inboxes` is replaced, never changed, so send() reads it without a lock."""

    __slots__ = ("inboxes",)

    def __init__(self) -> None:
        self.inboxes: tuple[_Inbox, ...] = ()


_registry: dict[str, _Channel] = {}
_registry_lock = threading.Lock()


def _join(name: str, inbox: _Inbox) -> _Channel:
    with _registry_lock:
        channel = _registry.get(name)
        if channel is None:
            channel = _registry[name] = _Channel()
        channel.inboxes = (*channel.inboxes, inbox)
        return channel


def _leave(name: str, inbox: _Inbox) -> None:
    """Take `inbox` off its channel (idempotent; also the finaliser of a bus dropped without shutdown)."""
    inbox.closed = True
    with _registry_lock:
        channel = _registry.get(name)
        if channel is not None:
            channel.inboxes = tuple(other for other in channel.inboxes if other is not inbox)
            if not channel.inboxes:
                del _registry[name]
    inbox.clear()
    inbox.wake()


class VirtualTimeBus(can.BusABC):
    """An in-process bus whose instances on the same channel receive each other's frames."""

    def __init__(self, channel: Any = "bench", receive_own_messages: bool = False, **kwargs: Any) -> None:
        super().__init__(channel=channel, **kwargs)
        self.channel_info = f"bench virtual-time bus {channel!r}"
        self._channel_name = str(channel)
        self.receive_own_messages = self._own = bool(receive_own_messages)   # capabilities.py asks it
        self._inbox = _Inbox(channel)
        self.queue = self._inbox              # python-can's virtual bus name for it (qsize, empty)
        self._net = _join(self._channel_name, self._inbox)
        self._finalizer = weakref.finalize(self, _leave, self._channel_name, self._inbox)

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        mine = self._inbox
        if mine.closed:
            raise can.CanOperationError(f"{self.channel_info} is shut down")
        own = self._own
        for inbox in self._net.inboxes:
            if inbox is mine:
                if not own:
                    continue
                inbox.append(_copy(msg, inbox.channel, False))
            else:
                inbox.append(_copy(msg, inbox.channel, True))
            if inbox.waiters:
                inbox.wake()

    def send_raw(self, t: float, frame_id: int, data: bytes) -> None:
        """Send a frame (its frame_id: bench.canid) stamped `t` without a can.Message (the stations' hot path: one
        shared Frame for every receiver; python-can's `recv` still gives each its own can.Message)."""
        mine = self._inbox
        if mine.closed:
            raise can.CanOperationError(f"{self.channel_info} is shut down")
        frame = Frame(t, frame_id, bytes(data))
        for inbox in self._net.inboxes:
            if inbox is mine:
                if not self._own:
                    continue
                inbox.append(_message(frame, inbox.channel, False))
            else:
                inbox.append(frame)
            if inbox.waiters:
                inbox.wake()

    def raw_frames(self, timeout: float, limit: int) -> Iterator[Frame | can.Message]:
        """Up to `limit` pending frames as they were sent (a Frame or the receiver's can.Message copy,
        both with the fields a station reads; python-can's filters are not applied): the first may be waited
        for up to `timeout` s, the rest only if already here."""
        inbox = self._inbox
        count = 0
        if not inbox and timeout > 0.0:
            first, _ = self._recv_internal(timeout)
            if first is None:
                return
            yield first
            count = 1
        while inbox and count < limit:
            try:
                frame = inbox.popleft()
            except IndexError:   # another thread took it first
                return
            yield frame
            count += 1
        if count < limit and inbox.closed:   # as recv: a shut-down bus raises once it has nothing left
            raise can.CanOperationError(f"{self.channel_info} is shut down")

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        inbox = self._inbox
        if inbox:
            item = inbox.popleft()
            if type(item) is Frame:
                return _message(item, inbox.channel, True), False
            return item, False
        if inbox.closed:
            raise can.CanOperationError(f"{self.channel_info} is shut down")
        if timeout is not None and timeout <= 0.0:
            return None, False
        deadline = None if timeout is None else time.monotonic() + timeout
        with inbox.ready:
            inbox.waiters += 1
            try:
                while not inbox:
                    if inbox.closed:
                        raise can.CanOperationError(f"{self.channel_info} is shut down")
                    left = None if deadline is None else deadline - time.monotonic()
                    if left is not None and left <= 0.0:
                        return None, False
                    inbox.ready.wait(left)
            finally:
                inbox.waiters -= 1
        try:
            item = inbox.popleft()
        except IndexError:   # another thread took it first
            return None, False
        if type(item) is Frame:
            return _message(item, inbox.channel, True), False
        return item, False

    def shutdown(self) -> None:
        super().shutdown()    # periodic tasks first, as python-can's virtual bus does
        self._finalizer()     # off the channel now, not when collected; wakes a recv() waiting on it


class EmbeddedTransport(PythonCanTransport):
    """The embedded bus for a station: frames as bytes both ways, no can.Message each (`send_raw`,
    `raw_frames`); an empty inbox costs a poll nothing (most ticks of a plant)."""

    receive_stamped = False   # a frame carries its sender's bench time; the station takes the time of reading

    def __init__(self, bus: VirtualTimeBus) -> None:
        super().__init__(bus)
        self._inbox = bus.queue
        self._raw_frames = bus.raw_frames
        self.send = bus.send_raw   # type: ignore[method-assign]  # hot path: no call in between

    def frames(self, timeout: float, limit: int) -> Iterable[ReceivedFrame]:
        inbox = self._inbox
        if not inbox and timeout <= 0.0 and not inbox.closed:
            return ()   # nothing pending, nothing to wait for: what raw_frames would find
        return self._raw_frames(timeout, limit)
