"""bench/transport/udp.py: a udp_multicast bus hears its own group only, from its first read on, while another bench
sends on another group of this host (python-can binds every such socket to one port on the wildcard address),
for IPv4 and IPv6 groups alike (issue 25, acceptance 1).

Found by tests/bench/cli/test_replay.py failing under load beside other benches: the receiver's first frames were
another group's (0x121, 0x122 ... of a running `bench plant`), queued between the socket's bind and
IP_MULTICAST_ALL = 0 (48 of 200 fresh buses before the fix). On IPv6 groups every bus heard every group of the
port until IPV6_MULTICAST_ALL = 0 (issue 25: `bench monitor` showed another bench's PLANT_Status).

Groups: IPv4 administratively scoped 239.255.x.y and IPv6 link-local ff12::..., all with the bench's hop limit 0
(bench.transport.udp.UDP_MULTICAST_HOP_LIMIT): nothing leaves this host."""

from __future__ import annotations

import re
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator

import can
import pytest

from bench.config import RunSettings, load_config
from bench.session import BenchSession
from bench.transport import open_bus
from bench.transport.busopts import BusOptions
from tests.fakes import ipv4_group, ipv6_available, ipv6_group
from tests.repo import ROOT

OPENS = 100

# Another bench on this host: a frame on its group every 0.1 ms for at most 60 s (the test stops it sooner).
SENDER = """
import sys, time
import can
from bench.transport import open_bus
bus = open_bus("udp_multicast", sys.argv[1])
end = time.monotonic() + 60.0
while time.monotonic() < end:
    bus.send(can.Message(arbitration_id=0x121, data=bytes(8), is_extended_id=False))
    time.sleep(0.0001)
"""


@pytest.fixture(params=["IPv4", "IPv6"])
def group(request: pytest.FixtureRequest) -> Callable[[], str]:
    """A maker of fresh groups of one family."""
    if request.param == "IPv6":
        ipv6_available()
        return ipv6_group
    return ipv4_group


def _two(group: Callable[[], str]) -> tuple[str, str]:
    first, second = group(), group()
    while second == first:
        second = group()
    return first, second


def test_a_fresh_bus_reads_no_frame_of_another_group(group: Callable[[], str]) -> None:
    theirs, ours = _two(group)
    sender = subprocess.Popen([sys.executable, "-c", SENDER, theirs], cwd=ROOT)
    try:
        with open_bus("udp_multicast", theirs) as watch:      # the other bench is sending: no guessed sleep
            assert watch.recv(30.0) is not None, "the other bench sent nothing within 30 s"
        foreign = []
        for _ in range(OPENS):
            bus = open_bus("udp_multicast", ours)
            try:
                while (msg := bus.recv(0.0)) is not None:
                    foreign.append(msg)
            finally:
                bus.shutdown()
    finally:
        sender.kill()
        sender.wait()
    assert foreign == [], f"{len(foreign)} frames of group {theirs} read on {ours}: {foreign[:3]}"


def test_a_fresh_bus_still_reads_its_own_group(group: Callable[[], str]) -> None:
    """Dropping what came before the bus was limited to its group loses nothing sent after it was opened."""
    channel = group()
    with open_bus("udp_multicast", channel) as receiver, open_bus("udp_multicast", channel) as sender:
        sender.send(can.Message(arbitration_id=0x321, data=b"\x05", is_extended_id=False))
        msg = receiver.recv(5.0)
    assert msg is not None and (msg.arbitration_id, bytes(msg.data)) == (0x321, b"\x05")


# -- two benches side by side ----------------------------------------------------------------------------------
FRAMES = 200   # per bench


def _drain(bus: can.BusABC, quiet: float = 0.3) -> list[can.Message]:
    """Every frame the bus has, until none came for `quiet` s."""
    got = []
    while (msg := bus.recv(quiet)) is not None:
        got.append(msg)
    return got


def _bench_pairs(groups: list[str]) -> None:
    """A sender and a receiver per group (two benches' buses, opened as the bench opens them), the senders
    interleaved; each receiver must read all of its own group's frames (identifier = its bench) and none of the
    other's."""
    buses = [(open_bus("udp_multicast", g), open_bus("udp_multicast", g)) for g in groups]
    try:
        for i in range(FRAMES):
            for bench, (sender, _) in enumerate(buses):
                sender.send(can.Message(arbitration_id=0x100 + bench, data=i.to_bytes(2, "big"),
                                        is_extended_id=False))
        for bench, (sender, receiver) in enumerate(buses):
            seen = _drain(receiver)
            foreign = [m for m in seen if m.arbitration_id != 0x100 + bench]
            assert foreign == [], (f"bench {bench} on {groups[bench]} received {len(foreign)} frames of another "
                                   f"group: {foreign[:3]}")
            assert len(seen) == FRAMES, f"bench {bench} on {groups[bench]}: {len(seen)} of its {FRAMES} frames"
            echoes = _drain(sender, 0.0)   # a sender hears its own frames back (IP_MULTICAST_LOOP), no other's
            assert {m.arbitration_id for m in echoes} <= {0x100 + bench}, echoes[:3]
    finally:
        for pair in buses:
            for bus in pair:
                bus.shutdown()


