"""The E2E receiver (docs/spec/e2e.md "Receiver"): the state machine's transition table row by row, the
consumer rule, and every counter pattern of the document with its statuses, states and verdicts.

Expected values come from the document, never from bench.e2e: its two tables are parsed here (so the document
and the tests cannot drift), and its rules are written once more as a small model (`Model`: the check
statuses, E2E_SM with one window and the consumer rule, from the document's text). Frames are built with
tests/reference.py's CRC. The bench is driven three ways: its StateMachine, its Receiver fed through the
message's Protection (the profile's check by the `autosar-e2e` library), and its Monitor (the consumer).
"""

from __future__ import annotations

import itertools
import operator
import re
from collections import deque
from dataclasses import dataclass, field

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bench import e2e
from bench.checks.monitor import Monitor
from bench.database.codec import Codebook
from tests import repo
from tests.reference import COUNTER_VALUES, protected

E2E_DOC = repo.ROOT / "docs" / "spec" / "e2e.md"
MESSAGE = "DRV_MotionRequest"
FRAME_ID = 0x102           # its DataID too (docs/spec/e2e.md: DataID = the CAN identifier)
CYCLE_MS = 20
TIMEOUT_MS = 3 * CYCLE_MS  # the consumer's deadline

STATUSES = ("OK", "OKSOMELOST", "REPEATED", "WRONGSEQUENCE", "ERROR")
STATES = ("NODATA", "INIT", "VALID", "INVALID")
#: The state machine's parameters by AUTOSAR name (the document's) -> SMConfig's fields.
SM_NAMES = {"WindowSize": "window_size", "MinOkStateInit": "min_ok_init", "MaxErrorStateInit": "max_error_init",
            "MinOkStateValid": "min_ok_valid", "MaxErrorStateValid": "max_error_valid",
            "MinOkStateInvalid": "min_ok_invalid", "MaxErrorStateInvalid": "max_error_invalid"}
#: The contract's values (docs/spec/e2e.md "The contract's protection"), checked against the document below.
CONTRACT = {"WindowSize": 2, "MinOkStateInit": 1, "MaxErrorStateInit": 0, "MinOkStateValid": 2,
            "MaxErrorStateValid": 0, "MinOkStateInvalid": 2, "MaxErrorStateInvalid": 0}
CONTRACT_MAX_DELTA = 2


def _doc() -> str:
    return E2E_DOC.read_text(encoding="utf-8")


def _table(header_start: str) -> list[list[str]]:
    """The rows (cells) of the document's table whose header line starts with `header_start`."""
    lines = _doc().splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith(header_start)) + 2   # header, |---|
    rows = []
    for line in lines[start:]:
        if not line.startswith("|"):
            break
        cells = re.split(r"(?<!\\)\|", line.strip()[1:-1])
        rows.append([cell.strip().replace("\\|", "|") for cell in cells])
    return rows


