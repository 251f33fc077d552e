"""Opening buses: the embedded bus (in process, virtual time: the default) or any python-can interface.

`VirtualTimeBus` is a python-can `BusABC` registered as the interface `embedded`. Unlike
python-can's `virtual` interface it keeps the sender's timestamp (the bench's virtual time; it never
stamps the wall clock) and has no threads of its own: frames are handed over in the order they were
sent, so that a campaign gives the same frame sequence on every run. Otherwise it behaves as python-can's
buses do (docs/python-can-conformance.md): every receiver gets its own copy of a frame, stamped with the
receiving bus's channel and `is_rx`; `recv(timeout)` sleeps until a frame arrives; a shut-down bus raises
`can.CanOperationError`; a bus dropped without `shutdown()` is collected and stops receiving.
"""

from __future__ import annotations

import ctypes
import logging
import socket
import struct
import sys
import threading
import time
import weakref
from collections import deque
from collections.abc import Iterator
from typing import Any, final

import can

from bench.busopts import BusOptions
from bench.capabilities import takes_hop_limit
from bench.errors import ConfigError

log = logging.getLogger(__name__)

#: The embedded bus's one name (command line, pytest options, the report, python-can's entry point): not python-can's
#: `virtual`, which names python-can's own in-process bus (real time) and reaches it.
EMBEDDED = "embedded"
#: python-can's in-process bus: like the embedded bus it reaches only its own process.
PYTHON_CAN_VIRTUAL = "virtual"
#: Earlier names of the embedded bus, refused with one line naming the new one.
RENAMED = {"bench_virtual": EMBEDDED}

#: udp_multicast must never leave this host (Developers' guide: hop limit 0).
UDP_MULTICAST_HOP_LIMIT = 0
#: python-can's default IPv4 group for udp_multicast (an administratively scoped address).
UDP_MULTICAST_DEFAULT_GROUP = "239.74.163.2"

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


@final   # no subclasses: the receive paths test `type(item) is VirtualFrame`, the fast test
class VirtualFrame:
    """A classic 11-bit data frame sent with `VirtualTimeBus.send_raw`: what a station reads of a frame
    (the fields of can.Message it needs, as bench.socketcan_rx.RawFrame), one object shared by every
    receiver, never changed; a python-can `recv` turns it into the receiver's own can.Message."""

    __slots__ = ("timestamp", "arbitration_id", "data")
    is_extended_id = False
    is_error_frame = False

    def __init__(self, timestamp: float, arbitration_id: int, data: bytes) -> None:
        self.timestamp = timestamp
        self.arbitration_id = arbitration_id
        self.data = data


def _message(frame: VirtualFrame, channel: Any, is_rx: bool) -> can.Message:
    """A receiver's can.Message of a raw frame, as `_copy` makes one of a sent can.Message."""
    msg = _new_message(can.Message)
    msg.timestamp = frame.timestamp
    msg.arbitration_id = frame.arbitration_id
    msg.is_extended_id = False
    msg.is_remote_frame = False
    msg.is_error_frame = False
    msg.channel = channel
    msg.dlc = len(frame.data)
    msg.data = bytearray(frame.data)
    msg.is_fd = False
    msg.is_rx = is_rx
    msg.bitrate_switch = False
    msg.error_state_indicator = False
    return msg