def test_two_benches_on_two_groups_hear_only_their_own(group: Callable[[], str]) -> None:
    _bench_pairs(list(_two(group)))


def test_an_ipv4_bench_and_an_ipv6_bench_hear_only_their_own() -> None:
    """python-can's IPv6 socket is dual-stack on the same port: it must not read the IPv4 group either."""
    ipv6_available()
    _bench_pairs([ipv4_group(), ipv6_group()])


@pytest.fixture
def two_plants(group: Callable[[], str]) -> Iterator[list[BenchSession]]:
    """Two `bench plant`s (BenchSession role "plant", as bench/cli/plant.py builds it) on two groups."""
    project = load_config()
    sessions: list[BenchSession] = []
    try:
        for channel in _two(group):
            sessions.append(BenchSession(project, RunSettings(interface="udp_multicast", channel=channel),
                                         role="plant"))
        yield sessions
    finally:
        for session in sessions:
            session.close()


def test_two_plants_side_by_side_apply_nothing_of_each_other(two_plants: list[BenchSession]) -> None:
    """Issue 25: a run beside two other benches had 462 725 invalid frames and "two senders" on every identifier.
    Here two plants send every message of the network on two groups, turn about for 1 s of real time each; a
    plant receives nothing at all but its own frames' echoes, so every frame it counts as received is foreign."""
    for session in two_plants:
        session.start()
    deadline = time.monotonic() + 1.0
    while time.monotonic() < deadline:
        for session in two_plants:      # in turn: the other's socket holds what reached it meanwhile
            session.run_until(session.now() + 0.05)
    for session in two_plants:
        plant = session.plant
        assert plant is not None and plant.sent > 100, "the plant sent nothing: the test would prove nothing"
        monitor = plant.monitor
        received = monitor.frames - plant.sent
        assert (received, monitor.invalid_frames, sorted(monitor.duplicates)) == (0, 0, []), (
            f"the plant on {session.channel} received {received} frames of the other group, "
            f"{monitor.invalid_frames} invalid, two senders on {len(monitor.duplicates)} identifiers")


def test_bench_monitor_shows_only_its_group(group: Callable[[], str]) -> None:
    """`bench monitor` on one group while another bench sends on another: "frames 0" (issue 25: a monitor on one
    IPv6 group showed another bench's PLANT_Status); on the sender's group it does count them."""
    theirs, ours = _two(group)
    stop = threading.Event()

    def other_bench() -> None:
        with open_bus("udp_multicast", theirs) as bus:
            while not stop.wait(0.001):
                bus.send(can.Message(arbitration_id=0x121, data=bytes(8), is_extended_id=False))

    sender = threading.Thread(target=other_bench, daemon=True)
    sender.start()
    try:
        counts = {}
        for channel in (ours, theirs):
            shown = subprocess.run([sys.executable, "-m", "bench", "monitor", "--interface", "udp_multicast",
                                    "--channel", channel, "--duration", "1"], cwd=ROOT, capture_output=True,
                                   text=True, timeout=60, stdin=subprocess.DEVNULL)
            found = re.findall(r"frames (\d+)", shown.stdout)
            assert shown.returncode == 0 and found, shown.stdout + shown.stderr
            counts[channel] = int(found[-1])
    finally:
        stop.set()
        sender.join()
    assert counts[ours] == 0, f"bench monitor on {ours} showed {counts[ours]} frames of {theirs}"
    assert counts[theirs] > 0, "bench monitor on the sender's group showed nothing: the test would prove nothing"


def _private_port(family: socket.AddressFamily) -> int:
    """A UDP port no other process of this host uses now (the kernel's choice of a free one)."""
    with socket.socket(family, socket.SOCK_DGRAM) as probe:
        probe.bind(("", 0))
        return int(probe.getsockname()[1])


def test_a_datagram_sent_to_the_port_itself_is_no_frame(group: Callable[[], str]) -> None:
    """python-can's socket is bound to the wildcard address of its port: a unicast datagram to that port (any
    process or host may send one; here to the loopback address) was read as a frame of the bus. The bench's
    socket filter keeps only what is addressed to the bus's group; python-can's IPv6 socket is dual-stack, so it
    is tried with an IPv4 datagram too. On a port of the test's own: on python-can's default port the stray
    datagram would reach another bench of this host (one that still reads such datagrams read it as a frame)."""
    from can.interfaces.udp_multicast.utils import pack_message

    channel = group()
    ipv6 = ":" in channel
    port = _private_port(socket.AF_INET6 if ipv6 else socket.AF_INET)
    options = BusOptions(extra={"port": port})
    with open_bus("udp_multicast", channel, options) as bus:   # alone on its port: a unicast datagram is its
        for family, loopback in ((socket.AF_INET, "127.0.0.1"), *([(socket.AF_INET6, "::1")] if ipv6 else [])):
            with socket.socket(family, socket.SOCK_DGRAM) as stray:
                stray.sendto(pack_message(can.Message(arbitration_id=0x7EE, data=b"\x01", is_extended_id=False)),
                             (loopback, port))
        with open_bus("udp_multicast", channel, options) as sender:
            sender.send(can.Message(arbitration_id=0x123, data=b"\x02", is_extended_id=False))
        seen = [m.arbitration_id for m in _drain(bus)]
    assert seen == [0x123], [hex(i) for i in seen]