# -- the model, from the document's text ------------------------------------------------------------------
@dataclass
class Model:
    """docs/spec/e2e.md "Receiver": check statuses, E2E_SM with one window, the consumer rule."""

    params: dict[str, int] = field(default_factory=lambda: dict(CONTRACT))
    max_delta: int = CONTRACT_MAX_DELTA
    values: int = COUNTER_VALUES
    state: str = "NODATA"
    last: int = -1
    window: deque = field(init=False)

    def __post_init__(self) -> None:
        self.last = self.values - 1                      # the counter's largest value
        self.window = deque([None] * self.params["WindowSize"], maxlen=self.params["WindowSize"])

    def check(self, counter: int | None) -> str:
        """`counter`: the frame's counter when its CRC and length are right, None when not."""
        if counter is None or not 0 <= counter < self.values:
            return "ERROR"                               # the counter is not read: last stays
        delta = (counter - self.last) % self.values
        self.last = counter
        if delta == 1:
            return "OK"
        if delta == 0:
            return "REPEATED"
        return "OKSOMELOST" if delta <= self.max_delta else "WRONGSEQUENCE"

    def step(self, status: str) -> str:
        p = self.params
        if self.state == "NODATA":
            if status != "ERROR":
                self.window = deque([None] * p["WindowSize"], maxlen=p["WindowSize"])
                self.state = "INIT"
            return self.state
        self.window.append(status)
        ok = sum(s in ("OK", "OKSOMELOST") for s in self.window)
        errors = sum(s == "ERROR" for s in self.window)
        if self.state == "INIT":
            if errors <= p["MaxErrorStateInit"] and ok >= p["MinOkStateInit"]:
                self.state = "VALID"
            elif errors > p["MaxErrorStateInit"]:
                self.state = "INVALID"
        elif self.state == "VALID":
            if not (errors <= p["MaxErrorStateValid"] and ok >= p["MinOkStateValid"]):
                self.state = "INVALID"
        elif errors <= p["MaxErrorStateInvalid"] and ok >= p["MinOkStateInvalid"]:
            self.state = "VALID"
        return self.state

    def receive(self, counter: int | None) -> tuple[str, str, bool]:
        status = self.check(counter)
        state = self.step(status)
        return status, state, state == "VALID" and status in ("OK", "OKSOMELOST")


def _config(params: dict[str, int]) -> e2e.SMConfig:
    return e2e.SMConfig(**{SM_NAMES[name]: value for name, value in params.items()})


def test_the_documents_parameters_are_the_models() -> None:
    """The table "The contract's protection" gives the values the model (and the tables below) assume."""
    rows = {row[0]: row[1] for row in _table("| parameter | value |")}
    assert rows["Profile"] == "P11" and rows["DataIDMode"] == "BOTH"
    assert rows["Offset"].startswith("48 bits") and rows["DataLength"].startswith("64 bits")
    assert int(rows["MaxDeltaCounter"]) == CONTRACT_MAX_DELTA
    assert int(rows["WindowSize"]) == CONTRACT["WindowSize"]
    for state in ("Init", "Valid", "Invalid"):
        ok, error = (int(v) for v in rows[f"MinOkState{state} / MaxErrorState{state}"].split("/"))
        assert (ok, error) == (CONTRACT[f"MinOkState{state}"], CONTRACT[f"MaxErrorState{state}"])


def test_every_contract_message_is_protected_as_the_document_says(codebook: Codebook) -> None:
    """Both databases: Profile 11, DataID = the identifier, DataIDMode BOTH, CRC byte 6, counter bits 56-59
    (0 ... 14), the whole frame, and the contract's receiver parameters."""
    for codec in codebook.by_id.values():
        if codec.diagnostic:
            assert codec.protection is None, codec.name   # ISO-TP: docs/contract/diagnostics.md DIAG-TP-01
            continue
        p = codec.protection
        assert p is not None, codec.name
        assert (p.profile, p.data_id, p.data_id_mode) == ("P11", codec.frame_id, "BOTH"), codec.name
        assert (p.crc.start, p.crc.length, p.counter.start, p.counter.length) == (48, 8, 56, 4), codec.name
        assert p.counter_modulo == COUNTER_VALUES and p.length in (0, 8), codec.name
        assert p.max_delta_counter == CONTRACT_MAX_DELTA and p.sm == _config(CONTRACT), codec.name


# -- the transition table, row by row -----------------------------------------------------------------------
TRANSITIONS_HEADER = "| state | status | condition | next state | window |"
CONDITION = re.compile(r"(\w+) (≤|≥|<|>) (\w+)")
OPERATORS = {"≤": operator.le, "≥": operator.ge, "<": operator.lt, ">": operator.gt}
#: Window parameters the rows are driven with: the contract's and others (a wider window, errors allowed).
CONFIGS = [
    CONTRACT,
    {"WindowSize": 3, "MinOkStateInit": 1, "MaxErrorStateInit": 1, "MinOkStateValid": 2, "MaxErrorStateValid": 1,
     "MinOkStateInvalid": 2, "MaxErrorStateInvalid": 0},
    {"WindowSize": 3, "MinOkStateInit": 2, "MaxErrorStateInit": 0, "MinOkStateValid": 1, "MaxErrorStateValid": 2,
     "MinOkStateInvalid": 3, "MaxErrorStateInvalid": 0},
    {"WindowSize": 1, "MinOkStateInit": 1, "MaxErrorStateInit": 0, "MinOkStateValid": 1, "MaxErrorStateValid": 0,
     "MinOkStateInvalid": 1, "MaxErrorStateInvalid": 0},
]


