"""bench.diag.isotp: the bench's ISO-TP on its own clock.

Frames expected here are written from ISO 15765-2 in this file (the helpers below), never by the module under
test; the interoperability tests put the peer implementation can-isotp on the other end of a python-can bus.
"""

from __future__ import annotations

import time
import uuid
from collections.abc import Callable, Iterator

import can
import isotp
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from bench.diag.isotp import RULES, IsoTpEndpoint, IsoTpFraming, IsoTpParams, IsoTpProblem

TESTER, ECU = 0x7E0, 0x7E8
Frame = tuple[float, int, bytes]


# -- ISO 15765-2 frames, written from the standard ---------------------------------------------------------
def pad(frame: bytes, padding: int | None = 0xCC) -> bytes:
    return frame if padding is None else frame + bytes([padding]) * (8 - len(frame))


def sf(payload: bytes, padding: int | None = 0xCC) -> bytes:
    return pad(bytes([len(payload)]) + payload, padding)


def ff(length: int, first: bytes) -> bytes:
    return bytes([0x10 | length >> 8, length & 0xFF]) + first[:6]


def cf(sn: int, chunk: bytes, padding: int | None = 0xCC) -> bytes:
    return pad(bytes([0x20 | sn & 0x0F]) + chunk, padding)


def fc(status: int = 0, bs: int = 0, stmin: int = 0, padding: int | None = 0xCC) -> bytes:
    return pad(bytes([0x30 | status, bs, stmin]), padding)


def consecutive(payload: bytes, padding: int | None = 0xCC) -> list[bytes]:
    rest = payload[6:]
    return [cf(n + 1, rest[i:i + 7], padding) for n, i in enumerate(range(0, len(rest), 7))]


def exchange(t: float, data_id: int, fc_id: int, payload: bytes, bs: int = 0, gap: float = 0.001) -> list[Frame]:
    """One message as the bus shows it: an SF, or the FF, the receiver's FC and the CFs (an FC after every
    block of bs), a frame every `gap` seconds."""
    if len(payload) <= 7:
        return [(t, data_id, sf(payload))]
    frames: list[Frame] = [(t, data_id, ff(len(payload), payload[:6])), (t + gap, fc_id, fc(bs=bs))]
    cfs = consecutive(payload)
    for n, frame in enumerate(cfs, 1):
        frames.append((frames[-1][0] + gap, data_id, frame))
        if bs and n % bs == 0 and n < len(cfs):
            frames.append((frames[-1][0] + gap, fc_id, fc(bs=bs)))
    return frames


# -- two endpoints back to back -------------------------------------------------------------------------------
class Wire:
    """Two endpoints wired back to back through lists, on a fake bench time that the test advances."""

    def __init__(self, a: IsoTpParams, b: IsoTpParams, ids: tuple[int, int] = (TESTER, ECU)) -> None:
        self.now = 0.0
        self.frames: list[Frame] = []
        self.pending: list[tuple[int, bytes]] = []
        self.a = IsoTpEndpoint(ids[0], ids[1], self._send, a)
        self.b = IsoTpEndpoint(ids[1], ids[0], self._send, b)

    def _send(self, frame_id: int, data: bytes) -> None:
        self.frames.append((self.now, frame_id, data))
        self.pending.append((frame_id, data))

    def deliver(self) -> None:
        while self.pending:
            frame_id, data = self.pending.pop(0)
            (self.b if frame_id == self.a.tx_id else self.a).on_frame(self.now, data)

    def run(self, step: float = 0.001, limit: int = 200_000) -> None:
        """Poll both sides every `step` (1 ms: the bench's tick) until neither is busy."""
        self.deliver()
        k = 0
        while self.a.busy or self.b.busy:
            k += 1
            assert k < limit, "the exchange did not end"
            self.now = k * step
            self.a.poll(self.now)
            self.b.poll(self.now)
            self.deliver()


STMIN = st.sampled_from([0.0, 0.0001, 0.0005, 0.0009, 0.001, 0.002, 0.005, 0.02, 0.127])
BLOCK = st.integers(0, 4) | st.integers(0, 255)
PAYLOAD = st.sampled_from([1, 7, 8, 13, 14, 15, 111, 112, 4095]) | st.integers(1, 4095)
PADDING = st.sampled_from([0xCC, 0x00, 0xAA, None])
IDS = st.sampled_from([(TESTER, ECU), (0x18DA10F1, 0x18DAF110)])


def _cf_times(frames: list[Frame], data_id: int) -> list[float]:
    return [t for t, i, d in frames if i == data_id and d[0] >> 4 == 2]


