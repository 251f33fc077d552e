"""The test-case API (`bench` fixture): drive the bus, wait, observe and check.

Everything a case checks becomes a Step (name, measured, expected, tolerance, verdict), so the
report shows what was measured, not only that something failed. Checks do not raise: a case runs
to its end and fails if any step failed (the pytest plugin does that).
"""

from __future__ import annotations

import math
import re
from bisect import bisect_left
from collections import Counter
from collections.abc import Callable, Iterable, Sequence
from typing import TYPE_CHECKING, Literal

import numpy as np
from pytest import fail

from bench.checks.monitor import InvalidFrame
from bench.checks.steps import StepLog, percentile, tolerance_text, within
from bench.checks.timing import LATE_FLOOR, Late, SelfTiming
from bench.database.codec import SignalCodec
from bench.diag.declaration import NodeDiagnostics, Protocol
from bench.errors import BenchError, Inconclusive, did_you_mean
from bench.faults.plan import KINDS, Fault
from bench.results.model import CaseResult, FaultRecord, Plot, Series, Table
from bench.session import BenchSession
from bench.sim.station import LATE_CYCLES

if TYPE_CHECKING:   # (udsoncan costs 0.3 s of import: in virtual time loaded when a case first asks for a tester)
    from udsoncan.client import Client

    from bench.diag.tester import TesterPort

MAX_INPUT_GAPS = 500         # gaps past their bound looked at per message and case (they are compared pairwise)
BENCH_FIGURES = 8            # figures of the bench's own timing on a case's record at most (the worst)
GAP_CYCLES = 2.5             # a plotted signal's line breaks where frames are this many cycles apart
_NUMBER = re.compile(r"(?<![A-Za-z0-9])\d+(?:\.\d+)?(?![A-Za-z])")   # 7, 0.5; not the 2 of "E2E"


class NoFrames(float):
    """What value() returns for a message with no valid frame now: NaN that knows why, so that a
    check records "no frames of MSG" (or "MSG timed out") rather than "nan"."""

    why: str

    def __new__(cls, why: str) -> NoFrames:
        value = super().__new__(cls, math.nan)
        value.why = why
        return value

    def __repr__(self) -> str:
        return self.why

    __str__ = __repr__


def _shown(value: float) -> float | str:
    """A measured or expected value as a step records it: NoFrames as its reason."""
    return value.why if isinstance(value, NoFrames) else float(value)