def _transitions() -> list[list[str]]:
    return _table(TRANSITIONS_HEADER)


def _statuses(cell: str) -> tuple[str, ...]:
    return STATUSES if cell == "any" else tuple(s.strip() for s in cell.split(","))


def _holds(condition: str, ok: int, errors: int, params: dict[str, int]) -> bool:
    """A condition cell: "always", "otherwise" (true here: the earlier rows are tried first) or comparisons
    of OkCount, ErrorCount and parameters joined by "and"."""
    if condition in ("always", "otherwise"):
        return True
    values = {"OkCount": ok, "ErrorCount": errors, **params}
    parts = condition.split(" and ")
    found = [CONDITION.fullmatch(part) for part in parts]
    assert all(found), f"unreadable condition {condition!r}"
    return all(OPERATORS[m.group(2)](values[m.group(1)], values[m.group(3)]) for m in found if m)


def _row_for(rows: list[list[str]], state: str, status: str, window: tuple, params: dict[str, int]) -> int:
    """Index of the row that applies: the first of the state's rows for the status whose condition holds,
    with the counts after the status is added to the window."""
    after = (*window[1:], status)
    ok = sum(s in ("OK", "OKSOMELOST") for s in after)
    errors = after.count("ERROR")
    for i, (row_state, row_status, condition, _, _) in enumerate(rows):
        if row_state == state and status in _statuses(row_status) and _holds(condition, ok, errors, params):
            return i
    raise AssertionError(f"no row for {state} {status}")


def test_the_table_covers_every_state_and_status() -> None:
    rows = _transitions()
    assert {row[0] for row in rows} == set(STATES)
    assert {row[3] for row in rows} <= set(STATES)
    for state in STATES:
        for status in STATUSES:    # each state has a last row that always applies: no status falls through
            last = [row for row in rows if row[0] == state and status in _statuses(row[1])][-1]
            assert last[2] in ("always", "otherwise"), (state, status)


def _bench_sm(params: dict[str, int], state: str, window: tuple) -> e2e.StateMachine:
    """The bench's state machine put in `state` with `window` (oldest first) as its last statuses."""
    sm = e2e.StateMachine(_config(params))
    sm.state = e2e.SMState[state]
    sm.window = [None if s is None else e2e.Status[s] for s in window]
    sm.top = 0                       # the oldest place is the next to be written
    return sm


def _bench_window(sm: e2e.StateMachine) -> tuple:
    ordered = sm.window[sm.top:] + sm.window[:sm.top]
    return tuple(None if s is None else s.value for s in ordered)


@pytest.mark.parametrize("index", range(len(_transitions())),
                         ids=[f"{r[0]} {r[1]} {r[2]}" for r in _transitions()])
def test_every_row_of_the_transition_table(index: int) -> None:
    """The row's state, every status it names and every window content for which the row applies (under the
    contract's parameters and three others): the bench's StateMachine and the model both go to the row's next
    state and do to the window what the row says."""
    rows = _transitions()
    state, status_cell, _, next_state, window_rule = rows[index]
    driven = 0
    for params in CONFIGS:
        size = params["WindowSize"]
        for window in itertools.product((None, *STATUSES), repeat=size):
            for status in _statuses(status_cell):
                if _row_for(rows, state, status, window, params) != index:
                    continue
                driven += 1
                sm = _bench_sm(params, state, window)
                assert sm.step(e2e.Status[status]) is e2e.SMState[next_state], (params, window, status)
                model = Model(dict(params))
                model.state, model.window = state, deque(window, maxlen=size)
                assert model.step(status) == next_state
                expected_window = {"unchanged": window, "cleared, the status is not added": (None,) * size,
                                   "the status is added": (*window[1:], status)}[window_rule]
                assert _bench_window(sm) == tuple(model.window) == expected_window
    assert driven, "no window reaches this row"


