"""The fault memory against ISO 14229-1 Annex D: worked examples, and a state machine checked against a model of
the rules written here from the standard (not from the implementation)."""

from __future__ import annotations

from dataclasses import dataclass

import pytest
from hypothesis import settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, initialize, invariant, rule

from bench.diag.declaration import Dtc, NodeDiagnostics, Protocol, dtc_number
from bench.diag.faultmemory import FaultMemory

# (code, name, confirm s, warning indicator)
DTCS = [("C1A01-1C", "SENSOR", 0.0, True), ("C1A02-00", "SLOW", 0.3, False), ("U0100-87", "LOST", 0.1, True)]


def make_node(snapshot: tuple[int, ...] = (0xDD01,)) -> NodeDiagnostics:
    dtcs = tuple(Dtc(code, dtc_number(code), name, name.lower(), "REQ", "", confirm, warning)
                 for code, name, confirm, warning in DTCS)
    return NodeDiagnostics("ECU", 0x7E0, 0x7E8, 0x1234, (), {}, snapshot, dtcs, ())


SENSOR, SLOW, LOST = (dtc_number(code) for code, *_ in DTCS)


class Clock:
    """The 'provider' of the snapshot: the record holds the bench time (ms) of the capture."""

    def __init__(self) -> None:
        self.ms = 0

    def capture(self) -> bytes:
        return bytes([0x01, 1, 0xDD, 0x01]) + self.ms.to_bytes(4, "big")


def memory(healing: int = 1, aging: int = 3) -> tuple[FaultMemory, Clock]:
    clock = Clock()
    return FaultMemory(make_node(), Protocol(healing_cycles=healing, aging_cycles=aging), clock.capture), clock


def test_power_up_status_is_0x50_for_every_dtc() -> None:
    m, _ = memory()
    assert [m.status(n) for n in (SENSOR, SLOW, LOST)] == [0x50] * 3
    assert m.dtcs_by_mask(0xFF) == [(SENSOR, 0x50), (SLOW, 0x50), (LOST, 0x50)]
    assert m.dtcs_by_mask(0x01) == []
    assert m.snapshot(SENSOR) is None and m.occurrences(SENSOR) == 0


def test_a_failure_with_confirm_0_is_confirmed_at_once_and_requests_the_warning_indicator() -> None:
    m, clock = memory()
    clock.ms = 1000
    m.report(1.0, "SENSOR")
    # testFailed, TFTOC, pending, confirmed, TFSLC, WIR; TNCSLC and TNCTOC cleared
    assert m.status(SENSOR) == 0xAF
    assert m.status(SLOW) == 0x00 and m.status(LOST) == 0x00     # passed: bits 4 and 6 cleared, nothing else
    assert m.occurrences(SENSOR) == 1
    assert m.snapshot(SENSOR) == bytes([0x01, 1, 0xDD, 0x01, 0, 0, 0x03, 0xE8])
    m.report(1.001)
    assert m.status(SENSOR) == 0xAE                                # only testFailed goes
    assert m.dtcs_by_mask(0x01) == [] and m.dtcs_by_mask(0x08) == [(SENSOR, 0xAE)]


def test_confirmation_needs_the_failure_held_for_confirm_seconds_continuously() -> None:
    m, _ = memory()
    m.report(0.0, "SLOW")
    m.report(0.2, "SLOW")
    assert m.status(SLOW) == 0x27                                  # pending, not confirmed
    m.report(0.25)                                                 # passed: the continuous failure is broken
    m.report(0.3, "SLOW")
    m.report(0.55, "SLOW")
    assert not m.status(SLOW) & 0x08
    m.report(0.6, "SLOW")
    assert m.status(SLOW) == 0x2F                                  # confirmed; no warning indicator for SLOW
    assert m.occurrences(SLOW) == 2


def test_the_most_recent_occurrence_s_snapshot_is_kept_and_the_counter_saturates() -> None:
    m, clock = memory()
    for i in range(300):
        clock.ms = i
        m.report(i / 1000, "LOST")
        m.report(i / 1000 + 0.0005)
    assert m.occurrences(LOST) == 255
    assert m.snapshot(LOST) == bytes([0x01, 1, 0xDD, 0x01]) + (299).to_bytes(4, "big")


def test_a_node_without_snapshot_dids_keeps_no_snapshot() -> None:
    m = FaultMemory(make_node(snapshot=()), Protocol(), Clock().capture)
    m.report(0.0, "SENSOR")
    assert m.snapshot(SENSOR) is None and m.occurrences(SENSOR) == 1