class Case:
    """The `bench` fixture: one test case on a bench session.

    A case drives the stimulus messages (`set`, `start_scenario`), lets bench time pass (`run`,
    `wait_until`), reads what the monitor accepted (`value`, `history`, `received`, `detections`) and checks
    it (`expect`, `expect_between`, `eventually`, `always`, `check_cycle_times`). Every check records one
    *step* in the report: name, measured, expected, tolerance, verdict and the bench time of the check.
    Checks never raise: the case runs to its end and fails when any step of its DUT failed; only `received` ends
    a case, in one line, when a message it cannot be judged without never came. A check that judges another node
    than the case's DUT (the plant, a simulated sensor) names it (`node="PLANT"`): its step is that node's, shown
    under it in the report's conformance section, and never fails the case. Times are bench time in
    seconds (virtual on the embedded default, wall-clock on a real bus); signal values are physical values
    in the DBC's units. Every time limit ("for how long") is the argument `seconds`: `run(seconds)`,
    `wait_until(predicate, seconds)`, `eventually(name, predicate, seconds)`, `always(name, predicate,
    seconds)` (before: `timeout`, `within_s` and `during`).
    """

    def __init__(self, session: BenchSession, result: CaseResult, steps: StepLog) -> None:
        self.session = session
        self.result = result
        self._steps = steps
        self.start = session.now()
        runner = session.runner
        if runner is None:
            raise BenchError("a test case needs the runner station")
        self._runner = runner
        self._monitor = runner.monitor
        self._monitor.history_from = self.start   # the case's whole history is kept (bench.checks.monitor)
        if session.self_timing is not None:       # the bench's own timing counts from here (not the pause before)
            session.self_timing.resume(self.start)
        session.scheduler.begin_case()            # and so does the watchdog's lag
        self._timers: list[_Timer] = []
        # bench time of the plant's acknowledgement of the latest scenario: what came before is the last one's
        self._acknowledged_at = -math.inf
        self._mark_counts()
        self._case_invalid_mark = self._invalid_mark     # start_scenario moves _invalid_mark, not this
        self._closed = False
        self._testers: dict[tuple[str, bool], Client] = {}   # bench.diag's clients: (node, functional)
        self._ports: dict[str, TesterPort] = {}
        self._resets: list[tuple[float, str]] = []   # (bench time of the positive response, node) of its ECUResets
        plan = session.faults
        self._fault_frames0 = {id(f): f.frames for f in plan.faults}   # run faults: their frames before the case
        plan.begin_case(self.start)

    def _mark_counts(self) -> None:
        # absolute counts (kept + dropped), so that trimming the monitor's lists never shifts a mark
        self._interval_marks = {name: s.intervals_dropped + len(s.intervals)
                                for name, s in self._monitor.by_name.items()}
        self._invalid_mark = self._monitor.invalid_dropped + len(self._monitor.invalid_log)
        self._e2e_marks = {name: s.e2e_status for name, s in self._monitor.by_name.items() if s.rx is not None}

    # -- the run ------------------------------------------------------------------------------------
    @property
    def external(self) -> frozenset[str]:
        """The nodes declared external in this run (`--external`): real ECUs on the bus, which the bench does
        not simulate. Records no step."""
        return frozenset(self.session.external)

    def calibration(self, node: str, name: str, unit: str) -> float:
        """A value of bench.toml's `[calibration.NODE]` table (the calibration of a real ECU that a case needs to
        judge it), checked to be in `unit`. A missing table or name, or another unit, ends the case as
        inconclusive in one line naming bench.toml and the key (the ECU is not at fault). Records no step."""
        project = self.session.project
        table = project.calibration.get(node)
        where = f"{project.path}: [calibration.{node}]"
        if table is None or name not in table:
            raise Inconclusive(f"{where} {name}: missing; the case needs the external {node}'s value "
                               f"({name} = {{ value = <number>, unit = \"{unit}\" }})")
        value, given = table[name]
        if given != unit:
            raise Inconclusive(f"{where} {name}: unit {given!r}, the case needs {unit!r}")
        return value

    # -- time --------------------------------------------------------------------------------------
    @property
    def now(self) -> float:
        """Bench time now, s (0 at the start of the run). Records no step."""
        return self.session.now()

    @property
    def elapsed(self) -> float:
        """Bench time since the case (or its latest `start_scenario`) started, s. Records no step."""
        return self.now - self.start

    def run(self, seconds: float) -> None:
        """Let the bus, the plant and the simulated ECUs run for `seconds` s of bench time (every frame is
        sent, received and checked meanwhile). Records no step."""
        self.session.run_until(self.now + seconds)

    def wait_until(self, predicate: Callable[[], bool], seconds: float) -> bool:
        """Run until `predicate()` is true (checked every 1 ms tick), at most `seconds` s of bench time.
        Returns True when it held within `seconds` s, as `eventually` judges (in real time, a bench that ran late
        stops at the clock's limit, not after `seconds` s worth of its ticks). Records no step (`eventually` is
        the check that does)."""
        took = self._watch(predicate, seconds, until=True, check_first=True)
        return took is not None and took <= seconds

    def _watch(self, predicate: Callable[[], bool], seconds: float, *, until: bool,
               check_first: bool) -> float | None:
        """Run until `bool(predicate()) is until` or `seconds` s of bench time have passed since now. Returns
        the bench time from now to the check that found it so (s, to the µs), or None when none did.

        The one measure of `wait_until`, `eventually` and `always`: their verdict and their figure are this
        number. In real time it is the clock's, read when the check found it, and the run also stops when the
        clock passes the limit: a bench whose tick loop runs late (a busy host, a blocking call in a timer)
        would otherwise let `seconds` s worth of late ticks pass, many more seconds of bench time, and pass
        a check whose own figure exceeds its limit (issue 25: "measured 17.7287 s, expected ≤ 0.2"). A check
        may then find it so a little after the limit (the loop looks at the clock between ticks, and looks once
        more at what the run's end read from the sockets): the figure says so and the verdict follows it. With
        the virtual clock the ticks are the clock: the run is the same as `run_until` alone."""
        session = self.session
        t0 = self.now
        if check_first and bool(predicate()) is until:
            return 0.0
        deadline = t0 + seconds
        seen: list[float] = []
        now, recent = session.now, session.recent

        def found() -> bool:
            if bool(predicate()) is until:
                seen.append(now())   # a new read, once: the time of this check, not of the tick's start
                return True
            return False

        if session.clock.realtime:
            session.run_until(deadline, lambda: found() or recent() >= deadline)
            if not seen:
                found()   # once more on what the end of the run read from the sockets: a figure past the limit
        else:
            session.run_until(deadline, found)
        return round(seen[0] - t0, 6) if seen else None

    def every(self, period: float, callback: Callable[[float], None]) -> Callable[[], None]:
        """Call `callback(now)` every `period` s of bench time while the bench runs (a test node's timer,
        e.g. a closed-loop driver model that sets the stimulus from what it reads); `now` is bench time, s.
        Returns a cancel function; every timer ends with its scenario (`start_scenario`) or with the case.
        Records no step."""
        if not period > 0:
            raise BenchError(f"timer period must be > 0 s, not {period!r}")
        timer = _Timer(self.now + period, period, callback)
        self._runner.behaviours.append(timer)
        self._timers.append(timer)

        def cancel() -> None:
            if timer in self._runner.behaviours:
                self._runner.behaviours.remove(timer)

        return cancel

    # -- diagnostics ---------------------------------------------------------------------------------
    def diag(self, node: str, *, functional: bool = False) -> Client:
        """A udsoncan client to `node`'s diagnostics (UDS on ISO-TP, docs/contract/diagnostics.md), opened: e.g.
        `bench.diag(NODE).get_dtc_by_status_mask(0xFF)`. Its waits run the bench in bench time (P2/P2* of the
        declaration); its DIDs decode to physical values; `functional` sends on the functional address (single
        frames) and reads `node`'s answer. The same client for the same arguments within a case (one ISO-TP
        endpoint per node: two would both answer a response with a flow control). A negative response raises
        udsoncan's NegativeResponseException (its `.response.code` is the NRC), no response its TimeoutException,
        each naming the node and the request. The exchange goes on the case's record in the report, decoded.
        Records no step."""
        from bench.diag.tester import open_client, tester_port

        declaration = self.session.declaration
        if declaration is None:
            raise BenchError(f"bench.diag({node!r}): {self.session.project.path} has no [diagnostics] file")
        client = self._testers.get((node, functional))
        if client is not None:
            return client
        port = self._ports.get(node)
        if port is None:
            port = self._ports[node] = tester_port(self._runner, declaration, node)
        response = self.session.codebook.by_id.get(declaration.node(node).response)
        client = open_client(self.session, port, declaration, node, functional=functional,
                             security=self.session.project.security, external=node in self.session.external,
                             response_name=response.name if response is not None else "")
        self._testers[(node, functional)] = client
        return client

    def value_table(self, message: str, signal: str) -> dict[str, int]:
        """The signal's value table (name -> raw number) from the databases; empty when it has none.
        Records no step."""
        codec = self._monitor.codebook[message]
        if signal not in codec.by_name:
            raise BenchError(f"{message} has no signal {signal!r}{did_you_mean(signal, codec.by_name)}")
        return dict(codec.by_name[signal].choices)

    def diagnostics(self, node: str) -> NodeDiagnostics:
        """What the project's diagnostic declaration (bench.toml [diagnostics] file) says of `node`: its DTCs
        (code, name, confirmation time), DIDs and routines, the expected values of its diagnostic cases.
        Records no step."""
        declaration = self.session.declaration
        if declaration is None:
            raise BenchError(f"bench.diagnostics({node!r}): {self.session.project.path} has no [diagnostics] file")
        try:
            return declaration.node(node)
        except KeyError as exc:
            raise BenchError(str(exc.args[0])) from None

    @property
    def diagnostic_protocol(self) -> Protocol:
        """The diagnostic timing and fault-memory rules every node shares (P2, S3, aging, security attempts).
        Records no step."""
        declaration = self.session.declaration
        if declaration is None:
            raise BenchError(f"{self.session.project.path} has no [diagnostics] file")
        return declaration.protocol

    def _close_testers(self) -> None:
        if not self._testers:
            return
        from bench.diag.describe import describe
        from bench.diag.tester import BenchConnection

        rows: list[list[object]] = []
        declaration = self.session.declaration
        for (node, _), client in self._testers.items():
            connection = client.conn
            assert isinstance(connection, BenchConnection)
            self._resets += [(t, node) for t, direction, payload in connection.exchanges
                             if direction == "response" and payload[:1] == b"\x51"]
            named = declaration.node(node) if declaration is not None else None   # DTCs by name, as the log has them
            rows += [[f"{t - self.start:.3f}", node, direction, describe(payload, named)]
                     for t, direction, payload in connection.exchanges]
            client.close()
        ports = list(self._ports.values())
        self._testers, self._ports = {}, {}
        if rows:
            rows.sort(key=lambda row: float(str(row[0])))
            kernel = sorted({port.channel for port in ports if port.channel is not None})
            how = f" (the tester on the kernel's ISO-TP of {', '.join(kernel)})" if kernel else ""
            self.table(f"Diagnostic exchange{how}", ["t (s)", "node", "", "message"], rows)

    def close(self) -> None:
        """End of the case (the pytest plugin calls it; a case need not): its timers stop, its case+ fault
        windows close, and the faults that were active and the invalid frames seen during it go on its
        record in the report. Records no step."""
        self._stop_timers()
        if self._closed:
            return
        self._close_testers()
        self._monitor.check_timeouts(self.now)   # an ISO-TP N_Bs / N_Cr that ran out in this case is this case's
        self._closed = True
        self._monitor.history_from = math.inf   # between cases only the last HISTORY_CAP frames are kept
        now = self.now
        plan = self.session.faults
        plan.end_case(now)
        t0 = self.result.sim_start
        records: list[FaultRecord] = []
        for fault in plan.history + _instances(plan):
            if fault.relative != "run" or not (fault.start < now and fault.end > t0):
                continue
            record = fault.record()
            record.frames = fault.frames - self._fault_frames0.get(id(fault), 0)
            records.append(record)
        # an ECUReset the case made is a disturbance of the bus like an injected fault: the node may restart its
        # AliveCounters and go silent for a while (docs/contract/diagnostics.md DIAG-RST-02)
        records += [FaultRecord(f"ecu_reset:{node}@{t:.3f}", self.result.nodeid, "ecu_reset", node, t, None)
                    for t, node in sorted(self._resets)]
        self.result.faults = records
        monitor = self._monitor
        self.result.invalid_frames = monitor.invalid_frames - self._case_invalid_mark
        seen = monitor.invalid_log[max(0, self._case_invalid_mark - monitor.invalid_dropped):]
        counts = Counter((f.message, _NUMBER.sub("N", f.reason)) for f in seen)
        self.result.invalid = [[m, r, str(n)] for (m, r), n in sorted(counts.items(), key=lambda x: -x[1])]
        self.bench_verdict()
        if self.session.self_timing is not None:   # what the bench does between cases is no case's timing
            self.session.self_timing.pause()

    def bench_verdict(self) -> str:
        """Real time: the bench's own timing (bench.checks.timing.SelfTiming) and the gaps of the DUT's inputs from
        other processes (`_input_gaps`) since the case's latest scenario started (or the case, without one: before it
        the bench was setting the case up, and an in-process plant replaying the pause between cases) onto its record
        (`bench_timing`, worst first), and the line that makes it inconclusive ("" when every figure is within its
        bound; always "" in virtual time, where the bench is never late). Records no step."""
        timing = self.session.self_timing
        if timing is None:
            return ""
        figures = timing.since(self.start) + self._input_gaps()
        figures.sort(key=lambda e: (-(e.late / e.bound if e.bound else 0.0), -e.late))
        self.result.bench_timing = [f.text() for f in figures[:BENCH_FIGURES]]
        return SelfTiming.verdict(figures)

    def _input_gaps(self) -> list[Late]:
        """Gaps since the scenario started in the periodic messages from nodes that are neither a DUT of the case
        nor simulated in this process (`bench plant` in another process, another ECU), on the receive stamps of
        their valid frames (the runner's history): a frame later than its cycle by more than LATE_CYCLES cycles
        leaves its receivers (the DUT among them) a timeout that the DUT did not cause. Such a gap counts against
        its bound only when another message gapped at the same time, of any node, past its own bound or late by at
        least half as much (a stalled process: `bench plant` plays many nodes, and a stall gaps every message it
        sends: its 5 ms bench I/O passes its bound while its 10 ms messages, as late, stay within theirs); one
        message silent alone is taken as meant (a fault the case asked the plant for) and shown as a figure only.
        The worst per message."""
        duts = set(self.result.duts)
        if not duts:
            return []
        session = self.session
        own = set(session.codebook.nodes) - session.external   # simulated here: timed as they are sent
        worst: dict[str, Late] = {}
        over: list[tuple[float, float, str, Late]] = []   # gaps past their bound: (from, to, message, figure)
        arrivals: dict[str, tuple[np.ndarray, np.ndarray]] = {}   # per message: its frames' times, each gap's lateness
        for name, state in self._monitor.by_name.items():
            cycle, senders = state.codec.cycle_time, frozenset(state.codec.senders)
            if not cycle or not senders or senders & duts or senders & own:
                continue
            ts = state.history_t
            times = np.asarray(ts[bisect_left(ts, self.start):], dtype=float)
            if times.size < 2:
                continue
            lates = np.diff(times) - cycle
            what, bound = f"input {name} from {'/'.join(sorted(senders))}", LATE_CYCLES * cycle
            i = int(np.argmax(lates))
            if lates[i] > LATE_FLOOR:
                worst[name] = Late(what, float(lates[i]), float(times[i]) + cycle, math.inf)   # a figure, first
            for j in np.nonzero(lates > bound)[0][:MAX_INPUT_GAPS]:
                over.append((float(times[j]), float(times[j + 1]), name,
                             Late(what, float(lates[j]), float(times[j]) + cycle, bound)))
            arrivals[name] = (times, lates)
        for t0, t1, name, late in over:
            # a stall: another message past its bound at the same time, or late then by at least half as much (a
            # stalled process lags all it sends; the plant's 5 ms I/O passes its bound while its 10 ms messages,
            # as late, are still within theirs)
            if any(u0 < t1 and t0 < u1 and other != name for u0, u1, other, _ in over) or any(
                    bool(np.any((times[:-1] < t1) & (times[1:] > t0) & (lates >= late.late / 2)))
                    for other, (times, lates) in arrivals.items() if other != name):
                current = worst[name]
                if math.isinf(current.bound) or late.late > current.late:
                    worst[name] = late
        return list(worst.values())

    def _stop_timers(self) -> None:
        for timer in self._timers:
            if timer in self._runner.behaviours:
                self._runner.behaviours.remove(timer)
        self._timers.clear()

    # -- stimulus ----------------------------------------------------------------------------------
    def set(self, message: str, **signals: float | int | str) -> None:
        """Set signals of a stimulus message (physical values in the DBC's units, or a value table's
        name such as `Mode="SPORT"`); the message carries them from its next cycle on. Raises on an
        unknown message or signal or a value outside the DBC's range. Records no step."""
        self._runner.restbus.set(message, **signals)

    def stop_sending(self, message: str) -> None:
        """Stop sending a stimulus message until `resume_sending` (its receivers time it out after
        3 × its cycle time); its E2E counter carries on where it stopped. Records no step."""
        self._runner.restbus.stop_sending(message)

    def resume_sending(self, message: str) -> None:
        """Send a stimulus message again after `stop_sending`, from its next cycle on. Records no step."""
        self._runner.restbus.resume_sending(message)

    def start_scenario(self, *, stimulus: Iterable[str] | None = None, **control: float | int | str) -> None:
        """Reset the plant to a fresh scenario: a new scenario id in bench.toml's `[scenario] command` signal,
        with `control` (other signals of that message, e.g. the vehicle) beside it; reset every stimulus message
        to its start values, end the timers of the last scenario, and wait (up to `[scenario] timeout`, default
        2 s of bench time) for the plant to echo the id in `[scenario] ack`; `elapsed`, `history` and
        `invalid_log` count from then on, and `value` reads only frames that came with or after the
        acknowledgement (a plant frame sent before the reset, or read late on a busy host, is the last
        scenario's). `stimulus`: the stimulus messages this scenario sends (besides the
        scenario message itself); the others stay off the bus until the next scenario (a vehicle whose network
        reads none of them need not carry them). Default: every stimulus message. Raises Inconclusive (a
        BenchError: the case's outcome is "inconclusive", never the DUT's failure) when the plant does not
        acknowledge, BenchError when the project has no [scenario]. Records no step."""
        protocol = self.session.project.scenario
        if protocol is None:
            raise BenchError(f"start_scenario: {self.session.project.path} has no [scenario] table "
                             f"(command = \"Message.Signal\", ack = \"Message.Signal\")")
        (command, id_signal), (ack, ack_signal) = protocol.command, protocol.ack
        self._stop_timers()           # timers belong to a scenario: a driver of the last one must not steer this one
        restbus = self._runner.restbus
        restbus.reset_all()
        wanted = None if stimulus is None else {command, *stimulus}
        unknown = set() if wanted is None else wanted - set(restbus.slots)
        if unknown:
            raise BenchError(f"start_scenario(stimulus=...): {', '.join(sorted(unknown))} is no periodic stimulus "
                             f"message (stimulus: {', '.join(sorted(restbus.slots))})")
        for name in restbus.slots:
            if wanted is None or name in wanted:
                restbus.resume_sending(name)
            else:
                restbus.stop_sending(name)
        state = self._monitor.state(ack)
        previous = int(state.latest[ack_signal]) if state.latest else 0
        scenario = previous % _largest_id(self.session.codebook[command].by_name[id_signal]) + 1   # 0 = none yet
        restbus.set(command, **{id_signal: scenario}, **control)

        def acknowledged() -> bool:
            latest = self._monitor.latest(ack, self.now)
            return latest is not None and int(latest[ack_signal]) == scenario

        # a setup wait, not a verdict: by the tick loop's time, as before wait_until looked at the clock (a late
        # bench reads the acknowledgement late, and the case has not started yet)
        if not (acknowledged() or self.session.run_until(self.now + protocol.timeout, acknowledged)):
            # the bench's own plant could not set the case up (starved, or not running): no verdict on the DUT
            raise Inconclusive(f"the plant did not acknowledge scenario {scenario} within "
                               f"{protocol.timeout:g} s ({ack}.{ack_signal}): the case could not start")
        self.start = self.now
        acked_at = self._monitor.state(ack).last_valid
        self._acknowledged_at = self.start if acked_at is None else acked_at
        self._mark_counts()

    def inject(self, kind: str, target: str, *, after: float = 0.0, duration: float = math.inf,
               param: float = 0.0) -> Fault:
        """Inject a fault of `kind` (the registry bench.faults.kinds.KINDS; its table is in docs/reliability.md)
        on `target` (a message, a node or an identifier such as "0x000", as the kind says), starting `after`
        s from now and lasting `duration` s (default: to the end of the run). `param`: the kind's PARAM
        (e.g. the delay in s, a bit index). Returns the Fault; its window is in bench time. Records no step;
        the fault goes on the case's record in the report."""
        start = self.now + after
        fault = Fault(kind, target, start, start + duration, param, source=self.result.nodeid)
        if kind not in KINDS:
            raise BenchError(f"unknown fault kind {kind!r} (kinds: {', '.join(KINDS)})")
        return self.session.faults.add(fault)

    def detections(self, message: str, since: float | None = None) -> list[tuple[float, str]]:
        """When the bench's monitor flagged a message since `since` (bench time, s; default: case start):
        a list of (bench time s, reason) for every invalid frame (e.g. "E2E REPEATED: counter 3 again, state INVALID")
        and every timeout ("timeout"), in time order. `message` may also be "error frame" or an unknown
        identifier as "0x7FF". Records no step."""
        since = self.start if since is None else since
        self._monitor.check_timeouts(self.now)
        found = [(f.t, f.reason) for f in self._monitor.invalid_log if f.message == message and f.t >= since]
        state = self._monitor.by_name.get(message)   # None for "error frame" and unknown identifiers
        if state is not None:
            found += [(t, "timeout") for t in state.timeouts if t >= since]
        return sorted(found)

    def e2e_statuses(self, message: str) -> dict[str, int]:
        """Frames of an E2E-protected message per AUTOSAR check status (OK, OKSOMELOST, REPEATED, WRONGSEQUENCE,
        ERROR, ...) since the case (or its latest scenario) started, as the bench's monitor found them: a receiver
        with the message's own parameters (docs/spec/e2e.md), i.e. what every consumer on the bus was given. Only the
        statuses that occurred; empty for an unprotected message. Records no step."""
        state = self._monitor.state(message)
        before = self._e2e_marks.get(message, {})
        return {name: n - before.get(name, 0) for name, n in state.e2e_status.items() if n > before.get(name, 0)}

    # -- observation -------------------------------------------------------------------------------
    def value(self, message: str, signal: str) -> float:
        """Latest valid value of a signal (physical, in the DBC's unit) from the frames the monitor
        accepted since the latest scenario's acknowledgement (`start_scenario`). With no such frame now, a NaN
        (`NoFrames`) that a check records as "no frames of MESSAGE" (none came), "no frames of MESSAGE since the
        scenario started" or "MESSAGE timed out" (none lately). Records no step."""
        # the clock's latest read, not a new one: a predicate calls this every tick (bench.session.Session.recent)
        latest = self._monitor.latest(message, self.session.recent(), since=self._acknowledged_at)
        if latest is None:
            if signal not in self.session.codebook[message].signal_names:
                self.session.codebook[message].physical(signal, 0.0)  # raises the clear error
            state = self._monitor.state(message)
            if state.last_valid is None:
                return NoFrames(f"no frames of {message}")
            if state.last_valid < self._acknowledged_at:
                return NoFrames(f"no frames of {message} since the scenario started (the last at "
                                f"{state.last_valid:.3f} s)")
            return NoFrames(f"{message} timed out (last frame at {state.last_valid:.3f} s)")
        if signal not in latest:
            codec = self.session.codebook[message]
            codec.physical(signal, 0.0)  # raises the clear error
            if codec.multiplexed:        # a signal of a variant not received yet
                return NoFrames(f"no frame of {message} with {signal} (a multiplexed signal) since the scenario "
                                "started")
        return latest[signal]

    def history(self, message: str, signal: str, since: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """(times, values) of every valid frame of a signal since `since` (bench time, s; default: case
        start) as two numpy arrays: bench time in s and physical values in the DBC's unit. Records no step."""
        t, v = self._monitor.history(message, signal, self.start if since is None else since)
        return np.asarray(t, dtype=float), np.asarray(v, dtype=float)

    def received(self, message: str, signal: str, since: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """`history` of a message the case cannot judge without (a DUT's output it computes figures from): with
        no valid frame of `message` since `since` (default: case start), the case ends here as failed, with one
        line naming the message, its sender and how long the bench listened, "no MESSAGE from the external NODE
        in 2.0 s" (and the invalid frames it had instead, if any), not with a traceback from the case's own
        arithmetic on empty arrays. Records no step."""
        t, v = self.history(message, signal, since)
        if len(t) == 0:
            fail(self._silence(message, self.start if since is None else since), pytrace=False)
        return t, v

    def _silence(self, message: str, since: float) -> str:
        """The one line of `received` for a message without valid frames since `since`: silent for the whole
        case when none came since it started (the time then counts from the start), else since `since`."""
        senders = self.session.codebook[message].senders
        external = self.session.external
        who = " / ".join(f"the {'external' if node in external else 'simulated'} {node}" for node in senders)
        now = self.now
        last = self._monitor.state(message).last_valid
        if last is None or last < self.start:
            since = min(since, self.start)
        line = f"no {message} from {who or 'its sender'} in {max(0.0, now - since):.1f} s"
        if last is not None and last >= self.start:
            line += f" (the last at {last:.3f} s)"
        invalid = [f for f in self.invalid_log() if f.message == message and f.t >= since]
        if invalid:
            line += f" ({len(invalid)} invalid frames, the first: {invalid[0].reason})"
        faults = [f.describe() for f in self.session.faults.faults
                  if f.target in (message, *senders) and f.start < now and f.end > since]
        if faults:
            line += f" (injected meanwhile: {', '.join(faults)})"
        return line

    def timed_out(self, message: str) -> bool:
        """True when no valid frame of `message` came for more than 3 × its cycle time, or none ever came
        (a message without a cycle time times out only so). Records no step."""
        return self._monitor.timed_out(message, self.now)

    def invalid_log(self) -> list[InvalidFrame]:
        """Every invalid frame (checksum, counter, length, range) since the case (or its latest scenario)
        started, each with its bench time (s), identifier, message and reason (the monitor's `invalid_log`
        since then; `invalid_frames` is always a count, e.g. the case's in the report). Records no step."""
        monitor = self._monitor
        monitor.check_timeouts(self.now)   # (an ISO-TP exchange's N_Bs / N_Cr that ran out is an invalid frame)
        return monitor.invalid_log[max(0, self._invalid_mark - monitor.invalid_dropped):]

    # -- checks ------------------------------------------------------------------------------------
    def expect(self, name: str, measured: float, expected: float, *, abs_tol: float = 0.0,
               rel_tol: float = 0.0, unit: str = "", detail: str = "", node: str = "") -> bool:
        """Check that `measured` is within max(`abs_tol`, `rel_tol`·|`expected`|) of `expected` (`unit`:
        the unit of all three, shown in the report). Records one step: measured, expected, the tolerance,
        pass/fail; a NaN on either side fails (a `value()` without frames is recorded as "no frames of
        MESSAGE"). `node`: the node the check judges when it is not the case's DUT (e.g. `node="PLANT"` for the
        plant against its model), a node of the databases: the step is that node's, shown under it in the
        conformance section and JUnit, and never fails the case; a failure of a node the bench simulates makes a
        case whose DUT failed too inconclusive (docs/contract/README.md). Returns the verdict."""
        if abs_tol < 0 or rel_tol < 0:
            raise BenchError(f"check {name!r}: tolerances must not be negative")
        self._check_node(name, node)
        ok = within(float(measured), float(expected), abs_tol, rel_tol)
        return self._steps.record(name, ok, _shown(measured), _shown(expected),
                                  tolerance_text(abs_tol, rel_tol, unit), unit, detail, node)

    def _check_node(self, name: str, node: str) -> None:
        """A check's `node` must name nodes of the databases (a typo would be a node of its own in the report)."""
        if not node:
            return
        known = self.session.codebook.nodes
        unknown = [n for n in node.split(",") if n and n not in known]
        if unknown or not node.strip(","):
            raise BenchError(f"check {name!r}: node {node!r} is not a node of the databases (nodes: "
                             f"{', '.join(known)})")

    def expect_true(self, name: str, condition: bool, *, measured: float | str | None = None,
                    expected: float | str | None = None, detail: str = "", node: str = "") -> bool:
        """Check a condition the case computed itself. Records one step, pass when `condition` is true,
        with the `measured` and `expected` it is given (for the reader of the report); `node` as `expect`.
        Returns the verdict."""
        self._check_node(name, node)
        return self._steps.record(name, bool(condition), measured, expected, "", "", detail, node)

    def expect_between(self, name: str, measured: float, low: float, high: float, *, unit: str = "",
                       detail: str = "", node: str = "") -> bool:
        """Check that `low` ≤ `measured` ≤ `high` (bounds included, all in `unit`). Records one step with
        expected "[low, high]" and tolerance "range"; a NaN fails; `node` as `expect`. Returns the verdict."""
        self._check_node(name, node)
        ok = math.isfinite(float(measured)) and low <= float(measured) <= high
        return self._steps.record(name, ok, _shown(measured), f"[{low:g}, {high:g}]", "range", unit, detail, node)

    def eventually(self, name: str, predicate: Callable[[], bool], seconds: float, *, node: str = "") -> bool:
        """Run until `predicate()` is true, at most `seconds` s of bench time. Records one step: measured =
        the time it took (s) or "not within N", expected "≤ N", unit s; pass exactly when the measured time is
        ≤ `seconds` (the figure is the verdict's number; in real time the clock's, see `wait_until`); `node` as
        `expect`. Returns the verdict."""
        self._check_node(name, node)
        took = self._watch(predicate, seconds, until=True, check_first=True)
        ok = took is not None and took <= seconds
        measured: float | str = f"not within {seconds:g}" if took is None else took
        return self._steps.record(name, ok, measured, f"≤ {seconds:g}", "eventually", "s", node=node)

    def always(self, name: str, predicate: Callable[[], bool], seconds: float, *, node: str = "") -> bool:
        """Run for `seconds` s of bench time and check `predicate()` at every 1 ms tick; stops at the first
        tick where it is false. Records one step: "held N s", or "violated at +t s" (since the call); fail
        exactly when it was found false at t ≤ `seconds` (in real time, a check that finds it false only after
        the limit, because the bench ran late, is outside the window: it held; see `wait_until`); `node` as
        `expect`. Returns the verdict."""
        self._check_node(name, node)
        violated = self._watch(predicate, seconds, until=False, check_first=False)
        if violated is not None and violated <= seconds:
            return self._steps.record(name, False, f"violated at +{violated:g} s", f"for {seconds:g} s", "always",
                                      node=node)
        return self._steps.record(name, True, f"held {seconds:g} s", f"for {seconds:g} s", "always", node=node)

    def expect_clean_bus(self) -> bool:
        """No invalid frame (range, E2E, length) since the case (or its latest scenario) started.
        Records one step when every frame was valid, else one step per sending node: the DUT's invalid frames
        (and frames of no known message) fail the case; those of a message none of whose senders is among the
        case's DUTs are judged as their senders' (the step's `node`, as `expect`'s). A frame of the bench's own
        stimulus that reaches the monitor out of sequence on a late host is then the bench's problem, shown under
        its node, and makes the case inconclusive if the DUT failed too, instead of failing the DUT for it.
        Returns True when no frame was invalid."""
        name = "no invalid frame on the bus (range, E2E, length)"
        duts = set(self.result.duts)
        codebook = self.session.codebook
        by_node: dict[str, list[InvalidFrame]] = {}
        for frame in self.invalid_log():
            codec = codebook.by_name.get(frame.message)
            senders = codec.senders if codec is not None else ()
            node = "" if not duts or not senders or set(senders) & duts else ",".join(senders)
            by_node.setdefault(node, []).append(frame)
        if not by_node:
            return self._steps.record(name, True, 0, 0, "", "", "", "")
        for node, frames in sorted(by_node.items()):
            detail = "; ".join(f"{f.message} at {f.t:.3f} s: {f.reason}" for f in frames[:5])
            self._steps.record(name + (f" from {node}" if node else ""), False, len(frames), 0, "", "", detail,
                               node)
        return False

    def check_cycle_times(self, messages: Iterable[str] | None = None, *, p50_band: float = 0.05,
                          p99_max: float = 1.5, max_max: float = 3.0, min_frames: int = 10) -> bool:
        """Measured cycle time per message since the case started: p50 within ±p50_band of the DBC
        cycle (GenMsgCycleTime), p99 ≤ p99_max × cycle and max < max_max × cycle (the timeout bound), as
        fractions. Without `messages`: every periodic message seen on the bus since the case started, and
        every periodic message a node the bench simulates sends now (its restbus sends it), seen or not: one
        that never arrived fails. Records one step per message (measured p50 / p99 / max in ms); fewer than
        `min_frames` intervals fail. A message none of whose senders is among the case's DUTs (`dut` markers;
        e.g. a sensor the bench simulates) is judged as its sender's (the step's `node`, as `expect`'s): shown
        under that node and never fails the case. In real time a message this process sends (its restbus) times the
        bench itself: where it fails, how far it is past the bound is a figure of the bench's lateness too
        (Case.bench_verdict), and the case is inconclusive, not failed. Returns True when every message passed."""
        ok_all = True
        duts = self.result.duts
        # A simulated node's periodic message the restbus sends now is due on the bus whether it came or not (a
        # fault may have dropped every frame); an external node's are known only by their frames.
        sent = {name for station in self.session.stations
                for name, slot in station.restbus.slots.items() if slot.enabled}
        if messages is None:
            names = [n for n, s in self._monitor.by_name.items() if s.codec.cycle_time and (
                n in sent or s.intervals_dropped + len(s.intervals) > self._interval_marks.get(n, 0))]
        else:
            names = list(messages)
        for name in names:
            state = self._monitor.state(name)
            cycle = state.codec.cycle_time
            senders = state.codec.senders
            node = "" if not duts or set(senders) & set(duts) else ",".join(senders)
            intervals = state.intervals[max(0, self._interval_marks.get(name, 0) - state.intervals_dropped):]
            if cycle is None or len(intervals) < min_frames:
                arrived = state.last_valid is not None and state.last_valid >= self.start
                ok_all &= self._steps.record(f"cycle time {name}", False,
                                             f"{len(intervals)} intervals" if arrived or intervals
                                             else "no frames since the case started", f"≥ {min_frames}", "", "s",
                                             node=node)
                continue
            p50, p99, worst = percentile(intervals, 50), percentile(intervals, 99), max(intervals)
            ms = 1000.0
            ok = (abs(p50 - cycle) <= p50_band * cycle and p99 <= p99_max * cycle and worst < max_max * cycle)
            timing = self.session.self_timing
            if not ok and timing is not None and name in sent:
                for figure, late, bound in (("p50", abs(p50 - cycle), p50_band * cycle),
                                            ("p99", p99 - cycle, (p99_max - 1.0) * cycle),
                                            ("max", worst - cycle, (max_max - 1.0) * cycle)):
                    timing.add(f"{name} sent by the bench, cycle {figure}", late, self.now, bound)
            ok_all &= self._steps.record(
                f"cycle time {name}", ok, f"p50 {p50 * ms:.2f} / p99 {p99 * ms:.2f} / max {worst * ms:.2f}",
                f"{cycle * ms:g} ms", f"p50 ±{p50_band:.0%}, p99 ≤ {p99_max:g}×, max < {max_max:g}×", "ms",
                detail=f"{len(intervals)} intervals", node=node)
        return ok_all

    # -- report ------------------------------------------------------------------------------------
    def plot(self, title: str, signals: Sequence[tuple[str, str] | tuple[str, str, str]], *,
             ylabel: str = "", since: float | None = None) -> None:
        """A time plot in the report of signals given as (message, signal[, label]), from the valid frames
        since `since` (bench time, s; default: case start); x is the time since the case start (s), `ylabel`
        names the y unit. Records no step."""
        series = []
        for item in signals:
            message, signal = item[0], item[1]
            label = item[2] if len(item) > 2 else f"{message}.{signal}"
            t, v = self.history(message, signal, since)
            cycle = self.session.codebook[message].cycle_time
            series.append(Series(label, (t - self.start).tolist(), v.tolist(),
                                 gap=GAP_CYCLES * cycle if cycle else None))
        self.result.plots.append(Plot(title, "time since case start [s]", ylabel, series, x0=self.start))

    def plot_series(self, title: str, series: Sequence[Series], *, xlabel: str, ylabel: str,
                    kind: Literal["time", "xy"] = "time", x0: float | None = None) -> None:
        """A plot in the report of series the case computed (`kind` "time", or "xy" for a top view with
        equal axes); `x0`: the bench time at x = 0 of a time plot whose x is seconds (the report then shades
        fault windows on it). Records no step."""
        self.result.plots.append(Plot(title, xlabel, ylabel, list(series), kind, x0))

    def table(self, title: str, columns: Sequence[str], rows: Sequence[Sequence[object]]) -> None:
        """A table in the case's part of the report (e.g. measured figures next to a paper's); floats are
        shown with 4 significant digits. Records no step."""
        self.result.tables.append(Table(title, list(columns), [[_cell(c) for c in row] for row in rows]))

    def note(self, text: str) -> None:
        """A line of text in the case's part of the report. Records no step."""
        self.result.notes.append(text)


class _Timer:
    """A behaviour of the runner station that calls a test's callback periodically."""

    nodes: tuple[str, ...] = ()

    def __init__(self, first: float, period: float, callback: Callable[[float], None]) -> None:
        self.next = first
        self.period = period
        self.callback = callback

    def reset(self) -> None:
        pass

    def step(self, io: object, t: float, dt: float) -> None:
        if t + 1e-9 >= self.next:
            self.next += self.period
            self.callback(t)


def _largest_id(signal: SignalCodec) -> int:
    """The largest scenario id the command signal carries: its DBC maximum, else what its bits hold."""
    top = signal.mask if signal.maximum is None else int(signal.maximum)
    return max(1, min(top, signal.mask))


def _instances(plan: object) -> list[Fault]:
    """The case+ instances of the case that just ended (FaultPlan keeps them until the next begin)."""
    return list(getattr(plan, "last_case_instances", []))


def _cell(value: object) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)
