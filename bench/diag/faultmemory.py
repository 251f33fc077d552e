"""The fault memory of one simulated node: ISO 14229-1 Annex D's DTC status byte, snapshots and counters.

The node's behaviour reports its monitors' results every step (`report`); the UDS server reads and clears the
memory (services 0x19 and 0x14) and starts a new operation cycle on an ECUReset. The rules are ISO's, with the
project's two numbers from the declaration: healing (`protocol.healing_cycles`) and aging
(`protocol.aging_cycles`) in operation cycles without failure, and each DTC's confirmation time (`dtc.confirm`).
"""

from __future__ import annotations

from collections.abc import Callable

from bench.diag.declaration import NodeDiagnostics, Protocol

# The status bits (ISO 14229-1 Annex D.2)
TEST_FAILED = 0x01
TEST_FAILED_THIS_CYCLE = 0x02
PENDING = 0x04
CONFIRMED = 0x08
NOT_COMPLETED_SINCE_CLEAR = 0x10
FAILED_SINCE_CLEAR = 0x20
NOT_COMPLETED_THIS_CYCLE = 0x40
WARNING_INDICATOR = 0x80

#: every bit is supported (DTCStatusAvailabilityMask)
AVAILABILITY = 0xFF
#: a DTC never tested since power-up or a clear: testNotCompletedSinceLastClear and ...ThisOperationCycle
INITIAL_STATUS = NOT_COMPLETED_SINCE_CLEAR | NOT_COMPLETED_THIS_CYCLE
#: snapshot record number of the one record kept per DTC (its most recent occurrence)
SNAPSHOT_RECORD = 0x01
#: group of all DTCs (ClearDiagnosticInformation)
ALL_DTCS = 0xFFFFFF

_FAIL_SET = TEST_FAILED | TEST_FAILED_THIS_CYCLE | PENDING | FAILED_SINCE_CLEAR
_NOT_COMPLETED = NOT_COMPLETED_SINCE_CLEAR | NOT_COMPLETED_THIS_CYCLE
_EPS = 1e-9     # float noise in t: a confirmation due "now" happens now


class _Entry:
    """One DTC's memory."""

    __slots__ = ("number", "confirm", "warning", "status", "occurrences", "passed_cycles", "snapshot",
                 "failing_since", "qualified")

    def __init__(self, number: int, confirm: float, warning: bool) -> None:
        self.number, self.confirm, self.warning = number, confirm, warning
        self.status = INITIAL_STATUS
        self.occurrences = 0
        self.passed_cycles = 0        # operation cycles completed without failure since the last failing one
        self.snapshot: bytes | None = None
        self.failing_since: float | None = None   # start of the continuous failure in this operation cycle
        self.qualified = False        # the failure met its confirmation time in this operation cycle

    def erase(self) -> None:
        self.status = INITIAL_STATUS
        self.occurrences = self.passed_cycles = 0
        self.snapshot = self.failing_since = None
        self.qualified = False