@pytest.mark.parametrize("state", STATES)
@pytest.mark.parametrize("status", STATUSES)
def test_the_consumer_rule(state: str, status: str) -> None:
    """docs/spec/e2e.md "Consumer rule": applied when the status is OK or OKSOMELOST and the state is VALID
    after the frame; bench.e2e.Receiver says so for every state and status."""
    assert ("**A frame is applied when its status is OK or OKSOMELOST and the state is VALID after it**"
            in " ".join(_doc().split()))
    counters = {"OK": 0, "OKSOMELOST": 1, "REPEATED": 14, "WRONGSEQUENCE": 5, "ERROR": None}   # after last = 14
    for window in itertools.product((None, *STATUSES), repeat=2):
        rx = e2e.Receiver(COUNTER_VALUES, CONTRACT_MAX_DELTA, _config(CONTRACT))
        rx.sm = _bench_sm(CONTRACT, state, window)
        got, applied = rx.receive(counters[status])
        assert got is e2e.Status[status]
        assert applied == (rx.state is e2e.SMState.VALID and status in ("OK", "OKSOMELOST"))


def test_the_check_starts_at_the_counters_largest_value() -> None:
    for modulo in (15, 16, 256):
        rx = e2e.Receiver(modulo, 2, _config(CONTRACT))
        assert rx.next == 0 and rx.check(0) is e2e.Status.OK
        assert e2e.Receiver(modulo, 2, _config(CONTRACT)).check(modulo) is e2e.Status.ERROR


_STATUS = st.sampled_from(STATUSES)


@st.composite
def _sm_params(draw) -> dict[str, int]:
    size = draw(st.integers(1, 5))
    params = {"WindowSize": size}
    for state in ("Init", "Valid", "Invalid"):
        ok = draw(st.integers(0, size))
        params[f"MinOkState{state}"] = ok
        params[f"MaxErrorState{state}"] = draw(st.integers(0, size - ok))
    return params


@settings(max_examples=300, deadline=None)
@given(params=st.one_of(st.just(CONTRACT), _sm_params()), statuses=st.lists(_STATUS, max_size=80))
def test_random_status_sequences_give_the_models_states(params: dict[str, int], statuses: list[str]) -> None:
    sm = e2e.StateMachine(_config(params))
    model = Model(dict(params))
    for status in statuses:
        assert sm.step(e2e.Status[status]).value == model.step(status)


@settings(max_examples=300, deadline=None)
@given(max_delta=st.integers(1, 7), counters=st.lists(st.one_of(st.none(), st.integers(0, 15)), max_size=80))
def test_random_counters_give_the_models_statuses_and_verdicts(max_delta: int, counters: list[int | None]) -> None:
    rx = e2e.Receiver(COUNTER_VALUES, max_delta, _config(CONTRACT))
    model = Model(max_delta=max_delta)
    for counter in counters:
        status, applied = rx.receive(counter)
        assert (status.value, rx.state.value, applied) == model.receive(counter)


# -- the counter patterns -------------------------------------------------------------------------------------
PATTERNS_HEADER = "| pattern | frames | statuses | states | applied | why |"
TOKEN = re.compile(r"\[\d+(?:…\d+)? \w+\]|\(\d+ ms\)|\S+")


@dataclass(frozen=True)
class Frame:
    t_ms: int
    counter: int
    kind: str = "intact"     # "bad": a wrong CRC, "short": 7 bytes


def _repeat(cell: str) -> list[str]:
    """Tokens of a statuses/states/applied cell, `X×N` written out."""
    out: list[str] = []
    for token in cell.split():
        word, _, times = token.partition("×")
        out += [word] * (int(times) if times else 1)
    return out