def test_operation_cycles_clear_pending_then_heal_then_age() -> None:
    m, _ = memory(healing=1, aging=3)
    m.report(0.0, "SENSOR")
    m.new_operation_cycle()
    # a failing cycle: pending stays; TFTOC 0, TNCTOC 1; testFailed unchanged until the next report
    assert m.status(SENSOR) == 0xAD | 0x40
    m.report(1.0)                                                  # passed in cycle 2
    assert m.status(SENSOR) == 0xAC
    m.new_operation_cycle()                                        # cycle 2 passed: pending 0, healed (1 cycle)
    assert m.status(SENSOR) == 0x68
    m.report(2.0)
    m.new_operation_cycle()
    assert m.status(SENSOR) == 0x68 and m.occurrences(SENSOR) == 1
    m.new_operation_cycle()                                        # a cycle without its test: counts nothing
    m.report(3.0)
    m.new_operation_cycle()                                        # the third passed cycle: aged
    assert m.status(SENSOR) == 0x60
    assert m.snapshot(SENSOR) is None and m.occurrences(SENSOR) == 0


def test_a_failure_in_a_cycle_restarts_the_count_of_passed_cycles() -> None:
    m, _ = memory(healing=2, aging=3)
    m.report(0.0, "SENSOR")
    for t in (1.0, 2.0):
        m.new_operation_cycle()
        m.report(t)
    m.new_operation_cycle()
    m.report(3.0, "SENSOR")
    m.report(3.1)
    for t in (4.0, 5.0):
        m.new_operation_cycle()
        m.report(t)
    m.new_operation_cycle()
    assert m.status(SENSOR) & 0x08                                 # two passed cycles since the failure: not aged
    assert not m.status(SENSOR) & 0x80                             # ... but healed (2 cycles)


def test_clear_all_one_and_unknown() -> None:
    m, _ = memory()
    m.report(0.0, "SENSOR", "LOST")
    assert m.clear(SENSOR)
    assert m.status(SENSOR) == 0x50 and m.snapshot(SENSOR) is None and m.occurrences(SENSOR) == 0
    assert m.status(LOST) == 0x27                                  # LOST confirms after 0.1 s
    assert not m.clear(0x123456)
    assert m.clear(0xFFFFFF)
    assert [m.status(n) for n in (SENSOR, SLOW, LOST)] == [0x50] * 3
    m.report(0.1, "SENSOR", "LOST")                                # the same failed set: tested again after a clear
    assert m.status(SENSOR) == 0xAF and m.occurrences(SENSOR) == 1


def test_an_unchanged_report_returns_before_touching_any_dtc(monkeypatch: pytest.MonkeyPatch) -> None:
    m, _ = memory()
    m.report(0.0, "SENSOR")
    calls: list[float] = []
    original = m._update
    monkeypatch.setattr(m, "_update", lambda t, failed: (calls.append(t), original(t, failed)))
    m.report(0.001, "SENSOR")
    assert calls == []
    m.report(0.002, "SLOW")                                        # changed: the full path, debouncing SLOW
    m.report(0.003, "SLOW")                                        # unchanged but SLOW is debouncing
    assert calls == [0.002, 0.003]
    m.report(0.31, "SLOW")                                         # confirmed now
    m.report(0.32, "SLOW")
    assert calls == [0.002, 0.003, 0.31]
    m.new_operation_cycle()                                        # bits 6 set again: the next report is needed
    m.report(0.4, "SLOW")
    assert calls[-1] == 0.4


def test_unknown_names_and_numbers_name_the_node_and_its_dtcs() -> None:
    m, _ = memory()
    with pytest.raises(KeyError, match="ECU: no DTC named 'NOPE'.*SENSOR, SLOW, LOST"):
        m.report(0.0, "NOPE")
    with pytest.raises(KeyError, match="ECU: no DTC 0x123456.*C1A01-1C SENSOR"):
        m.status(0x123456)


# -- the state machine against a model ---------------------------------------------------------------------------
@dataclass
class ModelDtc:
    """One DTC by ISO 14229-1 Annex D's words, one field per status bit."""

    confirm_ms: int
    warning: bool
    test_failed: bool = False
    failed_this_cycle: bool = False
    pending: bool = False
    confirmed: bool = False
    not_completed_since_clear: bool = True
    failed_since_clear: bool = False
    not_completed_this_cycle: bool = True
    warning_indicator: bool = False
    occurrences: int = 0
    passed_cycles: int = 0
    snapshot_ms: int | None = None
    failing_since_ms: int | None = None

    def status(self) -> int:
        bits = (self.test_failed, self.failed_this_cycle, self.pending, self.confirmed,
                self.not_completed_since_clear, self.failed_since_clear, self.not_completed_this_cycle,
                self.warning_indicator)
        return sum(1 << i for i, bit in enumerate(bits) if bit)