class FaultMemory:
    """The status byte, snapshot record 0x01 and occurrence counter of each DTC of one node.

    `capture` returns snapshot record 0x01 as it is sent (record number, number of identifiers, then DID and data
    of each), taken at each occurrence; None (or a node without snapshot DIDs) keeps no snapshot.
    """

    def __init__(self, node: NodeDiagnostics, protocol: Protocol, capture: Callable[[], bytes] | None = None) -> None:
        self.node = node
        self.healing_cycles = protocol.healing_cycles
        self.aging_cycles = protocol.aging_cycles
        self._capture = capture if node.snapshot else None
        self._entries = [_Entry(d.number, d.confirm, d.warning_indicator) for d in node.dtcs]
        self._by_number = {e.number: e for e in self._entries}
        self._by_name = {d.name: i for i, d in enumerate(node.dtcs)}
        # report's shortcut: the failed names of the last report, and whether a report with the same names would
        # change nothing (no DTC debouncing toward confirmation, bits 4 and 6 clear everywhere)
        self._last: tuple[str, ...] | None = None
        self._quiet = False

    # -- the behaviour's side ----------------------------------------------------------------------------------
    def report(self, t: float, *failed: str) -> None:
        """The node's monitors ran at t: the DTCs named (by name) failed, every other one passed."""
        if self._quiet and failed == self._last:
            return
        self._update(t, failed)

    def _update(self, t: float, failed: tuple[str, ...]) -> None:
        try:
            failing = {self._by_name[name] for name in failed}
        except KeyError as exc:
            raise KeyError(f"{self.node.node}: no DTC named {exc.args[0]!r} (DTCs: "
                           f"{', '.join(d.name for d in self.node.dtcs) or 'none'})") from None
        debouncing = False
        for index, entry in enumerate(self._entries):
            status = entry.status
            if index in failing:
                if not status & TEST_FAILED:
                    entry.occurrences = min(entry.occurrences + 1, 255)
                    if self._capture is not None:
                        entry.snapshot = self._capture()
                status = (status | _FAIL_SET) & ~_NOT_COMPLETED
                if entry.failing_since is None:
                    entry.failing_since = t
                if not entry.qualified:
                    if t + _EPS >= entry.failing_since + entry.confirm:
                        entry.qualified = True
                        status |= CONFIRMED | (WARNING_INDICATOR if entry.warning else 0)
                    else:
                        debouncing = True
            else:
                status &= ~(TEST_FAILED | _NOT_COMPLETED)
                entry.failing_since = None
                entry.qualified = False
            entry.status = status
        self._last = failed
        self._quiet = not debouncing    # every DTC was tested: bits 4 and 6 are clear

    def new_operation_cycle(self) -> None:
        """End the current operation cycle and start the next (power-up, ECUReset): pending, healing and aging."""
        for entry in self._entries:
            status = entry.status
            if status & TEST_FAILED_THIS_CYCLE:
                entry.passed_cycles = 0
            elif not status & NOT_COMPLETED_THIS_CYCLE:
                status &= ~PENDING
                entry.passed_cycles = min(entry.passed_cycles + 1, 255)
                if entry.passed_cycles >= self.healing_cycles:
                    status &= ~WARNING_INDICATOR
                if entry.passed_cycles >= self.aging_cycles:    # aged
                    status &= ~CONFIRMED
                    entry.snapshot = None
                    entry.occurrences = 0
            entry.status = (status & ~TEST_FAILED_THIS_CYCLE) | NOT_COMPLETED_THIS_CYCLE
            entry.failing_since = None
            entry.qualified = False
        self._quiet = False

    # -- the tester's side -------------------------------------------------------------------------------------
    def clear(self, group: int) -> bool:
        """ClearDiagnosticInformation: all DTCs (0xFFFFFF) or one by its number; False for an unknown group."""
        if group == ALL_DTCS:
            entries = self._entries
        elif group in self._by_number:
            entries = [self._by_number[group]]
        else:
            return False
        for entry in entries:
            entry.erase()
        self._quiet = False
        return True

    def known(self, number: int) -> bool:
        return number in self._by_number

    def status(self, number: int) -> int:
        return self._entry(number).status

    def dtcs_by_mask(self, mask: int) -> list[tuple[int, int]]:
        """(number, status) of every DTC whose status has a bit of the mask (ISO: masked by the availability)."""
        mask &= AVAILABILITY
        return [(e.number, e.status) for e in self._entries if e.status & mask]

    def snapshot(self, number: int) -> bytes | None:
        """Snapshot record 0x01 of the most recent occurrence, as 0x19 0x04 sends it after the DTC and its status:
        record number, number of identifiers, then each DID (2 bytes) and its data; None when none is stored."""
        return self._entry(number).snapshot

    def occurrences(self, number: int) -> int:
        """How often testFailed went from 0 to 1 since the last clear or aging (saturating at 255)."""
        return self._entry(number).occurrences

    def _entry(self, number: int) -> _Entry:
        entry = self._by_number.get(number)
        if entry is None:
            raise KeyError(f"{self.node.node}: no DTC 0x{number:06X} (DTCs: "
                           f"{', '.join(f'{d.code} {d.name}' for d in self.node.dtcs) or 'none'})")
        return entry