def _frames(cell: str) -> tuple[list[Frame], int]:
    """The frames of a pattern and the index of the first after `|`."""
    frames: list[Frame] = []
    start = 0
    t = -CYCLE_MS
    pause = None
    for token in TOKEN.findall(cell):
        if token == "|":
            start = len(frames)
            continue
        if token.startswith("("):
            pause = int(token[1:].split()[0])
            continue
        if token.startswith("["):
            numbers, kind = token[1:-1].split()
            first, _, last = numbers.partition("…")
            counters = list(range(int(first), int(last or first) + 1))
        else:
            number, _, times = token.partition("×")
            counters, kind = [int(number)] * (int(times) if times else 1), "intact"
        for counter in counters:
            t += CYCLE_MS if pause is None else pause
            pause = None
            frames.append(Frame(t, counter, kind))
    return frames, start


def _wire(index: int, frame: Frame) -> bytes:
    """The frame on the bus: byte 0 carries its index (PivotX = 0.02 m x index), so the applied values show
    which frame was applied."""
    data = bytearray(protected(FRAME_ID, bytes([index & 0x7F, 0, 0, 0, 0, 0, 0, 0]), frame.counter))
    if frame.kind == "bad":
        data[6] ^= 0x5A
    return bytes(data[:7]) if frame.kind == "short" else bytes(data)


def _patterns() -> list[list[str]]:
    return _table(PATTERNS_HEADER)


def test_the_patterns_table_is_complete() -> None:
    """Every pattern the issue asks for is a row (the names the document gives them)."""
    names = {row[0] for row in _patterns()}
    for name in ("start-up", "in sequence, wrap", "frozen for 1 s", "end of a freeze", "skip 1 (a lost frame)",
                 "skip 2", "one step back", "counting down", "delayed (stale) frame", "wrong CRC", "CRC burst",
                 "lost frame and a bad CRC", "timeout then resume", "a counter of 15", "wrong length"):
        assert name in names
    assert any(name.startswith("two interleaved senders") for name in names)
    for row in _patterns():        # one status, state and verdict per frame after `|`
        frames, start = _frames(row[1])
        assert len(_repeat(row[2])) == len(_repeat(row[3])) == len(_repeat(row[4])) == len(frames) - start, row[0]


@pytest.mark.parametrize("row", _patterns(), ids=lambda row: row[0])
def test_counter_pattern(codebook: Codebook, row: list[str]) -> None:
    """One row of docs/spec/e2e.md "Counter patterns": the model, the bench's Receiver fed through the
    message's Protection (the library's check), and the Monitor each give the row's statuses, states and
    verdicts for the frames after `|`."""
    name, frames_cell, statuses_cell, states_cell, applied_cell, _ = row
    frames, start = _frames(frames_cell)
    statuses, states = _repeat(statuses_cell), _repeat(states_cell)
    applied = [token == "a" for token in _repeat(applied_cell)]
    assert set(_repeat(applied_cell)) <= {"a", "x"}
    wires = [_wire(i, f) for i, f in enumerate(frames)]

    model = Model()
    got = [model.receive(f.counter if f.kind == "intact" else None) for f in frames]
    assert [g[0] for g in got[start:]] == statuses, name
    assert [g[1] for g in got[start:]] == states, name
    assert [g[2] for g in got[start:]] == applied, name

    codec = codebook[MESSAGE]
    protection = codec.protection
    assert protection is not None
    rx = e2e.Receiver(protection.counter_modulo, protection.max_delta_counter, protection.sm)
    bench = []
    for data in wires:
        status, ok = rx.receive(protection.counter_if_intact(data) if len(data) == codec.length else None)
        bench.append((status.value, rx.state.value, ok))
    assert bench == got, name

    monitor = Monitor(codebook, keep_history=True)
    verdicts = [monitor.on_frame(f.t_ms / 1000.0, FRAME_ID, wires[i], "rx") for i, f in enumerate(frames)]
    assert verdicts[start:] == applied, name
    assert verdicts == [g[2] for g in got], name
    counts: dict[str, int] = {}
    for status, _, _ in got:
        counts[status] = counts.get(status, 0) + 1
    assert monitor.state(MESSAGE).e2e_status == counts