class _Inbox(deque[can.Message | VirtualFrame]):
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
        self.receive_own_messages = self._own = bool(receive_own_messages)   # bench/capabilities.py asks it
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

    def send_raw(self, t: float, arbitration_id: int, data: bytes) -> None:
        """Send a classic 11-bit data frame stamped `t` without a can.Message (the stations' hot path: one
        shared VirtualFrame for every receiver; python-can's `recv` still gives each its own can.Message)."""
        mine = self._inbox
        if mine.closed:
            raise can.CanOperationError(f"{self.channel_info} is shut down")
        frame = VirtualFrame(t, arbitration_id, bytes(data))
        for inbox in self._net.inboxes:
            if inbox is mine:
                if not self._own:
                    continue
                inbox.append(_message(frame, inbox.channel, False))
            else:
                inbox.append(frame)
            if inbox.waiters:
                inbox.wake()

    def raw_frames(self, timeout: float, limit: int) -> Iterator[VirtualFrame | can.Message]:
        """Up to `limit` pending frames as they were sent (a VirtualFrame or the receiver's can.Message copy,
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
            if type(item) is VirtualFrame:
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
        if type(item) is VirtualFrame:
            return _message(item, inbox.channel, True), False
        return item, False

    def shutdown(self) -> None:
        super().shutdown()    # periodic tasks first, as python-can's virtual bus does
        self._finalizer()     # off the channel now, not when collected; wakes a recv() waiting on it


#: Bytes of socket receive buffer for udp_multicast: every frame is one datagram (about 1 KiB of kernel
#: memory each), so the default ~200 KiB holds only ~200 frames, a tenth of a second of a loaded bus; a
#: receiver that pauses longer (garbage collection, a busy core) would lose frames. The kernel caps the
#: request at net.core.rmem_max.
UDP_RECEIVE_BUFFER = 8 * 1024 * 1024


#: s between the two passes that empty a new udp_multicast socket of other groups' datagrams (_drop_queued)
DROP_SETTLE_S = 0.002
#: Linux's IP_MULTICAST_ALL (linux/in.h; socket.IP_MULTICAST_ALL where Python defines it).
IP_MULTICAST_ALL = getattr(socket, "IP_MULTICAST_ALL", 49)
#: Linux's IPV6_MULTICAST_ALL (linux/in6.h, since Linux 4.20; Python defines no name for it).
IPV6_MULTICAST_ALL = getattr(socket, "IPV6_MULTICAST_ALL", 29)


def _tune_udp_socket(bus: can.BusABC) -> None:
    """python-can's UdpMulticastBus has no options for these; set them on its socket (a private attribute,
    isolated here; without them the bus works, but worse):
    - SO_RCVBUF: see UDP_RECEIVE_BUFFER;
    - only its own group: python-can binds the socket to the wildcard address on its fixed port (43113), and
      Linux then delivers to it every group joined on that port by any socket of the host, so two benches on
      two groups would hear each other's frames. Off for both families: IP_MULTICAST_ALL = 0 on an IPv4
      socket; on an IPv6 socket IPV6_MULTICAST_ALL = 0 (the IPv6 groups) and IP_MULTICAST_ALL = 0 too,
      because python-can's IPv6 socket is dual-stack ([::], IPV6_V6ONLY off) and also receives the IPv4
      groups of its port while that option is on. Then the kernel delivers only the group the socket joined;
    - a socket filter that keeps only datagrams addressed to that group (_only_to_group): a datagram sent to
      the port itself (unicast, broadcast: any process or host may send one) reaches a socket bound so too, and
      python-can would decode it as a frame of this bus;
    what came before is dropped (_drop_queued)."""
    multicast = getattr(bus, "_multicast", None)
    sock = getattr(multicast, "_socket", None)
    if sock is None:
        return
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, UDP_RECEIVE_BUFFER)
    if not sys.platform.startswith("linux"):
        return
    group = getattr(multicast, "group", None)
    if isinstance(group, str):
        _only_to_group(sock, group)
    if sock.family == socket.AF_INET6:
        try:
            sock.setsockopt(socket.IPPROTO_IPV6, IPV6_MULTICAST_ALL, 0)
        except OSError as exc:   # a kernel before 4.20: the socket would hear every IPv6 group of the host
            raise can.CanInitializationError(
                f"cannot limit the socket to its own IPv6 group (IPV6_MULTICAST_ALL, Linux 4.20 or later: "
                f"{exc.strerror}); use an IPv4 group") from None
    sock.setsockopt(socket.IPPROTO_IP, IP_MULTICAST_ALL, 0)
    _drop_queued(sock)


#: Linux's SO_ATTACH_FILTER (asm-generic/socket.h) and classic BPF (linux/filter.h): load a 32-bit word at an
#: offset from the network header, jump if equal, return (0 drops the datagram, 0xFFFFFFFF keeps all of it).
SO_ATTACH_FILTER = getattr(socket, "SO_ATTACH_FILTER", 26)
_SKF_NET_OFF = -0x100000
_BPF_LD_W_ABS, _BPF_JEQ_K, _BPF_RET_K = 0x20, 0x15, 0x06
_DESTINATION_OFFSET = {socket.AF_INET: 16, socket.AF_INET6: 24}   # in the IPv4 and the IPv6 header


def _only_to_group(sock: socket.socket, group: str) -> None:
    """Attach a classic BPF filter that drops every datagram whose destination address is not `group`: the
    kernel then queues nothing else (an IPv4 datagram on python-can's dual-stack IPv6 socket has no such
    address where the filter looks, and is dropped too). A filter the kernel refuses is logged, not fatal: the
    multicast options above keep other groups out already."""
    family = sock.family
    address = str(socket.getaddrinfo(group, None, family, socket.SOCK_DGRAM)[0][4][0])   # the group, as python-can
    words = struct.unpack(f"!{4 if family == socket.AF_INET6 else 1}I", socket.inet_pton(family, address))
    code = []
    for i, word in enumerate(words):
        code.append((_BPF_LD_W_ABS, 0, 0, (_SKF_NET_OFF + _DESTINATION_OFFSET[family] + 4 * i) & 0xFFFFFFFF))
        code.append((_BPF_JEQ_K, 0, 2 * (len(words) - i - 1) + 1, word))   # not equal: on to the drop
    code += [(_BPF_RET_K, 0, 0, 0xFFFFFFFF), (_BPF_RET_K, 0, 0, 0)]
    program = ctypes.create_string_buffer(b"".join(struct.pack("@HBBI", *op) for op in code))
    try:   # struct sock_fprog {unsigned short len; struct sock_filter *filter;}; the kernel copies the program
        sock.setsockopt(socket.SOL_SOCKET, SO_ATTACH_FILTER,
                        struct.pack("@HP", len(code), ctypes.addressof(program)))
    except OSError as exc:
        log.warning("udp_multicast %s: no socket filter (%s); datagrams sent to the port itself are read too",
                    group, exc)


def _drop_queued(sock: socket.socket) -> None:
    """Discard what the socket received between its bind and the settings that limit it to its group: other
    groups' frames (with another bench on this host, 48 of 200 fresh buses read a foreign frame first); this
    bus is not in use yet.
    Twice, DROP_SETTLE_S apart: a datagram the kernel had already matched to this socket before the setting may
    still be on its way into the queue while the first pass empties it (1 of 100 fresh buses read one in a CI run)."""
    dropped = 0
    for settle in (DROP_SETTLE_S, 0.0):
        while True:
            try:
                sock.recv(65535, socket.MSG_DONTWAIT)
            except (BlockingIOError, InterruptedError):
                break
            dropped += 1
        time.sleep(settle)
    if dropped:
        log.debug("udp_multicast: %d datagram(s) received before the socket was limited to its group, dropped",
                  dropped)


def is_embedded(interface: str) -> bool:
    """The embedded bus: in process, in virtual time (the only bus on which the bench's time is not the wall clock)."""
    return interface == EMBEDDED


def in_process(interface: str) -> bool:
    """A bus that only this process can reach (the embedded bus, python-can's virtual bus)."""
    return interface in (EMBEDDED, PYTHON_CAN_VIRTUAL)


def known_interfaces() -> list[str]:
    return sorted({EMBEDDED, *can.interfaces.VALID_INTERFACES})


def check_interface(interface: str, option: str = "--interface") -> None:
    """An interface name the bench can open: the embedded bus or a python-can interface; an old name of the
    embedded bus is one line naming the new one."""
    if interface in RENAMED:
        raise ConfigError(f"{option} {interface}: renamed to {RENAMED[interface]} (the bench's in-process "
                          "virtual-time bus)")
    if not is_embedded(interface) and interface not in can.interfaces.VALID_INTERFACES:
        raise ConfigError(f"{option}: unknown python-can interface {interface!r} "
                          f"(known: {', '.join(known_interfaces())})")


def open_bus(interface: str, channel: str | None, options: BusOptions | None = None) -> can.BusABC:
    """Open a bus by python-can interface name with `options` (bitrate, CAN FD, [bus] table); errors name the
    interface and channel. The embedded bus has no bit timing: it ignores `options`."""
    check_interface(interface)
    if is_embedded(interface):
        return VirtualTimeBus(channel=channel or "bench")
    kwargs: dict[str, Any] = options.kwargs() if options is not None else {}
    if takes_hop_limit(interface):   # an IP multicast bus (udp_multicast): asked of its class's parameters
        kwargs["hop_limit"] = UDP_MULTICAST_HOP_LIMIT   # never a user's choice: the frames stay on this host
        channel = channel or UDP_MULTICAST_DEFAULT_GROUP
    if interface == "socketcan":
        kwargs.setdefault("receive_own_messages", False)
    if not channel:
        raise ConfigError(f"interface {interface!r} needs a channel (--channel)")
    try:
        bus = can.Bus(interface=interface, channel=channel, **kwargs)
        try:
            _tune_udp_socket(bus)   # a bus without python-can's multicast socket is left alone
        except BaseException:
            bus.shutdown()
            raise
        return bus
    except Exception as exc:   # drivers raise anything (vendor DLL errors, TypeError on a bad [bus] key)
        message = f"cannot open interface {interface!r} channel {channel!r}: {type(exc).__name__}: {exc}"
        _forget_half_open(exc)
        raise ConfigError(message.replace("\n", " ")) from None


def _forget_half_open(exc: BaseException) -> None:
    """A driver that fails inside its __init__ leaves a half-built bus whose finaliser later logs "was not
    properly shut down" under the one-line error; there is nothing to shut down, so mark it so (python-can's
    BusABC flag)."""
    tb = exc.__traceback__
    while tb is not None:
        candidate = tb.tb_frame.f_locals.get("self")
        if isinstance(candidate, can.BusABC):
            candidate._is_shutdown = True
        tb = tb.tb_next


def probe_bus(interface: str, channel: str | None, options: BusOptions | None = None) -> None:
    """Open the bus once and close it: a bus that cannot be opened stops a run before its first case (an
    in-process bus has nothing to probe: the run opens it on a channel of its own)."""
    if in_process(interface):
        check_interface(interface)
        return
    open_bus(interface, channel, options).shutdown()


def check_channel(interface: str, channel: str | None, option: str = "--channel") -> None:
    """`--channel` on the embedded bus is a mistake (the user meant another bus), not a no-op."""
    if is_embedded(interface) and channel:
        raise ConfigError(f"{option} {channel}: the embedded bus (in process, virtual time) has no channels; "
                          "name the interface too (e.g. --interface socketcan --channel vcan0)")
