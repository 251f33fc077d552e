"""The AUTOSAR E2E receiver of one message: the profile's check, the E2E state machine, the consumer's rule.

Written from the AUTOSAR E2E specification (the check of Profiles 4 to 11 and E2E_SM with one window size);
the transition table is docs/spec/e2e.md "State machine", which tests/bench/e2e/test_e2e_receiver.py checks row by
row against a model of its own. The receiver runs once per received frame (NewDataAvailable is always true);
that a message stopped arriving is the consumer's deadline monitoring (the timeout), not the receiver's.
"""

from __future__ import annotations

from enum import StrEnum

from bench.e2e.profiles import SMConfig


class Status(StrEnum):
    """The profile check's status of one frame (E2E_PXXCheckStatusType); equal to its name as a string."""

    OK = "OK"                        # CRC right, counter = previous + 1
    OKSOMELOST = "OKSOMELOST"        # CRC right, counter = previous + 2 ... previous + MaxDeltaCounter
    REPEATED = "REPEATED"            # CRC right, counter = previous
    WRONGSEQUENCE = "WRONGSEQUENCE"  # CRC right, any other counter (skipped too far, back, a second sender)
    ERROR = "ERROR"                  # CRC wrong (or wrong length): the counter is not read


class SMState(StrEnum):
    """E2E_SMStateType; equal to its name as a string."""

    NODATA = "NODATA"
    INIT = "INIT"
    VALID = "VALID"
    INVALID = "INVALID"


#: Statuses the state machine's window counts as OK (E2E_P_OK) and as ERROR (E2E_P_ERROR); REPEATED and
#: WRONGSEQUENCE take a place in the window and count as neither.
_COUNTS_OK = (Status.OK, Status.OKSOMELOST)
_OK = Status.OK


class StateMachine:
    """E2E_SM of one message: the last `window_size` statuses decide the state (docs/spec/e2e.md)."""

    __slots__ = ("config", "state", "window", "size", "top", "ok_run", "steady")

    def __init__(self, config: SMConfig) -> None:
        self.config = config
        self.state = SMState.NODATA
        self.size = config.window_size
        self.window: list[Status | None] = [None] * self.size
        self.top = 0
        self.ok_run = 0       # statuses counted as OK added last in a row (up to the window's size)
        self.steady = False   # VALID with a window of OK statuses only: an OK status keeps everything as it is

    def _clear(self) -> None:
        self.window = [None] * self.size
        self.top = 0
        self.ok_run = 0

    def _add(self, status: Status) -> tuple[int, int]:
        window = self.window
        window[self.top] = status
        self.top = (self.top + 1) % self.size
        self.ok_run = min(self.ok_run + 1, self.size) if status in _COUNTS_OK else 0
        ok = sum(1 for s in window if s in _COUNTS_OK)
        return ok, window.count(Status.ERROR)

    def step(self, status: Status) -> SMState:
        """E2E_SMCheck: one status in, the new state out."""
        config = self.config
        state = self.state
        if state is SMState.NODATA:
            if status is not Status.ERROR:
                self._clear()
                self.state = SMState.INIT
            return self.state
        ok, errors = self._add(status)
        if state is SMState.INIT:
            if errors <= config.max_error_init and ok >= config.min_ok_init:
                self.state = SMState.VALID
            elif errors > config.max_error_init:
                self.state = SMState.INVALID
        elif state is SMState.VALID:
            if not (errors <= config.max_error_valid and ok >= config.min_ok_valid):
                self.state = SMState.INVALID
        elif errors <= config.max_error_invalid and ok >= config.min_ok_invalid:   # INVALID
            self.state = SMState.VALID
        self.steady = self.state is SMState.VALID and self.ok_run >= self.size
        return self.state


_VALID = SMState.VALID
_OK_APPLIED = (_OK, True)


class Receiver:
    """The check and the state machine of one message, and the consumer's rule: a frame is applied when its
    status is OK or OKSOMELOST and the state machine is VALID after it."""

    __slots__ = ("modulo", "max_delta", "next", "sm", "counts", "steady_ok", "held_back", "joins")

    def __init__(self, counter_modulo: int, max_delta_counter: int, sm: SMConfig) -> None:
        self.modulo = counter_modulo
        self.max_delta = max_delta_counter
        self.next = 0   # the counter an in-sequence frame carries next (E2E_PXXCheckInit: a first 0 is in sequence)
        self.sm = StateMachine(sm)
        #: After a frame that was not applied: whether it says nothing against its sender (intact, and the first
        #: frame this receiver judges, or in sequence while the state machine is INIT) rather than failing.
        self.held_back = False
        self.counts: dict[Status, int] = {}   # frames per status, but for ...
        self.steady_ok = 0                    # ... the OK frames of the steady path, counted here
        #: A receiver that joins a running stream (`bench monitor`): the first intact frame's counter is taken as
        #: the one due, where E2E_PXXCheckInit's 0 would make it REPEATED or WRONGSEQUENCE, a fault no sender made.
        self.joins = False

    @property
    def state(self) -> SMState:
        return self.sm.state

    def check(self, counter: int | None) -> Status:
        """The profile's check of one frame: `counter` is its counter when the CRC is right, None when not."""
        if counter is None or counter >= self.modulo:
            return Status.ERROR
        delta = (counter - self.next + 1) % self.modulo
        self.next = (counter + 1) % self.modulo
        if delta == 1:
            return Status.OK
        if delta == 0:
            return Status.REPEATED
        return Status.OKSOMELOST if delta <= self.max_delta else Status.WRONGSEQUENCE

    def receive(self, counter: int | None) -> tuple[Status, bool]:
        """One frame: its status and whether the consumer may apply it (the signal checks still follow)."""
        if counter == self.next and self.sm.steady:
            # VALID with a window of OK statuses only: one more OK changes neither the counts nor the state (the
            # window stays all OK, so which of its places the status takes does not matter)
            self.next = counter + 1 if counter + 1 < self.modulo else 0
            self.steady_ok += 1
            return _OK_APPLIED
        first = self.sm.state is SMState.NODATA
        if first and self.joins and counter is not None and counter < self.modulo:
            self.next = counter
        status = self.check(counter)
        counts = self.counts
        counts[status] = counts.get(status, 0) + 1
        state = self.sm.step(status)
        ok = status in _COUNTS_OK
        applied = state is _VALID and ok
        self.held_back = not applied and status is not Status.ERROR and (first or (state is SMState.INIT and ok))
        return status, applied

    def status_counts(self) -> dict[Status, int]:
        """Frames received per check status (a Status equals its name as a str)."""
        counts = dict(self.counts)
        if self.steady_ok:
            counts[_OK] = counts.get(_OK, 0) + self.steady_ok
        return counts