# -- the patterns' consequences for the consumer (the "why" column) -------------------------------------------
def _steady(counters: list[int], start_ms: int = 0) -> list[Frame]:
    return [Frame(start_ms + CYCLE_MS * i, c % COUNTER_VALUES) for i, c in enumerate(counters)]


def _feed(codebook: Codebook, frames: list[Frame]) -> tuple[Monitor, list[bool]]:
    monitor = Monitor(codebook, keep_history=True)
    return monitor, [monitor.on_frame(f.t_ms / 1000.0, FRAME_ID, _wire(i, f), "rx") for i, f in enumerate(frames)]


def _model_verdicts(frames: list[Frame]) -> list[bool]:
    model = Model()
    return [model.receive(f.counter if f.kind == "intact" else None)[2] for f in frames]


def _applied_index(monitor: Monitor) -> int:
    latest = monitor.state(MESSAGE).latest
    assert latest is not None
    return round(latest["PivotX"] / 0.02)


def test_frozen_counter_for_one_second_applies_nothing(codebook: Codebook) -> None:
    """Issue 14, acceptance 3: 50 frames (1 s at 20 ms) with the counter frozen at its last value: none applied.
    The consumer sees the message timed out 3 cycles after the last applied frame, once, for the whole second;
    each frame is rejected as "E2E REPEATED"."""
    good = _steady(list(range(11)))                              # counters 0..10, the last applied one is 10
    frozen = [Frame(good[-1].t_ms + CYCLE_MS * (i + 1), 10) for i in range(50)]
    frames = good + frozen
    monitor, verdicts = _feed(codebook, frames)
    assert verdicts == _model_verdicts(frames)
    assert verdicts[11:].count(True) == 0
    state = monitor.state(MESSAGE)
    assert state.last_valid == pytest.approx(good[-1].t_ms / 1000.0)
    assert _applied_index(monitor) == 10
    assert state.timeouts == [pytest.approx((good[-1].t_ms + TIMEOUT_MS) / 1000.0)]
    assert monitor.timed_out(MESSAGE, frames[-1].t_ms / 1000.0)
    assert state.invalid == {"counter": 50}          # the frozen ones (the first frame, INIT, is not invalid)
    assert all(r.reason == "E2E REPEATED: counter 10 again, state INVALID" for r in monitor.invalid_log[1:])


def test_end_of_a_freeze_names_each_rejection(codebook: Codebook) -> None:
    frames = _steady(list(range(11)) + [10] * 5 + [13, 14, 0])
    monitor, verdicts = _feed(codebook, frames)
    assert verdicts[-3:] == [False, False, True]
    assert [r.reason for r in monitor.invalid_log[-2:]] == [
        "E2E WRONGSEQUENCE: counter 13, expected 11, state INVALID",
        "E2E OK: counter 14 in sequence, state INVALID (not VALID yet)"]