@settings(max_examples=60, deadline=None)
@given(size=PAYLOAD, bs=BLOCK, stmin=STMIN, padding=PADDING, ids=IDS, data=st.data())
@example(size=4095, bs=1, stmin=0.127, padding=0xCC, ids=(TESTER, ECU), data=None).via("the slowest exchange")
@example(size=4095, bs=0, stmin=0.0001, padding=None, ids=(0x18DA10F1, 0x18DAF110), data=None).via("one block")
def test_round_trip(size: int, bs: int, stmin: float, padding: int | None, ids: tuple[int, int],
                    data: st.DataObject | None) -> None:
    """A payload of any length arrives whole; the receiver's BS and STmin (counted in bench time) hold between
    the sender's CFs; every frame is padded to 8 or as short as its data."""
    payload = data.draw(st.binary(min_size=size, max_size=size)) if data else bytes(range(256)) * 16
    payload = payload[:size]
    wire = Wire(IsoTpParams(padding=padding), IsoTpParams(padding=padding, block_size=bs, stmin=stmin), ids)
    wire.a.transmit(0.0, payload)
    wire.run()
    last = [t for t, i, _ in wire.frames if i == ids[0]][-1]
    assert list(wire.b.received) == [(last, payload)]
    assert wire.a.problems == [] and wire.b.problems == [] and not wire.a.received
    times = _cf_times(wire.frames, ids[0])
    assert all(later - earlier >= stmin - 1e-6 for earlier, later in zip(times, times[1:]))
    n_cf = len(times)
    assert n_cf == (-(-(size - 6) // 7) if size > 7 else 0)
    fcs = [d for _, i, d in wire.frames if i == ids[1]]
    assert len(fcs) == (0 if size <= 7 else 1 + ((n_cf - 1) // bs if bs else 0))
    for _, _, frame in wire.frames:
        assert len(frame) == 8 if padding is not None or frame[0] >> 4 == 1 else len(frame) <= 8
    if padding is None and size <= 7:
        assert wire.frames[0][2] == bytes([size]) + payload
    messages: list[Frame] = []
    framing = IsoTpFraming(*ids, on_message=lambda *m: messages.append(m))   # a monitor on the bus finds
    assert [p for t, i, d in wire.frames for p in framing.on_frame(t, i, d)] == []   # nothing wrong either,
    assert framing.check_timeouts(wire.now + 10.0) == []
    assert messages == [(last, ids[0], payload)]                            # and reads the same message


@settings(max_examples=30, deadline=None)
@given(first=PAYLOAD, second=PAYLOAD, bs_a=BLOCK, bs_b=BLOCK, stmin_a=STMIN, stmin_b=STMIN, data=st.data())
def test_round_trip_both_ways_at_once(first: int, second: int, bs_a: int, bs_b: int, stmin_a: float,
                                      stmin_b: float, data: st.DataObject) -> None:
    """Full duplex: each side sends while it receives, the data of one direction sharing an id with the flow
    control of the other."""
    one = data.draw(st.binary(min_size=first, max_size=first))
    two = data.draw(st.binary(min_size=second, max_size=second))
    wire = Wire(IsoTpParams(block_size=bs_a, stmin=stmin_a), IsoTpParams(block_size=bs_b, stmin=stmin_b))
    wire.a.transmit(0.0, one)
    wire.b.transmit(0.0, two)
    wire.run()
    assert [p for _, p in wire.b.received] == [one] and [p for _, p in wire.a.received] == [two]
    assert wire.a.problems == [] and wire.b.problems == []
    for sender, stmin in ((TESTER, stmin_b), (ECU, stmin_a)):
        times = _cf_times(wire.frames, sender)
        assert all(later - earlier >= stmin - 1e-6 for earlier, later in zip(times, times[1:]))
    assert check(wire.frames) == []


# -- interoperability with can-isotp over a python-can bus ----------------------------------------------------
class Peer:
    """can-isotp on one handle of a virtual bus, the bench's endpoint on another, a third one watching."""

    def __init__(self, ids: tuple[int, int], mine: IsoTpParams, theirs: dict[str, object]) -> None:
        channel = f"isotp-{uuid.uuid4().hex}"
        self.buses = [can.Bus(interface="virtual", channel=channel) for _ in range(3)]
        peer_bus, self.bus, self.watch = self.buses
        self.errors: list[Exception] = []
        extended = max(ids) > 0x7FF
        mode = isotp.AddressingMode.Normal_29bits if extended else isotp.AddressingMode.Normal_11bits
        self.stack = isotp.CanStack(peer_bus, address=isotp.Address(mode, txid=ids[1], rxid=ids[0]),
                                    error_handler=self.errors.append, params=theirs)
        self.endpoint = IsoTpEndpoint(ids[0], ids[1], self._send, mine)
        self.extended = extended

    def _send(self, frame_id: int, data: bytes) -> None:
        self.bus.send(can.Message(arbitration_id=frame_id, data=data, is_extended_id=self.extended))

    def drive(self, until: Callable[[], bool], limit: float = 5.0) -> None:
        """The endpoint's owner: every frame of its rx id to on_frame, a poll after each read, monotonic time."""
        end = time.monotonic() + limit
        while not until():
            assert time.monotonic() < end, f"not done within {limit} s; can-isotp's errors: {self.errors}"
            msg = self.bus.recv(timeout=0.0002)
            now = time.monotonic()
            if msg is not None and msg.arbitration_id == self.endpoint.rx_id:
                self.endpoint.on_frame(now, bytes(msg.data))
            self.endpoint.poll(now)

    def watched(self) -> list[can.Message]:
        frames = []
        while (msg := self.watch.recv(timeout=0)) is not None:
            frames.append(msg)
        return frames

    def close(self) -> None:
        self.stack.stop()
        for bus in self.buses:
            bus.shutdown()


@pytest.fixture
def peers() -> Iterator[Callable[..., Peer]]:
    made: list[Peer] = []

    def make(mine: IsoTpParams | None = None, ids: tuple[int, int] = (TESTER, ECU), **theirs: object) -> Peer:
        peer = Peer(ids, mine or IsoTpParams(), theirs)
        made.append(peer)
        peer.stack.start()
        return peer

    yield make
    for peer in made:
        peer.close()


def _payload(size: int) -> bytes:
    return bytes((i * 7 + 3) & 0xFF for i in range(size))


INTEROP = [
    pytest.param(IsoTpParams(), {}, (TESTER, ECU), id="defaults"),
    pytest.param(IsoTpParams(padding=None), {"tx_padding": 0x55}, (TESTER, ECU), id="their-padding-ours-none"),
    pytest.param(IsoTpParams(block_size=8, stmin=0.001), {"blocksize": 3, "tx_padding": 0xAA},
                 (TESTER, ECU), id="blocks-both-ways"),
    pytest.param(IsoTpParams(), {"tx_padding": 0}, (0x18DA10F1, 0x18DAF110), id="29-bit"),
]


@pytest.mark.parametrize("size", [100, 4095])
@pytest.mark.parametrize(("mine", "theirs", "ids"), INTEROP)
def test_we_send_to_can_isotp(peers: Callable[..., Peer], size: int, mine: IsoTpParams,
                              theirs: dict[str, object], ids: tuple[int, int]) -> None:
    peer = peers(mine, ids, **theirs)
    payload = _payload(size)
    peer.endpoint.transmit(time.monotonic(), payload)
    peer.drive(lambda: not peer.endpoint.busy)
    assert peer.stack.recv(block=True, timeout=2.0) == payload
    assert peer.endpoint.problems == [] and peer.errors == []


@pytest.mark.parametrize("size", [100, 4095])
@pytest.mark.parametrize(("mine", "theirs", "ids"), INTEROP)
def test_can_isotp_sends_to_us(peers: Callable[..., Peer], size: int, mine: IsoTpParams,
                               theirs: dict[str, object], ids: tuple[int, int]) -> None:
    peer = peers(mine, ids, **theirs)
    payload = _payload(size)
    peer.stack.send(payload)
    peer.drive(lambda: bool(peer.endpoint.received))
    assert [p for _, p in peer.endpoint.received] == [payload]
    assert peer.endpoint.problems == [] and peer.errors == []
    if "tx_padding" in theirs:
        assert all(len(m.data) == 8 for m in peer.watched() if m.arbitration_id == ids[1])


@pytest.mark.realtime   # judges gaps on the wall clock: a busy host delays a frame and shortens the next gap
@pytest.mark.parametrize("size", [100, 300])
def test_we_respect_can_isotp_stmin_and_block_size(peers: Callable[..., Peer], size: int) -> None:
    """can-isotp asks for 5 ms between CFs and an FC every 4: the bus (the watching handle's timestamps)
    shows both kept."""
    peer = peers(stmin=5, blocksize=4)
    payload = _payload(size)
    peer.endpoint.transmit(time.monotonic(), payload)
    peer.drive(lambda: not peer.endpoint.busy)
    assert peer.stack.recv(block=True, timeout=2.0) == payload
    assert peer.endpoint.problems == [] and peer.errors == []
    frames = peer.watched()
    cfs = [m.timestamp for m in frames if m.arbitration_id == TESTER and m.data[0] >> 4 == 2]
    assert len(cfs) == (size - 6 + 6) // 7
    assert min(b - a for a, b in zip(cfs, cfs[1:])) >= 0.005 - 0.001   # the watcher stamps a little after us
    kinds = "".join("F" if m.arbitration_id == ECU else "c" for m in frames if m.data[0] >> 4 in (2, 3))
    assert all(len(block) <= 4 for block in kinds.split("F"))


@pytest.mark.realtime   # can-isotp's own STmin timing on the wall clock
def test_can_isotp_follows_our_flow_control(peers: Callable[..., Peer]) -> None:
    """Our FC (BS 5, STmin 3 ms) as can-isotp reads it: blocks of 5, CFs 3 ms apart."""
    peer = peers(IsoTpParams(stmin=0.003, block_size=5))
    payload = _payload(200)
    peer.stack.send(payload)
    peer.drive(lambda: bool(peer.endpoint.received))
    assert [p for _, p in peer.endpoint.received] == [payload] and peer.endpoint.problems == []
    frames = peer.watched()
    fcs = [bytes(m.data) for m in frames if m.arbitration_id == TESTER]
    assert len(fcs) == 6 and all(d == fc(bs=5, stmin=3) for d in fcs)
    cfs = [m.timestamp for m in frames if m.arbitration_id == ECU and m.data[0] >> 4 == 2]
    assert len(cfs) == 28 and min(b - a for a, b in zip(cfs, cfs[1:])) >= 0.003 - 0.001


# -- every violation, and the recovery after it ---------------------------------------------------------------
class Ecu:
    """An endpoint fed by hand (on TESTER's side: it sends on 0x7E0, receives on 0x7E8)."""

    def __init__(self, params: IsoTpParams | None = None, ids: tuple[int, int] = (TESTER, ECU)) -> None:
        self.sent: list[bytes] = []
        self.ep = IsoTpEndpoint(ids[0], ids[1], lambda i, d: self.sent.append(d), params or IsoTpParams())

    def feed(self, frames: list[tuple[float, bytes]]) -> None:
        for t, data in frames:
            self.ep.on_frame(t, data)

    def receive_good(self, t: float, size: int = 20) -> None:
        """The recovery: a good multi-frame message afterwards arrives whole, with no new problem."""
        before = len(self.ep.problems)
        payload = _payload(size)
        self.feed([(t, ff(size, payload[:6]))] + [(t + 0.001 * (n + 1), f)
                                                   for n, f in enumerate(consecutive(payload))])
        assert self.ep.received[-1][1] == payload
        assert len(self.ep.problems) == before and not self.ep.busy


def only(problems: list[IsoTpProblem], rule: str, *words: str) -> IsoTpProblem:
    assert [p.rule for p in problems] == [rule], problems
    assert rule in RULES
    for word in words:
        assert word in problems[0].text, problems[0].text
    return problems[0]


def test_wrong_sequence_number() -> None:
    ecu, payload = Ecu(), _payload(30)
    ecu.feed([(0.0, ff(30, payload[:6]))])
    assert ecu.sent == [fc()]
    first, second, third, fourth = consecutive(payload)
    ecu.feed([(0.01, first), (0.02, third), (0.03, fourth)])
    problem = only(ecu.ep.problems, "sequence number", "0x7E8", third.hex(" ").upper(), "SN 3", "2 was due")
    assert problem.t == 0.02 and not ecu.ep.busy and not ecu.ep.received
    ecu.receive_good(0.1)


def test_missing_flow_control_n_bs() -> None:
    ecu = Ecu()
    ecu.ep.transmit(0.0, _payload(20))
    ecu.ep.poll(0.5)
    ecu.ep.poll(1.0)
    assert ecu.ep.busy and ecu.ep.problems == [] and len(ecu.sent) == 1
    ecu.ep.poll(1.001)
    assert only(ecu.ep.problems, "N_Bs timeout", "0x7E0 [10 14", "0x7E8", "N_Bs").t == 1.0
    assert not ecu.ep.busy
    ecu.ep.on_frame(1.2, fc())              # late: the same fault, not a second one
    ecu.ep.poll(1.2)
    assert len(ecu.ep.problems) == 1 and len(ecu.sent) == 1
    ecu.ep.transmit(2.0, _payload(20))      # the next message goes
    ecu.ep.on_frame(2.01, fc())
    ecu.ep.poll(2.01)
    assert ecu.sent[1:] == [ff(20, _payload(6)), *consecutive(_payload(20))] and not ecu.ep.busy
    assert len(ecu.ep.problems) == 1


def test_missing_consecutive_frame_n_cr() -> None:
    ecu, payload = Ecu(), _payload(30)
    cfs = consecutive(payload)
    ecu.feed([(0.0, ff(30, payload[:6])), (0.1, cfs[0])])
    ecu.ep.poll(1.05)
    assert ecu.ep.busy and ecu.ep.problems == []
    ecu.ep.poll(1.2)
    only(ecu.ep.problems, "N_Cr timeout", "0x7E8", cfs[0].hex(" ").upper(), "N_Cr")
    assert not ecu.ep.busy
    ecu.feed([(1.3, cfs[1]), (1.31, cfs[2])])   # the rest of the dropped message: no second problem
    assert len(ecu.ep.problems) == 1 and not ecu.ep.received
    ecu.receive_good(2.0)


def test_n_cr_found_by_the_late_frame_itself() -> None:
    """Without a poll in between, the late CF ends the reception; the problem is dated when N_Cr ran out."""
    ecu, payload = Ecu(), _payload(20)
    cfs = consecutive(payload)
    ecu.feed([(0.0, ff(20, payload[:6])), (0.25, cfs[0]), (1.5, cfs[1])])
    assert only(ecu.ep.problems, "N_Cr timeout").t == 1.25 and not ecu.ep.received


def test_unexpected_flow_control() -> None:
    ecu = Ecu()
    ecu.ep.on_frame(0.0, fc(bs=2))
    only(ecu.ep.problems, "unexpected flow control", "0x7E8 [30 02 00", "nothing is being sent")
    assert not ecu.ep.busy and ecu.sent == []
    ecu.ep.transmit(1.0, _payload(30))      # and while CFs are due (BS 0): ignored, the CFs go on
    ecu.ep.on_frame(1.01, fc())
    ecu.ep.on_frame(1.02, fc(bs=1))
    assert [p.rule for p in ecu.ep.problems] == ["unexpected flow control"] * 2
    ecu.ep.poll(1.03)
    assert ecu.sent[1:] == consecutive(_payload(30)) and not ecu.ep.busy
    ecu.receive_good(2.0)


def test_flow_control_overflow() -> None:
    ecu = Ecu()
    ecu.ep.transmit(0.0, _payload(20))
    ecu.ep.on_frame(0.01, fc(status=2))
    only(ecu.ep.problems, "flow control overflow", "0x7E8 [32", "OVFLW", "20-byte")
    assert not ecu.ep.busy
    ecu.ep.poll(0.02)
    assert len(ecu.sent) == 1
    ecu.ep.transmit(0.1, _payload(7))
    assert ecu.sent[-1] == sf(_payload(7))


def test_truncated_first_frame() -> None:
    ecu = Ecu()
    ecu.ep.on_frame(0.0, bytes([0x10, 20, 1, 2, 3]))
    only(ecu.ep.problems, "length", "0x7E8 [10 14 01 02 03]", "FF of 5 bytes")
    assert ecu.sent == [] and not ecu.ep.busy
    ecu.receive_good(0.1)


@pytest.mark.parametrize(("frame", "words"), [
    (bytes([0x03, 1, 2]), "SF_DL says 3"),
    (bytes([0x00, 1, 2]), "SF_DL 0"),
    (bytes([0x08, 1, 2, 3, 4, 5, 6, 7]), "SF_DL 8"),
    (bytes([0x10, 5, 1, 2, 3, 4, 5, 6]), "FF_DL 5"),
    (bytes([0x10, 0, 0, 0, 0x0F, 0xFF, 1, 2]), "escape sequence"),
    (bytes([0x30, 0]), "an FC has 3"),
    (bytes([0x21]), "CF without data"),
    (b"", "empty"),
])
def test_frames_shorter_than_their_pci(frame: bytes, words: str) -> None:
    ecu = Ecu()
    ecu.ep.on_frame(0.0, frame)
    only(ecu.ep.problems, "length", "0x7E8", words)
    assert ecu.sent == [] and not ecu.ep.busy and not ecu.ep.received


def test_truncated_consecutive_frame_drops_the_message() -> None:
    ecu, payload = Ecu(IsoTpParams(padding=None)), _payload(20)
    ecu.feed([(0.0, ff(20, payload[:6])), (0.01, cf(1, payload[6:13], None)), (0.02, cf(2, payload[13:18], None))])
    only(ecu.ep.problems, "length", "5 data bytes where 7 were due")
    ecu.receive_good(0.1)


def test_a_new_message_interrupts_the_reception() -> None:
    """ISO 15765-2: an SF or FF during a reception ends it and is taken as the start of the new message."""
    ecu, payload = Ecu(), _payload(30)
    cfs = consecutive(payload)
    ecu.feed([(0.0, ff(30, payload[:6])), (0.01, cfs[0]), (0.02, sf(b"\x50\x03"))])
    only(ecu.ep.problems, "interrupted", "0x7E8 [02 50 03", "13 of 30 bytes")
    assert list(ecu.ep.received) == [(0.02, b"\x50\x03")]
    ecu.feed([(0.03, cfs[1]), (0.04, cfs[2])])    # the old message's rest: no further problem
    assert len(ecu.ep.problems) == 1
    other = _payload(40)[::-1]
    ecu.feed([(0.05, ff(40, other[:6])), (0.06, consecutive(other)[0]), (0.07, ff(20, payload[:6]))])
    assert [p.rule for p in ecu.ep.problems] == ["interrupted"] * 2 and ecu.sent == [fc()] * 3
    ecu.feed([(0.08 + n / 1000, f) for n, f in enumerate(consecutive(payload[:20]))])
    assert ecu.ep.received[-1] == (0.08 + 1 / 1000, payload[:20])


def test_consecutive_frame_without_first_frame() -> None:
    ecu = Ecu()
    ecu.feed([(0.0, cf(1, b"1234567")), (0.01, cf(2, b"1234567"))])
    only(ecu.ep.problems, "unexpected consecutive frame", "0x7E8 [21 31", "no FF")
    ecu.receive_good(0.1)


def test_reserved_frame_type_and_flow_status() -> None:
    ecu = Ecu()
    ecu.ep.on_frame(0.0, pad(bytes([0x40, 1, 2])))
    only(ecu.ep.problems, "frame type", "0x7E8 [40 01 02", "PCI type 4")
    ecu.ep.transmit(0.1, _payload(20))
    ecu.ep.on_frame(0.11, fc(status=3))
    assert ecu.ep.problems[-1].rule == "flow status" and "flow status 3" in ecu.ep.problems[-1].text
    assert not ecu.ep.busy


def test_flow_control_wait() -> None:
    """FC WAIT restarts N_Bs; up to wft_max of them in a row are accepted, one more drops the message."""
    ecu = Ecu(IsoTpParams(wft_max=2))
    ecu.ep.transmit(0.0, _payload(20))
    ecu.ep.on_frame(0.9, fc(status=1))
    ecu.ep.poll(1.5)
    ecu.ep.on_frame(1.8, fc(status=1))
    ecu.ep.poll(2.7)
    assert ecu.ep.problems == [] and ecu.ep.busy and len(ecu.sent) == 1
    ecu.ep.on_frame(2.75, fc())
    ecu.ep.poll(2.75)
    assert not ecu.ep.busy and len(ecu.sent) == 3 and ecu.ep.problems == []
    ecu.ep.transmit(3.0, _payload(20))
    ecu.feed([(3.1 + n / 10, fc(status=1)) for n in range(3)])
    only(ecu.ep.problems, "FC WAIT limit", "0x7E8 [31", "wft_max 2")
    assert not ecu.ep.busy


def test_no_wait_accepted_by_default() -> None:
    ecu = Ecu()
    ecu.ep.transmit(0.0, _payload(20))
    ecu.ep.on_frame(0.1, fc(status=1))
    only(ecu.ep.problems, "FC WAIT limit")


def test_first_frame_longer_than_max_length_is_answered_overflow() -> None:
    ecu = Ecu(IsoTpParams(max_length=100))
    ecu.ep.on_frame(0.0, ff(101, _payload(6)))
    assert ecu.sent == [fc(status=2)]
    only(ecu.ep.problems, "flow control overflow", "101 bytes", "FC OVFLW")
    ecu.ep.on_frame(0.01, cf(1, _payload(7)))      # a sender that went on regardless: the same fault
    assert len(ecu.ep.problems) == 1
    ecu.ep.on_frame(0.1, bytes([0x10, 0, 0, 1, 0, 0, 1, 2]))   # the escape sequence: 65536 bytes, refused too
    assert ecu.sent[-1] == fc(status=2) and ecu.ep.problems[-1].rule == "flow control overflow"
    ecu.receive_good(0.2, size=100)


def test_transmit_refusals() -> None:
    ecu = Ecu()
    ecu.ep.transmit(0.0, _payload(20))
    with pytest.raises(ValueError, match=r"0x7E0: cannot transmit 3 bytes while a 20-byte message is still"):
        ecu.ep.transmit(0.1, b"abc")
    with pytest.raises(ValueError, match="not 1-4095"):
        Ecu().ep.transmit(0.0, b"")
    with pytest.raises(ValueError, match="not 1-4095"):
        Ecu().ep.transmit(0.0, bytes(4096))
    ecu.ep.transmit(1.5, b"abc")                    # N_Bs expired by then: the transmit may go
    assert ecu.ep.problems[-1].rule == "N_Bs timeout" and ecu.sent[-1] == sf(b"abc")


def test_sending_while_receiving() -> None:
    """Full duplex: a reception in progress does not stop a transmission, nor the other way round."""
    ecu, payload = Ecu(), _payload(20)
    ecu.feed([(0.0, ff(20, payload[:6]))])
    ecu.ep.transmit(0.01, b"\x7f\x22\x78")
    assert ecu.sent == [fc(), sf(b"\x7f\x22\x78")] and ecu.ep.busy
    ecu.feed([(0.02 + n / 1000, f) for n, f in enumerate(consecutive(payload))])
    assert ecu.ep.received[-1][1] == payload and not ecu.ep.busy


@pytest.mark.parametrize(("raw", "gap"), [(0x00, 0.0), (0x05, 0.005), (0x7F, 0.127), (0xF1, 0.0001),
                                          (0xF9, 0.0009), (0x80, 0.127), (0xF0, 0.127), (0xFA, 0.127),
                                          (0xFF, 0.127)])
def test_sender_reads_stmin(raw: int, gap: float) -> None:
    """0-127 ms, 100-900 us as F1-F9, every reserved byte as 127 ms (ISO 15765-2)."""
    ecu = Ecu()
    ecu.ep.transmit(0.0, _payload(20))
    ecu.ep.on_frame(1.0, fc(stmin=raw))
    ecu.ep.poll(1.0)
    assert len(ecu.sent) == (3 if gap == 0 else 2)
    if gap:
        ecu.ep.poll(1.0 + gap - 0.00001)
        assert len(ecu.sent) == 2
        ecu.ep.poll(1.0 + gap)
        assert len(ecu.sent) == 3


def test_stmin_holds_across_a_flow_control() -> None:
    """With BS 1 the FC comes after every CF: the next CF still waits the STmin from the previous one."""
    ecu = Ecu()
    ecu.ep.transmit(0.0, _payload(20))
    ecu.ep.on_frame(0.0, fc(bs=1, stmin=10))
    ecu.ep.poll(0.0)
    ecu.ep.on_frame(0.001, fc(bs=1, stmin=10))
    ecu.ep.poll(0.005)
    assert len(ecu.sent) == 2
    ecu.ep.poll(0.010)
    assert len(ecu.sent) == 3 and not ecu.ep.busy


@pytest.mark.parametrize(("bs", "stmin", "expected"), [(0, 0.0, (0, 0)), (4, 0.0003, (4, 0xF3)),
                                                        (255, 0.02, (255, 0x14)), (1, 0.127, (1, 0x7F))])
def test_our_flow_control(bs: int, stmin: float, expected: tuple[int, int]) -> None:
    ecu = Ecu(IsoTpParams(block_size=bs, stmin=stmin, padding=None))
    ecu.ep.on_frame(0.0, ff(20, _payload(6)))
    assert ecu.sent == [bytes([0x30, *expected])]


def test_padding_none_sends_minimal_frames() -> None:
    ecu = Ecu(IsoTpParams(padding=None))
    ecu.ep.transmit(0.0, b"\x22\xf1\x90")
    ecu.ep.transmit(0.1, _payload(15))
    ecu.ep.on_frame(0.2, fc())
    ecu.ep.poll(0.2)
    assert ecu.sent == [b"\x03\x22\xf1\x90", ff(15, _payload(6)), *consecutive(_payload(15), None)]
    assert [len(f) for f in ecu.sent] == [4, 8, 8, 3]


@pytest.mark.parametrize("kwargs", [dict(stmin=0.0015), dict(stmin=0.128), dict(stmin=-0.001), dict(padding=256),
                                    dict(block_size=256), dict(n_bs=0.0), dict(n_cr=float("nan")),
                                    dict(max_length=4096), dict(max_length=0), dict(wft_max=-1)])
def test_params_refuse_what_iso_cannot_say(kwargs: dict[str, float]) -> None:
    with pytest.raises(ValueError, match="ISO-TP " + next(iter(kwargs))):
        IsoTpParams(**kwargs)  # type: ignore[arg-type]


def test_reset_drops_everything_quietly() -> None:
    ecu, payload = Ecu(), _payload(30)
    ecu.feed([(0.0, ff(30, payload[:6])), (0.01, consecutive(payload)[0])])
    ecu.ep.transmit(0.02, _payload(20))
    assert ecu.ep.busy
    ecu.ep.reset()
    assert not ecu.ep.busy
    ecu.feed([(0.03, consecutive(payload)[1]), (0.04, fc())])   # the peer's rest of both: not its fault
    ecu.ep.poll(5.0)
    assert ecu.ep.problems == [] and len(ecu.sent) == 2
    ecu.receive_good(6.0)


def test_29_bit_ids_in_the_text() -> None:
    ecu = Ecu(ids=(0x18DA10F1, 0x18DAF110))
    ecu.ep.on_frame(0.0, fc())
    only(ecu.ep.problems, "unexpected flow control", "0x18DAF110")


# -- the monitor's framing check ------------------------------------------------------------------------------
REQUEST = _payload(40)       # a multi-frame request (a write), BS 0
RESPONSE = _payload(200)     # a multi-frame response, BS 4, its sequence numbers wrapping


def good() -> list[Frame]:
    frames = exchange(0.0, TESTER, ECU, b"\x22\xf1\x90")
    frames += exchange(0.010, ECU, TESTER, RESPONSE, bs=4)
    frames += exchange(0.200, TESTER, ECU, REQUEST)
    frames += exchange(0.300, ECU, TESTER, b"\x6e\xf1\x90")
    return frames


def check(frames: list[Frame], then: float | None = None) -> list[IsoTpProblem]:
    framing = IsoTpFraming(TESTER, ECU)
    problems = [p for t, i, d in frames for p in framing.on_frame(t, i, d)]
    return problems + framing.check_timeouts(then if then is not None else frames[-1][0] + 10.0)


def test_framing_of_a_good_exchange() -> None:
    frames = good()
    assert any(d[0] == 0x20 for _, _, d in frames)       # the sequence number wrapped
    assert check(frames) == []
    assert IsoTpFraming(TESTER, ECU).on_frame(0.0, 0x123, b"\x21") == []   # not this connection's


def test_framing_of_what_the_endpoints_send() -> None:
    wire = Wire(IsoTpParams(), IsoTpParams(block_size=3, stmin=0.002))
    wire.a.transmit(0.0, RESPONSE)
    wire.b.transmit(0.0, REQUEST)
    wire.run()
    assert check(wire.frames) == []


def _index(frames: list[Frame], data_id: int, kind: int, nth: int = 0) -> int:
    return [n for n, (_, i, d) in enumerate(frames) if i == data_id and d[0] >> 4 == kind][nth]


def _wrong_sn(frames: list[Frame]) -> list[Frame]:
    n = _index(frames, ECU, 2, 5)
    t, i, d = frames[n]
    frames[n] = (t, i, bytes([d[0] + 1]) + d[1:])
    return frames


def _shift_from(frames: list[Frame], n: int, delay: float) -> list[Frame]:
    return frames[:n] + [(t + delay, i, d) for t, i, d in frames[n:]]


def _drop(frames: list[Frame], n: int) -> list[Frame]:
    return frames[:n] + frames[n + 1:]


def _insert(frames: list[Frame], n: int, frame_id: int, data: bytes) -> list[Frame]:
    return frames[:n] + [(frames[n - 1][0], frame_id, data)] + frames[n:]


BROKEN: list[tuple[str, Callable[[list[Frame]], list[Frame]], str, str]] = [
    ("wrong sequence number", _wrong_sn, "sequence number", "0x7E8 [27"),
    ("FC late", lambda f: _shift_from(f, _index(f, TESTER, 3), 1.5), "N_Bs timeout", "0x7E8 [10 C8"),
    ("FC missing, the next request shows it", lambda f: f[:2] + [(3.0, TESTER, sf(b"\x3e\x00"))],
     "N_Bs timeout", "no flow control on 0x7E0"),
    ("FC missing at the end", lambda f: f[:2], "N_Bs timeout", "within N_Bs 1 s"),
    ("FC after a block missing", lambda f: _drop(f, _index(f, TESTER, 3, 1))[:_index(f, TESTER, 3, 1)],
     "N_Bs timeout", "0x7E8 [24"),
    ("CF gap over N_Cr", lambda f: _shift_from(f, _index(f, ECU, 2, 2), 1.2), "N_Cr timeout", "0x7E8 [22"),
    ("CF missing at the end", lambda f: f[:_index(f, ECU, 2, 2)], "N_Cr timeout", "no CF on 0x7E8"),
    ("CF without FF", lambda f: f[:1] + [(0.005, ECU, cf(1, b"abcdefg"))] + f[1:], "unexpected consecutive frame",
     "0x7E8 [21 61"),
    ("CF before the FC", lambda f: _drop(f, _index(f, TESTER, 3, 1)), "unexpected consecutive frame",
     "before the flow control"),
    ("FC without FF", lambda f: f[:1] + [(0.005, TESTER, fc())] + f[1:], "unexpected flow control",
     "0x7E0 [30 00 00"),
    ("FC while CFs are due", lambda f: _insert(f, _index(f, ECU, 2, 1), TESTER, fc()), "unexpected flow control",
     "while consecutive frames were due"),
    ("truncated FF", lambda f: [(t, i, d[:5] if d[0] == 0x10 and i == ECU else d) for t, i, d in f][:2],
     "length", "FF of 5 bytes"),
    ("truncated CF", lambda f: [(t, i, d[:4] if d[0] == 0x23 and i == ECU else d) for t, i, d in f],
     "length", "3 data bytes where 7"),
    ("interrupted", lambda f: _insert(f, _index(f, ECU, 2, 3), ECU, sf(b"\x7f\x22\x78")), "interrupted",
     "0x7E8 [03 7F 22 78"),
    ("OVFLW", lambda f: [(t, i, fc(status=2) if (i, d) == (TESTER, fc(bs=4)) else d) for t, i, d in f][:3],
     "flow control overflow", "200-byte message on 0x7E8"),
    ("reserved flow status", lambda f: [(t, i, fc(status=5) if (i, d) == (TESTER, fc(bs=4)) else d)
                                        for t, i, d in f][:3], "flow status", "0x7E0 [35"),
    ("FC WAIT", lambda f: _insert(f, _index(f, TESTER, 3), TESTER, fc(status=1)), "FC WAIT limit", "[31 00 00"),
    ("reserved frame type", lambda f: f[:1] + [(0.005, ECU, pad(b"\x50"))] + f[1:], "frame type", "PCI type 5"),
]


@pytest.mark.parametrize(("mutate", "rule", "words"), [pytest.param(*case[1:], id=case[0]) for case in BROKEN])
def test_framing_of_a_broken_exchange(mutate: Callable[[list[Frame]], list[Frame]], rule: str, words: str) -> None:
    only(check(mutate(good())), rule, words)


def test_framing_accepts_fc_wait_up_to_wft_max() -> None:
    frames = _insert(good(), 2, TESTER, fc(status=1))
    framing = IsoTpFraming(TESTER, ECU, IsoTpParams(wft_max=1))
    assert [p for t, i, d in frames for p in framing.on_frame(t, i, d)] == []


def test_framing_reports_a_timeout_once() -> None:
    framing = IsoTpFraming(TESTER, ECU)
    frames = good()[:2]
    for t, i, d in frames:
        assert framing.on_frame(t, i, d) == []
    assert framing.check_timeouts(0.5) == []
    assert [(p.rule, p.t) for p in framing.check_timeouts(1.5)] == [("N_Bs timeout", 0.010 + 1.0)]
    assert framing.check_timeouts(2.0) == []
    assert framing.on_frame(2.1, TESTER, fc(bs=4)) == []       # the late FC: the same fault
    assert [p for t, i, d in good() for p in framing.on_frame(t + 3.0, i, d)] == []   # the next exchange is fine


# -- the monitor's reassembly (on_message: the run log's diagnostic topics) ------------------------------------
def reassembled(frames: list[Frame]) -> tuple[list[Frame], list[IsoTpProblem]]:
    """The whole messages a bus observer reads from the frames, and the problems it finds."""
    messages: list[Frame] = []
    framing = IsoTpFraming(TESTER, ECU, on_message=lambda *m: messages.append(m))
    problems = [p for t, i, d in frames for p in framing.on_frame(t, i, d)]
    return messages, problems


def test_reassembly_of_a_single_frame_drops_the_padding() -> None:
    assert reassembled([(0.5, TESTER, sf(b"\x19\x02\xff"))]) == ([(0.5, TESTER, b"\x19\x02\xff")], [])
    assert reassembled([(0.5, ECU, sf(b"\x7f\x19\x31", padding=None))])[0] == [(0.5, ECU, b"\x7f\x19\x31")]


def test_reassembly_of_multi_frame_messages_with_flow_control() -> None:
    """Each message once its last byte came, at that frame's time, both ways, across blocks (BS 4) and a
    sequence number that wraps; the flow control frames are no message."""
    frames = good()
    messages, problems = reassembled(frames)
    assert problems == []
    assert [(i, p) for _, i, p in messages] == [(TESTER, b"\x22\xf1\x90"), (ECU, RESPONSE), (TESTER, REQUEST),
                                                (ECU, b"\x6e\xf1\x90")]
    assert messages[1][0] == frames[_index(frames, ECU, 2, 27)][0]     # its 28th and last CF
    assert messages[2][0] == frames[_index(frames, TESTER, 2, 4)][0]   # its 5th and last CF


@pytest.mark.parametrize("mutate", [
    pytest.param(_wrong_sn, id="wrong sequence number"),
    pytest.param(lambda f: _drop(f, _index(f, ECU, 2, 6)), id="CF missing"),
    pytest.param(lambda f: _shift_from(f, _index(f, ECU, 2, 2), 1.2), id="CF gap over N_Cr"),
    pytest.param(lambda f: _insert(f, _index(f, ECU, 2, 3), ECU, sf(b"\x7f\x22\x78")), id="interrupted"),
    pytest.param(lambda f: [(t, i, fc(status=2) if (i, d) == (TESTER, fc(bs=4)) else d) for t, i, d in f],
                 id="OVFLW"),
])
def test_a_broken_sequence_gives_no_message(mutate: Callable[[list[Frame]], list[Frame]]) -> None:
    """The message whose framing broke is dropped as its receiver drops it; the others still arrive, an SF that
    interrupts it among them."""
    messages, problems = reassembled(mutate(good()))
    assert problems
    payloads = [p for _, _, p in messages]
    assert RESPONSE not in payloads
    assert payloads[0] == b"\x22\xf1\x90" and payloads[-2:] == [REQUEST, b"\x6e\xf1\x90"]


def test_reassembly_changes_no_judgement() -> None:
    """With on_message the framing finds exactly the problems it finds without (the monitor's behaviour)."""
    for _, mutate, _, _ in BROKEN:
        frames = mutate(good())
        framing = IsoTpFraming(TESTER, ECU)
        assert reassembled(frames)[1] == [p for t, i, d in frames for p in framing.on_frame(t, i, d)]


class _Stacks:
    """Two can-isotp protocol stacks (TransportLayerLogic, no thread) wired back to back through queues."""

    def __init__(self, sender: dict[str, object], receiver: dict[str, object]) -> None:
        self.frames: list[Frame] = []
        self.queues: dict[int, list[isotp.CanMessage]] = {TESTER: [], ECU: []}
        self.a = self._stack(TESTER, ECU, sender)
        self.b = self._stack(ECU, TESTER, receiver)

    def _stack(self, tx: int, rx: int, params: dict[str, object]) -> isotp.TransportLayerLogic:
        queue = self.queues[rx]

        def send(msg: isotp.CanMessage) -> None:
            self.frames.append((len(self.frames) * 0.001, msg.arbitration_id, bytes(msg.data)))
            self.queues[msg.arbitration_id].append(msg)

        return isotp.TransportLayerLogic(lambda timeout: queue.pop(0) if queue else None, send,
                                         isotp.Address(isotp.AddressingMode.Normal_11bits, txid=tx, rxid=rx),
                                         params=params)


@settings(max_examples=60, deadline=None)
@given(payload=st.binary(min_size=1, max_size=4095), bs=BLOCK, padding=st.sampled_from([0xCC, 0x00, None]))
@example(payload=bytes(range(256)) * 15 + bytes(range(255)), bs=0, padding=0xCC).via("the longest message")
def test_reassembly_of_what_can_isotp_sends(payload: bytes, bs: int, padding: int | None) -> None:
    """Any payload of 1-4095 bytes framed by can-isotp, its receiver asking for BS blocks: the observer reads it
    whole, once, at the time of its last frame, and finds nothing wrong."""
    stacks = _Stacks({"tx_padding": padding}, {"blocksize": bs, "tx_padding": padding})
    stacks.a.send(payload)
    for _ in range(10_000):
        stacks.a.process()
        stacks.b.process()
        if stacks.b.available():
            break
    assert stacks.b.recv() == payload
    messages, problems = reassembled(stacks.frames)
    assert problems == []
    assert messages == [(stacks.frames[-1][0], TESTER, payload)]
