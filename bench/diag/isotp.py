"""ISO-TP (ISO 15765-2) on classical CAN: normal addressing, 8-byte frames, 11- or 29-bit identifiers.

Every call takes the bench time `t` and nothing here reads a clock, so N_Bs, N_Cr and STmin count bench time:
in virtual time a multi-frame exchange is as deterministic as the rest of the run, and a run slowed by the host
never turns into a timeout of the DUT's. `IsoTpEndpoint` is one side of a connection (the tester's, a simulated
node's); `IsoTpFraming` judges both sides of one connection from a bus monitor's seat without sending.

Problems are records, not exceptions: a DUT that breaks the framing is what a test bench is there to see, so
every violation is kept with its bench time and the frame that showed it, and the endpoint recovers as ISO
15765-2 says (drops the message, takes the next SF or FF). The rule names are in `RULES`.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

from bench import canid

#: every `IsoTpProblem.rule` this module gives
RULES = (
    "length",                        # a frame shorter (or longer) than its PCI says, or a length ISO forbids
    "frame type",                    # a reserved PCI type (4-15)
    "sequence number",               # a CF whose SN is not the one due
    "interrupted",                   # a new SF or FF while a multi-frame message was still in progress
    "unexpected consecutive frame",  # a CF with no FF before it, or before the flow control that allows it
    "unexpected flow control",       # an FC while none was awaited
    "flow status",                   # an FC with a reserved flow status
    "flow control overflow",         # FC OVFLW: the receiver refused the message's length
    "FC WAIT limit",                 # more FC WAIT in a row than wft_max
    "N_Bs timeout",                  # no FC within N_Bs of an FF or of a block's last CF
    "N_Cr timeout",                  # no CF within N_Cr of the FC or of the previous CF
)

_SF, _FF, _CF, _FC = 0, 1, 2, 3
_CTS, _WAIT, _OVFLW = 0, 1, 2
_FRAME_LEN = 8
_MAX_LENGTH = 4095            # a 12-bit FF_DL; the escape sequence (32-bit FF_DL) is sent never and refused
_RESERVED_STMIN = 0.127       # ISO 15765-2: a reserved STmin byte is read as the longest one, 127 ms
_DUE_EPS = 1e-9               # float noise in t: a CF due "now" goes now, not one poll later


@dataclass(frozen=True)
class IsoTpParams:
    """One endpoint's (or one connection's) ISO-TP settings; times in seconds of bench time."""

    padding: int | None = 0xCC   # pad every frame to 8 bytes with this byte; None: frames as short as their data
    block_size: int = 0          # BS asked for in this endpoint's flow control (0: one FC for the whole message)
    stmin: float = 0.0           # STmin asked for in this endpoint's flow control: 0-127 ms, or 100-900 us
    n_bs: float = 1.0            # waiting for a flow control after an FF or a block
    n_cr: float = 1.0            # waiting for the next consecutive frame
    max_length: int = _MAX_LENGTH   # the longest payload sent or accepted (an FF beyond it is answered OVFLW)
    wft_max: int = 0             # FC WAIT frames accepted in a row before giving up

    def __post_init__(self) -> None:
        if self.padding is not None and not 0 <= self.padding <= 0xFF:
            raise ValueError(f"ISO-TP padding {self.padding!r} is not a byte (0-255) or None")
        if not 0 <= self.block_size <= 0xFF:
            raise ValueError(f"ISO-TP block_size {self.block_size!r} is not 0-255")
        _encode_stmin(self.stmin)
        for name in ("n_bs", "n_cr"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"ISO-TP {name} {value!r} is not a positive number of seconds")
        if not 1 <= self.max_length <= _MAX_LENGTH:
            raise ValueError(f"ISO-TP max_length {self.max_length!r} is not 1-{_MAX_LENGTH} (a 12-bit FF_DL)")
        if self.wft_max < 0:
            raise ValueError(f"ISO-TP wft_max {self.wft_max!r} is negative")


@dataclass(frozen=True)
class IsoTpProblem:
    """One violation of ISO 15765-2."""

    t: float         # bench time of the offending frame, or the moment a timeout ran out (exact however late found)
    rule: str        # one of RULES
    text: str        # the frame (id and data in hex) and what is wrong with it


# -- frames ---------------------------------------------------------------------------------------------------
def _encode_stmin(seconds: float) -> int:
    """The STmin byte of a gap; ValueError when ISO has no byte for it (rounding would ask for another gap)."""
    if not math.isfinite(seconds):
        raise ValueError(f"ISO-TP stmin {seconds!r} s is not a number of seconds")
    ms = round(seconds * 1000)
    if 0 <= ms <= 0x7F and math.isclose(ms / 1000, seconds, abs_tol=1e-9):
        return ms
    hundreds = round(seconds * 10000)
    if 1 <= hundreds <= 9 and math.isclose(hundreds / 10000, seconds, abs_tol=1e-9):
        return 0xF0 + hundreds
    raise ValueError(f"ISO-TP stmin {seconds!r} s is neither 0-127 ms in whole ms nor 100-900 us in steps of 100 us")


def _decode_stmin(raw: int) -> float:
    """The gap an STmin byte asks for; reserved bytes ask for the longest (ISO 15765-2)."""
    if raw <= 0x7F:
        return raw / 1000
    if 0xF1 <= raw <= 0xF9:
        return (raw - 0xF0) / 10000
    return _RESERVED_STMIN


def _show(frame_id: int, data: bytes) -> str:
    """A frame as the problems name it: '0x7E8 [21 AA BB]'."""
    return f"{canid.text(frame_id)} [{data.hex(' ').upper()}]"


def _ff_length(data: bytes) -> tuple[int, int]:
    """(FF_DL, offset of the first data byte) of a first frame of 8 bytes, escape sequence included."""
    length = ((data[0] & 0x0F) << 8) | data[1]
    if length == 0:
        return int.from_bytes(data[2:6], "big"), 6
    return length, 2


def _malformed(data: bytes) -> tuple[str, str] | None:
    """(rule, what is wrong) when the frame is no ISO-TP frame of classical CAN whatever the state, else None.
    ISO 15765-2 ignores such a frame, so it changes no state: the caller records it and stops there."""
    if not data:
        return "length", "is empty: no PCI"
    if len(data) > _FRAME_LEN:
        return "length", f"has {len(data)} bytes, more than classical CAN's 8"
    kind = data[0] >> 4
    if kind == _SF:
        sf_dl = data[0] & 0x0F
        if sf_dl == 0:
            return "length", "is an SF with SF_DL 0 (the escape sequence is CAN FD's)"
        if sf_dl > 7:
            return "length", f"is an SF with SF_DL {sf_dl}, more than 7 bytes fit"
        if len(data) < 1 + sf_dl:
            return "length", f"is an SF with {len(data) - 1} data bytes where its SF_DL says {sf_dl}"
    elif kind == _FF:
        if len(data) < _FRAME_LEN:
            return "length", f"is an FF of {len(data)} bytes; an FF fills all 8"
        ff_dl, start = _ff_length(data)
        if start == 2 and ff_dl < 8:
            return "length", f"is an FF with FF_DL {ff_dl}, which fits a single frame"
        if start == 6 and ff_dl <= _MAX_LENGTH:
            return "length", f"is an FF with the escape sequence for FF_DL {ff_dl}, which fits 12 bits"
    elif kind == _CF:
        if len(data) < 2:
            return "length", "is a CF without data"
    elif kind == _FC:
        if len(data) < 3:
            return "length", f"is an FC of {len(data)} bytes; an FC has 3 (FS, BS, STmin)"
    else:
        return "frame type", f"has PCI type {kind}, which ISO 15765-2 reserves"
    return None


# -- the endpoint ---------------------------------------------------------------------------------------------
@dataclass(slots=True)
class _Sending:
    """A multi-frame message on its way out (an SF never is: it goes at once)."""

    payload: bytes
    pos: int               # payload bytes sent so far
    sn: int                # the next CF's sequence number
    waiting: bool          # for a flow control (after the FF or a block)
    deadline: float        # N_Bs, while waiting
    due: float             # the next CF, while not waiting
    bs: int = 0            # the peer's block size (0: no further FC)
    block_left: int = 0    # CFs left in this block
    stmin: float = 0.0     # the peer's STmin
    waits: int = 0         # FC WAIT in a row
    last_cf: float = -math.inf
    last: bytes = b""      # the last frame sent, for a timeout's text


@dataclass(slots=True)
class _Receiving:
    """A multi-frame message on its way in."""

    length: int
    buffer: bytearray
    sn: int
    block_left: int
    deadline: float        # N_Cr
    last: bytes            # the last frame received, for a timeout's text


class IsoTpEndpoint:
    """One side of an ISO-TP connection: sends on tx_id, receives (and takes flow control) on rx_id.

    Full duplex, as ISO 15765-2 allows: a message can be received while one is being sent. The owner passes
    every frame of rx_id to `on_frame` and calls `poll` often (consecutive frames go out from there, at their
    STmin); `busy` and the timeouts are as of the last call.
    """

    def __init__(self, tx_id: int, rx_id: int, send: Callable[[int, bytes], None],
                 params: IsoTpParams = IsoTpParams()) -> None:
        self.tx_id, self.rx_id = tx_id, rx_id
        self.send = send
        self.params = params
        #: complete payloads, with the bench time of their last frame
        self.received: deque[tuple[float, bytes]] = deque()
        #: every violation this endpoint saw, in order
        self.problems: list[IsoTpProblem] = []
        self._tx: _Sending | None = None
        self._rx: _Receiving | None = None
        # After a message was given up, the peer's rest of it (its CFs, a late FC) is the same fault again:
        # ignored quietly until a new message starts, so one fault gives one problem.
        self._rx_dropped = False
        self._tx_dropped = False

    @property
    def busy(self) -> bool:
        """A transmission or a reception in progress."""
        return self._tx is not None or self._rx is not None

    def reset(self) -> None:
        """Abort everything, as an ECU reset does; `received` and `problems` stay (they are the bench's record)."""
        self._rx_dropped = self._rx_dropped or self._rx is not None
        self._tx_dropped = self._tx_dropped or self._tx is not None
        self._tx = self._rx = None

    # -- sending --------------------------------------------------------------------------------------------
    def transmit(self, t: float, payload: bytes) -> None:
        """Send a payload: an SF now, or the FF now and its CFs from `poll` as the peer's flow control allows."""
        self._expire(t)
        payload = bytes(payload)
        if self._tx is not None:
            raise ValueError(f"ISO-TP {canid.text(self.tx_id)}: cannot transmit {len(payload)} bytes while a "
                             f"{len(self._tx.payload)}-byte message is still being sent ({self._tx.pos} bytes "
                             f"out); wait until busy is False or reset()")
        if not 1 <= len(payload) <= self.params.max_length:
            raise ValueError(f"ISO-TP {canid.text(self.tx_id)}: a payload of {len(payload)} bytes is not "
                             f"1-{self.params.max_length}")
        self._tx_dropped = False
        if len(payload) <= 7:
            self._send(bytes([len(payload)]) + payload)
            return
        first = bytes([0x10 | (len(payload) >> 8), len(payload) & 0xFF]) + payload[:6]
        self._tx = _Sending(payload, pos=6, sn=1, waiting=True, deadline=t + self.params.n_bs, due=t, last=first)
        self._send(first)

    def poll(self, t: float) -> None:
        """Send the consecutive frames that are due and fire the timeouts that have expired."""
        self._expire(t)
        while (tx := self._tx) is not None and not tx.waiting and t + _DUE_EPS >= tx.due:
            chunk = tx.payload[tx.pos:tx.pos + 7]
            frame = bytes([0x20 | tx.sn]) + chunk
            tx.pos += len(chunk)
            tx.sn = (tx.sn + 1) & 0x0F
            tx.last, tx.last_cf = frame, t
            tx.due = t + tx.stmin            # STmin 0: the loop sends the rest of the block in this call
            if tx.pos >= len(tx.payload):
                self._tx = None
            elif tx.bs:
                tx.block_left -= 1
                if tx.block_left == 0:
                    tx.waiting, tx.deadline = True, t + self.params.n_bs
            self._send(frame)                # after the state: a peer wired back to back may answer at once

    def _send(self, frame: bytes) -> None:
        padding = self.params.padding
        if padding is not None and len(frame) < _FRAME_LEN:
            frame += bytes([padding]) * (_FRAME_LEN - len(frame))
        self.send(self.tx_id, frame)

    # -- receiving ------------------------------------------------------------------------------------------
    def on_frame(self, t: float, data: bytes) -> None:
        """A frame received on rx_id: the peer's SF, FF or CF, or its flow control for this endpoint's FF."""
        self._expire(t)
        data = bytes(data)
        bad = _malformed(data)
        if bad is not None:
            self._problem(t, bad[0], f"{_show(self.rx_id, data)} {bad[1]}")
            return
        kind = data[0] >> 4
        if kind == _FC:
            self._flow_control(t, data)
        elif kind == _CF:
            self._consecutive(t, data)
        else:
            rx = self._rx
            if rx is not None:
                self._problem(t, "interrupted", f"{_show(self.rx_id, data)} starts a new message while "
                              f"{len(rx.buffer)} of {rx.length} bytes were in; the old one is dropped")
                self._rx = None
            # the old message's rest, should it still come, is the same fault (after an FF it meets the new
            # message's sequence numbers instead)
            self._rx_dropped = rx is not None
            if kind == _SF:
                self.received.append((t, data[1:1 + (data[0] & 0x0F)]))
            else:
                self._first(t, data)

    def _first(self, t: float, data: bytes) -> None:
        length, start = _ff_length(data)
        if length > self.params.max_length:
            self._problem(t, "flow control overflow", f"{_show(self.rx_id, data)} announces {length} bytes, more "
                          f"than this endpoint's {self.params.max_length}: answered FC OVFLW")
            self._rx_dropped = True
            self._send(bytes([0x30 | _OVFLW, 0, 0]))
            return
        bs = self.params.block_size
        self._rx = _Receiving(length, bytearray(data[start:]), sn=1, block_left=bs,
                              deadline=t + self.params.n_cr, last=data)
        self._send(bytes([0x30 | _CTS, bs, _encode_stmin(self.params.stmin)]))

    def _consecutive(self, t: float, data: bytes) -> None:
        rx = self._rx
        if rx is None:
            if not self._rx_dropped:
                self._drop_rx(t, "unexpected consecutive frame",
                              f"{_show(self.rx_id, data)} is a CF with no FF before it")
            return
        sn = data[0] & 0x0F
        if sn != rx.sn:
            self._drop_rx(t, "sequence number", f"{_show(self.rx_id, data)} is a CF with SN {sn} where {rx.sn} "
                          f"was due; the message is dropped")
            return
        need = min(7, rx.length - len(rx.buffer))
        if len(data) - 1 < need:
            self._drop_rx(t, "length", f"{_show(self.rx_id, data)} is a CF with {len(data) - 1} data bytes where "
                          f"{need} were due; the message is dropped")
            return
        rx.buffer += data[1:1 + need]
        rx.sn = (rx.sn + 1) & 0x0F
        rx.last, rx.deadline = data, t + self.params.n_cr
        if len(rx.buffer) >= rx.length:
            self.received.append((t, bytes(rx.buffer)))
            self._rx = None
        elif self.params.block_size:
            rx.block_left -= 1
            if rx.block_left == 0:
                rx.block_left = self.params.block_size
                self._send(bytes([0x30 | _CTS, self.params.block_size, _encode_stmin(self.params.stmin)]))

    def _flow_control(self, t: float, data: bytes) -> None:
        tx = self._tx
        if tx is None or not tx.waiting:
            if not (tx is None and self._tx_dropped):
                doing = "nothing is being sent" if tx is None else "consecutive frames are due"
                self._problem(t, "unexpected flow control", f"{_show(self.rx_id, data)} is an FC while {doing}; "
                              f"ignored")
            return
        status = data[0] & 0x0F
        if status == _CTS:
            tx.waiting, tx.waits = False, 0
            tx.bs = tx.block_left = data[1]
            tx.stmin = _decode_stmin(data[2])
            tx.due = max(t, tx.last_cf + tx.stmin)   # the peer's STmin holds between any two CFs, across an FC
        elif status == _WAIT:
            tx.waits += 1
            if tx.waits > self.params.wft_max:
                self._drop_tx(t, "FC WAIT limit", f"{_show(self.rx_id, data)} is FC WAIT number {tx.waits}, more "
                              f"than wft_max {self.params.wft_max}; the message is dropped")
            else:
                tx.deadline = t + self.params.n_bs
        elif status == _OVFLW:
            self._drop_tx(t, "flow control overflow", f"{_show(self.rx_id, data)} is FC OVFLW: the receiver "
                          f"refused the {len(tx.payload)}-byte message")
            self._tx_dropped = False      # the receiver said its last word: a further FC is a fault of its own
        else:
            self._drop_tx(t, "flow status", f"{_show(self.rx_id, data)} is an FC with the reserved flow status "
                          f"{status}; the message is dropped")

    # -- time and problems ----------------------------------------------------------------------------------
    def _expire(self, t: float) -> None:
        tx, rx = self._tx, self._rx
        if tx is not None and tx.waiting and t > tx.deadline:
            self._drop_tx(tx.deadline, "N_Bs timeout", f"{_show(self.tx_id, tx.last)} got no flow control on "
                          f"{canid.text(self.rx_id)} within N_Bs {self.params.n_bs:g} s; the message is dropped")
        if rx is not None and t > rx.deadline:
            self._drop_rx(rx.deadline, "N_Cr timeout", f"{_show(self.rx_id, rx.last)} was followed by no CF "
                          f"within N_Cr {self.params.n_cr:g} s; the message ({len(rx.buffer)} of {rx.length} "
                          f"bytes) is dropped")

    def _drop_tx(self, t: float, rule: str, text: str) -> None:
        self._problem(t, rule, text)
        self._tx, self._tx_dropped = None, True

    def _drop_rx(self, t: float, rule: str, text: str) -> None:
        self._problem(t, rule, text)
        self._rx, self._rx_dropped = None, True

    def _problem(self, t: float, rule: str, text: str) -> None:
        self.problems.append(IsoTpProblem(t, rule, text))


# -- the monitor's check --------------------------------------------------------------------------------------
_IDLE, _AWAIT_FC, _AWAIT_CF = 0, 1, 2


@dataclass(slots=True)
class _Transfer:
    """One direction of a connection as the bus shows it: data frames on data_id, their FCs on fc_id."""

    data_id: int
    fc_id: int
    phase: int = _IDLE
    length: int = 0
    got: int = 0
    sn: int = 0
    block_left: int = 0
    waits: int = 0
    deadline: float = 0.0
    last: tuple[int, bytes] = (0, b"")
    dropped: bool = False       # given up after a problem: the rest of it is the same fault, not reported again
    payload: bytearray = field(default_factory=bytearray)   # the message's bytes so far (for on_message)


class IsoTpFraming:
    """Checks the ISO-TP framing of one connection (two ids) as a bus monitor sees it, without sending.

    A monitor learns time only from frames: a missing FC or CF is found by the next frame after its deadline
    (or by `check_timeouts`), and reported once, at the moment its timeout ran out. Each direction is
    followed as its receiver would: after a problem the message is given up and its remaining frames are not
    reported again.

    `on_message(t, data_id, payload)`, when given, gets each whole message as its receiver would take it: an SF's
    data, or an FF's once its last CF came (t: that frame's), the padding cut off by the SF_DL / FF_DL. So the
    run log shows UDS messages from the same reading of the frames as the monitor's judgement (bench.log.diaglog).
    A functional request is single frames only (no flow control answers it): give its id as both ids.
    """

    def __init__(self, a_id: int, b_id: int, params: IsoTpParams = IsoTpParams(),
                 on_message: Callable[[float, int, bytes], None] | None = None) -> None:
        self.params = params
        self.on_message = on_message
        self._transfers = {a_id: _Transfer(a_id, b_id), b_id: _Transfer(b_id, a_id)}

    def on_frame(self, t: float, frame_id: int, data: bytes) -> list[IsoTpProblem]:
        """The problems this frame reveals (none for a frame of another id)."""
        if frame_id not in self._transfers:
            return []
        problems = self.check_timeouts(t)
        data = bytes(data)
        bad = _malformed(data)
        if bad is not None:
            problems.append(IsoTpProblem(t, bad[0], f"{_show(frame_id, data)} {bad[1]}"))
            return problems
        kind = data[0] >> 4
        if kind == _FC:
            # an FC on one id steers the data of the other
            other = self._transfers[frame_id].fc_id
            self._flow_control(t, self._transfers[other], data, problems)
        else:
            self._data(t, self._transfers[frame_id], kind, data, problems)
        return problems

    def check_timeouts(self, t: float) -> list[IsoTpProblem]:
        """N_Bs or N_Cr expired by t with nothing since: each reported once."""
        problems: list[IsoTpProblem] = []
        for tr in self._transfers.values():
            if tr.phase == _IDLE or t <= tr.deadline:
                continue
            frame = _show(*tr.last)
            if tr.phase == _AWAIT_FC:
                self._drop(tr, problems, tr.deadline, "N_Bs timeout", f"{frame} got no flow control on "
                           f"{canid.text(tr.fc_id)} within N_Bs {self.params.n_bs:g} s")
            else:
                self._drop(tr, problems, tr.deadline, "N_Cr timeout", f"{frame} was followed by no CF on "
                           f"{canid.text(tr.data_id)} within N_Cr {self.params.n_cr:g} s")
        return problems

    def _data(self, t: float, tr: _Transfer, kind: int, data: bytes, problems: list[IsoTpProblem]) -> None:
        frame = _show(tr.data_id, data)
        if kind in (_SF, _FF):
            if tr.phase != _IDLE:
                problems.append(IsoTpProblem(t, "interrupted", f"{frame} starts a new message while {tr.got} of "
                                             f"{tr.length} bytes of the previous one were sent"))
            tr.dropped = tr.phase != _IDLE      # the old message's rest, should it still come, is the same fault
            tr.phase = _IDLE
            if kind == _FF:
                tr.length, start = _ff_length(data)
                tr.got, tr.sn, tr.waits = _FRAME_LEN - start, 1, 0
                tr.phase, tr.deadline, tr.last = _AWAIT_FC, t + self.params.n_bs, (tr.data_id, data)
                if self.on_message is not None:
                    tr.payload = bytearray(data[start:])
            elif self.on_message is not None:
                self.on_message(t, tr.data_id, data[1:1 + (data[0] & 0x0F)])
            return
        if tr.phase != _AWAIT_CF:
            if not tr.dropped:
                why = "with no FF before it" if tr.phase == _IDLE else "before the flow control that allows it"
                self._drop(tr, problems, t, "unexpected consecutive frame", f"{frame} is a CF {why}")
            return
        sn = data[0] & 0x0F
        if sn != tr.sn:
            self._drop(tr, problems, t, "sequence number", f"{frame} is a CF with SN {sn} where {tr.sn} was due")
            return
        need = min(7, tr.length - tr.got)
        if len(data) - 1 < need:
            self._drop(tr, problems, t, "length", f"{frame} is a CF with {len(data) - 1} data bytes where {need} "
                       f"were due")
            return
        tr.got += need
        tr.sn = (tr.sn + 1) & 0x0F
        tr.last = (tr.data_id, data)
        if self.on_message is not None:
            tr.payload += data[1:1 + need]
        if tr.got >= tr.length:
            tr.phase = _IDLE
            if self.on_message is not None:
                payload, tr.payload = bytes(tr.payload), bytearray()
                self.on_message(t, tr.data_id, payload)
        elif tr.block_left:
            tr.block_left -= 1
            if tr.block_left == 0:
                tr.phase, tr.deadline = _AWAIT_FC, t + self.params.n_bs
                return
        tr.deadline = t + self.params.n_cr

    def _flow_control(self, t: float, tr: _Transfer, data: bytes, problems: list[IsoTpProblem]) -> None:
        frame = _show(tr.fc_id, data)
        if tr.phase != _AWAIT_FC:
            if not tr.dropped:
                why = f"with no FF on {canid.text(tr.data_id)} before it" if tr.phase == _IDLE else \
                    "while consecutive frames were due"
                problems.append(IsoTpProblem(t, "unexpected flow control", f"{frame} is an FC {why}"))
            return
        status = data[0] & 0x0F
        tr.last = (tr.fc_id, data)
        if status == _CTS:
            tr.phase, tr.waits = _AWAIT_CF, 0
            tr.block_left = data[1]
            tr.deadline = t + self.params.n_cr
        elif status == _WAIT:
            tr.waits += 1
            if tr.waits > self.params.wft_max:
                self._drop(tr, problems, t, "FC WAIT limit", f"{frame} is FC WAIT number {tr.waits}, more than "
                           f"wft_max {self.params.wft_max}")
            else:
                tr.deadline = t + self.params.n_bs
        elif status == _OVFLW:
            self._drop(tr, problems, t, "flow control overflow", f"{frame} is FC OVFLW: the receiver refused the "
                       f"{tr.length}-byte message on {canid.text(tr.data_id)}")
            tr.dropped = False     # nothing more is due; a CF after it is the sender's own fault
        else:
            self._drop(tr, problems, t, "flow status", f"{frame} is an FC with the reserved flow status {status}")

    @staticmethod
    def _drop(tr: _Transfer, problems: list[IsoTpProblem], t: float, rule: str, text: str) -> None:
        problems.append(IsoTpProblem(t, rule, text))
        tr.phase, tr.dropped = _IDLE, True