HEALING, AGING = 2, 3
NAMES = [name for _, name, _, _ in DTCS]
NUMBERS = [SENSOR, SLOW, LOST]


class FaultMemoryMachine(RuleBasedStateMachine):
    @initialize()
    def start(self) -> None:
        self.memory, self.clock = memory(healing=HEALING, aging=AGING)
        self.model = {name: ModelDtc(round(confirm * 1000), warning) for _, name, confirm, warning in DTCS}
        self.reported_this_cycle = False

    @rule(step_ms=st.sampled_from([0, 1, 50, 100, 150, 300]), failed=st.lists(st.sampled_from(NAMES), unique=True))
    def report(self, step_ms: int, failed: list[str]) -> None:
        self.clock.ms += step_ms
        now = self.clock.ms
        self.memory.report(now / 1000, *failed)
        for name, d in self.model.items():
            if name in failed:
                if not d.test_failed:
                    d.occurrences = min(d.occurrences + 1, 255)
                    d.snapshot_ms = now
                d.test_failed = d.failed_this_cycle = d.pending = d.failed_since_clear = True
                d.not_completed_since_clear = d.not_completed_this_cycle = False
                if d.failing_since_ms is None:
                    d.failing_since_ms = now
                if now - d.failing_since_ms >= d.confirm_ms:
                    d.confirmed = True
                    d.warning_indicator = d.warning_indicator or d.warning
            else:
                d.test_failed = d.not_completed_since_clear = d.not_completed_this_cycle = False
                d.failing_since_ms = None
        self.reported_this_cycle = True
        for number in NUMBERS:
            assert not self.memory.status(number) & 0x40, "TNCTOC after a report"

    @rule()
    def new_operation_cycle(self) -> None:
        self.memory.new_operation_cycle()
        for d in self.model.values():
            if d.failed_this_cycle:
                d.passed_cycles = 0
            elif not d.not_completed_this_cycle:
                d.pending = False
                d.passed_cycles += 1
                if d.passed_cycles >= HEALING:
                    d.warning_indicator = False
                if d.passed_cycles >= AGING:
                    d.confirmed = False
                    d.snapshot_ms = None
                    d.occurrences = 0
            d.failed_this_cycle = False
            d.not_completed_this_cycle = True
            d.failing_since_ms = None
        self.reported_this_cycle = False

    @rule(which=st.sampled_from([0xFFFFFF, *NUMBERS, 0x123456]))
    def clear(self, which: int) -> None:
        known = which == 0xFFFFFF or which in NUMBERS
        assert self.memory.clear(which) == known
        for name, number in zip(NAMES, NUMBERS):
            if which in (0xFFFFFF, number):
                d = self.model[name]
                self.model[name] = ModelDtc(d.confirm_ms, d.warning)
                assert self.memory.status(number) == 0x50

    @invariant()
    def matches_the_model(self) -> None:
        for name, number in zip(NAMES, NUMBERS):
            d = self.model[name]
            assert self.memory.status(number) == d.status(), name
            assert self.memory.occurrences(number) == d.occurrences, name
            expected = None if d.snapshot_ms is None else self.clock.capture()[:4] + d.snapshot_ms.to_bytes(4, "big")
            assert self.memory.snapshot(number) == expected, name

    @invariant()
    def annex_d_implications(self) -> None:
        for number in NUMBERS:
            s = self.memory.status(number)
            if s & 0x08:
                assert s & 0x20, "confirmed implies testFailedSinceLastClear"
            if s & 0x04:
                assert s & 0x20, "pending implies testFailedSinceLastClear"
            if s & 0x01:
                assert s & 0x04, "testFailed implies pending"
                if self.reported_this_cycle:   # testFailed carries over a cycle's end until the next report
                    assert s & 0x02, "testFailed implies testFailedThisOperationCycle"
            if s & 0x80:
                assert s & 0x08, "the warning indicator implies confirmed (healing before aging)"
            assert not (s & 0x10 and s & 0x20), "not completed and failed since the last clear"
            assert self.memory.dtcs_by_mask(s) == [] or (number, s) in self.memory.dtcs_by_mask(s)


FaultMemoryMachine.TestCase.settings = settings(max_examples=300, stateful_step_count=40, deadline=None)
TestFaultMemoryMachine = FaultMemoryMachine.TestCase