@pytest.mark.parametrize("lead", range(COUNTER_VALUES))
def test_two_interleaved_senders(codebook: Codebook, lead: int) -> None:
    """A second sender B at the same rate, half a cycle before each frame of A, its counter `lead` ahead of the
    one A sends next: while both send, nothing is applied but, for lead 0 or 1, B's first frame (it carries a
    counter A could have sent). Once B stops, A alone is applied again by its third frame at the latest."""
    a = _steady(list(range(10)))                                     # A alone: VALID, last counter 9
    both = []
    for i in range(40):
        t = a[-1].t_ms + CYCLE_MS * (i + 1)
        both += [Frame(t - CYCLE_MS // 2, (10 + lead + i) % COUNTER_VALUES), Frame(t, (10 + i) % COUNTER_VALUES)]
    after = [Frame(both[-1].t_ms + CYCLE_MS * (i + 1), (50 + i) % COUNTER_VALUES) for i in range(5)]
    frames = a + both + after
    _, verdicts = _feed(codebook, frames)
    assert verdicts == _model_verdicts(frames)
    while_both = verdicts[10:10 + len(both)]
    assert while_both.count(True) == (1 if lead in (0, 1) else 0)
    assert lead not in (0, 1) or while_both[0]
    assert verdicts[-3:] == [True, True, True]


def test_delayed_stale_frame_is_never_applied(codebook: Codebook) -> None:
    """Counter 9 arriving after 13 (a stale frame delivered late): neither it nor the next two frames are
    applied; the values applied never go back to the stale frame's."""
    frames = _steady([10, 11, 12, 13]) + [Frame(70, 9)] + [Frame(80 + CYCLE_MS * i, c) for i, c in
                                                         enumerate([14, 0, 1, 2])]
    monitor, verdicts = _feed(codebook, frames)
    assert verdicts == _model_verdicts(frames) == [False, True, True, True, False, False, False, True, True]
    _, x = monitor.history(MESSAGE, "PivotX")
    assert [round(v / 0.02) for v in x] == [1, 2, 3, 7, 8]          # frame 4 (the stale one) never applied
    assert monitor.invalid_log[0].reason == "E2E WRONGSEQUENCE: counter 9, expected 14, state INVALID"


def test_a_bad_crc_costs_two_frames_and_no_timeout(codebook: Codebook) -> None:
    """A frame with a wrong CRC and the next one are rejected; the frame after is applied 3 cycles after the
    last applied one: not a timeout (more than 3 cycles)."""
    frames = _steady([2, 3, 4, 5, 6])
    frames[2] = Frame(frames[2].t_ms, 4, "bad")
    monitor, verdicts = _feed(codebook, frames)
    assert verdicts == _model_verdicts(frames) == [False, True, False, False, True]
    assert [r.reason for r in monitor.invalid_log] == [
        "E2E ERROR: CRC wrong, state INVALID", "E2E OKSOMELOST: counter 5 in sequence, state INVALID (not VALID yet)"]
    assert monitor.state(MESSAGE).timeouts == []


def test_a_crc_burst_times_the_consumer_out(codebook: Codebook) -> None:
    frames = _steady([2, 3] + list(range(4, 14)) + [14, 0, 1])
    frames[2:12] = [Frame(f.t_ms, f.counter, "bad") for f in frames[2:12]]
    monitor, verdicts = _feed(codebook, frames)
    assert verdicts == _model_verdicts(frames)
    assert verdicts[2:] == [False] * 12 + [True]
    assert monitor.state(MESSAGE).timeouts == [pytest.approx((frames[1].t_ms + TIMEOUT_MS) / 1000.0)]
    assert monitor.state(MESSAGE).invalid["checksum"] == 10


def test_a_wrong_length_is_an_error_of_the_message(codebook: Codebook) -> None:
    """Issue 26: a 7-byte frame of DRV_MotionRequest is a frame of the message with the status ERROR (its
    counter is not read), counted as a rejected frame of it (reason "length")."""
    frames = _steady([2, 3, 4, 5, 6])
    frames[2] = Frame(frames[2].t_ms, 4, "short")
    monitor, verdicts = _feed(codebook, frames)
    assert verdicts == [False, True, False, False, True]
    state = monitor.state(MESSAGE)
    assert state.e2e_status["ERROR"] == 1 and state.invalid["length"] == 1
    assert monitor.invalid_log[0].reason == "length 7, DBC says 8"


def test_timeout_then_resume(codebook: Codebook) -> None:
    """Frames stop for 200 ms: the consumer sees a timeout 60 ms after the last applied frame. The receiver has
    no clock: a sender that resumes with another counter is applied at its second frame in sequence, one that
    kept its counter at once."""
    before = _steady(list(range(5)))
    for first, verdicts_after in ((9, [False, False, True, True]), (5, [True] * 4)):
        resume = _steady(list(range(first, first + 4)), start_ms=before[-1].t_ms + 200)
        monitor, verdicts = _feed(codebook, before + resume)
        assert verdicts[5:] == verdicts_after == _model_verdicts(before + resume)[5:]
        assert monitor.state(MESSAGE).timeouts == [pytest.approx((before[-1].t_ms + TIMEOUT_MS) / 1000.0)]


def test_rejected_frames_never_time_themselves_into_acceptance(codebook: Codebook) -> None:
    """Issue 14: a frozen counter sent every 80 ms, or after any pause, is never applied."""
    for gap in (50, 80, 200, 1000):
        frames = _steady([1, 2, 3]) + [Frame(40 + gap * (i + 1), 3) for i in range(20)]
        _, verdicts = _feed(codebook, frames)
        assert verdicts == _model_verdicts(frames)
        assert verdicts[3:].count(True) == 0


# -- generated frames against the model -----------------------------------------------------------------------
_STEP = st.one_of(st.just(1), st.just(1), st.just(0), st.just(2), st.integers(3, 14))   # mostly in sequence
_EVENT = st.tuples(_STEP, st.sampled_from([CYCLE_MS, CYCLE_MS, CYCLE_MS // 2, TIMEOUT_MS, TIMEOUT_MS + 1, 200]),
                   st.sampled_from(["intact"] * 8 + ["bad", "short"]), st.booleans())


@settings(max_examples=300, deadline=None)
@given(start=st.integers(0, 14), events=st.lists(_EVENT, max_size=60))
def test_generated_frames_follow_the_model(codebook: Codebook, start: int,
                                           events: list[tuple[int, int, str, bool]]) -> None:
    """Random steps (mostly +1, some repeats, losses and jumps; now and then a counter of 15), random gaps, and
    about 1 in 5 frames with a wrong CRC or length: the monitor applies exactly the frames the model applies,
    and the last of them is the one it holds."""
    frames = [Frame(0, start)]
    counter = start
    for step, dt, kind, fifteen in events:
        counter = (counter + step) % COUNTER_VALUES
        frames.append(Frame(frames[-1].t_ms + dt, 15 if fifteen and step == 2 else counter, kind))
    monitor, verdicts = _feed(codebook, frames)
    expected = _model_verdicts(frames)
    assert verdicts == expected
    last = max((i for i, ok in enumerate(expected) if ok), default=None)
    state = monitor.state(MESSAGE)
    assert (state.latest is None) == (last is None)
    if last is not None:
        assert _applied_index(monitor) == last & 0x7F
        assert state.last_valid == pytest.approx(frames[last].t_ms / 1000.0)


@pytest.mark.parametrize("first", [0, 7, 13, 14])
def test_a_monitor_that_joins_mid_stream_takes_the_first_counter(codebook: Codebook, first: int) -> None:
    """`bench monitor` joins a running bus (issue 34): a healthy stream that starts at any counter gives OK from
    its first frame, which only moves NODATA to INIT (not applied, as the document's first frame after power-up);
    the second is applied. Without joining, AUTOSAR's check (E2E_P11CheckInit: 0 is due first) gives the first
    frame of a stream that does not start at 0 REPEATED (counter 14, the one before 0) or WRONGSEQUENCE."""
    frames = _steady(list(range(first, first + 5)))
    joined = Monitor(codebook, keep_history=True)
    joined.join_mid_stream()
    verdicts = [joined.on_frame(f.t_ms / 1000.0, FRAME_ID, _wire(i, f), "rx") for i, f in enumerate(frames)]
    assert verdicts == [False, True, True, True, True]
    assert joined.state(MESSAGE).e2e_status == {"OK": 5}
    model = Model()
    expected = model.receive(first)[0]   # the document's model of a receiver started with its sender
    strict, _ = _feed(codebook, frames)
    assert set(strict.state(MESSAGE).e2e_status) - {"OK"} == ({expected} - {"OK"})
    assert expected == ("OK" if first == 0 else "REPEATED" if first == COUNTER_VALUES - 1 else "WRONGSEQUENCE")
