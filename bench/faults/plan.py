"""Fault injection: what a broken ECU or bus does to frames, scoped to a message or node and a window.

The kinds (what each does, its TARGET and PARAM) are the registry in bench/faults/kinds.py; this module
parses and checks specs and applies the faults of a run, asking each fault's kind.
Spec syntax (command line, `--fault`): `KIND:TARGET[:PARAM]@[case+]START[-END]`, times in seconds.
Without `case+` the window counts from the start of the run (bench time) and an open END lasts to the
end of the run; with `case+` it counts from the start of every case, and an open END lasts to the end
of that case. E.g. `drop:MESSAGE@2-3`, `silence:NODE@1.5-`, `checksum_offset:MESSAGE:1@2-4`,
`flood:0x000:8@1-2`, `drop:MESSAGE@case+1-2` (1 s to 2 s after each case's start).

Every fault is on the record: it counts the frames it acted on (dropped, delayed, duplicated,
corrupted, silenced or babbled), and :meth:`FaultPlan.records` gives what the report, JUnit and the
MCAP log show. :func:`validate` checks specs against the databases before a run starts.
"""

from __future__ import annotations

import math
import random
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

from bench.canid import IDENTITY
from bench.database.codec import Codebook
from bench.errors import ConfigError
from bench.faults.kinds import KINDS, MESSAGE, Outgoing, kinds_with_target
from bench.results.model import FaultRecord

__all__ = ["KINDS", "FRAME_KINDS", "RUN", "CASE", "CASE_PREFIX", "COMMAND_LINE", "RANDOM_SEED", "Fault", "FaultPlan",
           "parse_fault", "check_fault", "validate"]

FRAME_KINDS = kinds_with_target(MESSAGE)   # the kinds whose TARGET is a message (from the registry)
RANDOM_SEED = 0x5EED     # checksum_random is deterministic, so a campaign stays reproducible
RUN, CASE = "run", "case"   # what a fault's window counts from
CASE_PREFIX = "case+"
COMMAND_LINE = "command line"


@dataclass(eq=False)   # identity: two faults with the same spec are two faults
class Fault:
    kind: str
    target: str          # message name (frame kinds), node name (silence, bus_off), identifier (flood)
    start: float         # bench time, s
    end: float = math.inf
    param: float = 0.0   # delay s, bit index, counter jump, checksum value/offset, flood frames per ms
    frozen: int | None = field(default=None, repr=False)   # counter/checksum value at the fault's start
    relative: str = RUN        # CASE: start/end count from each case's start (a template, see FaultPlan)
    source: str = COMMAND_LINE  # or the node id of the case that injected it
    frames: int = 0            # frames it acted on so far
    parent: Fault | None = field(default=None, repr=False, compare=False)   # the case+ template it came from

    def active(self, t: float) -> bool:
        return self.start <= t < self.end

    def hit(self, n: int = 1) -> None:
        """Count frames the fault acted on (also on its case+ template, for the run's total)."""
        self.frames += n
        if self.parent is not None:
            self.parent.frames += n

    def describe(self) -> str:
        end = "" if math.isinf(self.end) else f"{self.end:g}"
        param = f":{self.param:g}" if self.param else ""
        where = CASE_PREFIX if self.relative == CASE else ""
        return f"{self.kind}:{self.target}{param}@{where}{self.start:g}-{end}"

    def record(self) -> FaultRecord:
        spec = self.parent.describe() if self.parent is not None else self.describe()
        return FaultRecord(spec=spec, source=self.source, kind=self.kind, target=self.target, start=self.start,
                           end=None if math.isinf(self.end) else self.end, frames=self.frames,
                           relative=self.relative)


def parse_fault(spec: str) -> Fault:
    """`KIND:TARGET[:PARAM]@[case+]START[-END]` -> Fault; ConfigError naming the spec and what is wrong."""
    head, at, window = spec.partition("@")
    parts = head.split(":")
    if not at or len(parts) not in (2, 3):
        raise ConfigError(f"--fault {spec!r}: expected KIND:TARGET[:PARAM]@[case+]START[-END]")
    relative = RUN
    if window.startswith(CASE_PREFIX):
        relative, window = CASE, window[len(CASE_PREFIX):]
    elif window.startswith("run+"):
        window = window[len("run+"):]
    kind, target = parts[0], parts[1]
    if kind not in KINDS:
        raise ConfigError(f"--fault {spec!r}: unknown kind {kind!r} (kinds: {', '.join(KINDS)})")
    start_text, _, end_text = window.partition("-")
    param = _number(spec, "PARAM", parts[2]) if len(parts) == 3 else 0.0
    start = _number(spec, "START", start_text)
    end = _number(spec, "END", end_text) if end_text else math.inf
    if not (math.isfinite(param) and math.isfinite(start) and start >= 0 and end > start):
        raise ConfigError(f"--fault {spec!r}: need 0 <= START < END and a finite PARAM")
    return Fault(kind, target, start, end, param, relative=relative)


def _number(spec: str, name: str, text: str) -> float:
    """A number of the spec (PARAM, START or END); ConfigError naming which one is not, and where `case+` goes when
    it was written inside the window rather than once at its front."""
    try:
        return float(text)
    except ValueError:
        pass
    if CASE_PREFIX in text:
        head, _, window = spec.partition("@")
        fixed = f"{head}@{CASE_PREFIX}{window.replace(CASE_PREFIX, '')}"
        raise ConfigError(f"--fault {spec!r}: {name} {text!r} is not a number: case+ goes once, at the front of "
                          f"the window, and makes both times count from each case's start (e.g. {fixed})")
    if not text:
        raise ConfigError(f"--fault {spec!r}: {name} is missing (the window is START-END in s, START >= 0)")
    raise ConfigError(f"--fault {spec!r}: {name} {text!r} is not a number" + (" (s)" if name != "PARAM" else ""))


def check_fault(fault: Fault, codebook: Codebook, simulated: frozenset[str] | None = None) -> None:
    """ConfigError when the fault's target or PARAM does not fit its kind and the databases, or (given the nodes
    `simulated` by the process that would inject it) when none of its frames is the bench's to change."""
    kind = KINDS.get(fault.kind)
    if kind is None:
        raise ConfigError(f"fault {fault.describe()}: unknown kind {fault.kind!r} (kinds: {', '.join(KINDS)})")
    if not (fault.start >= 0 and fault.end > fault.start):
        raise ConfigError(f"fault {fault.describe()}: need 0 <= START < END")
    problem = kind.check_target(fault.target, codebook) or kind.check_param(fault.param, codebook.by_name.get(
        fault.target))
    if problem is None and simulated is not None:
        problem = kind.check_reach(fault.target, codebook, simulated)
    if problem:
        raise ConfigError(f"fault {fault.describe()}: {problem}")


def validate(specs: Iterable[str], codebook: Codebook, simulated: frozenset[str] | None = None) -> list[str]:
    """One line per problem of the `--fault` specs (syntax, kind, target in the databases, window,
    PARAM, and with `simulated` a sender the process simulates); empty when all can be injected. For the
    command line's check before the first case."""
    problems = []
    for spec in specs:
        try:
            fault = parse_fault(spec)
            check_fault(fault, codebook, simulated)
        except ConfigError as exc:
            text = str(exc)
            problems.append(text if text.startswith("--fault") else f"--fault {spec!r}: {text.partition(': ')[2]}")
    return problems


class FaultPlan:
    """The faults of a run; every station of the run applies them to the frames it sends."""

    def __init__(self, codebook: Codebook, simulated: frozenset[str] | None = None) -> None:
        self.codebook = codebook
        self.simulated = simulated   # the nodes whose frames the run's stations send (None: not checked)
        self.faults: list[Fault] = []       # the faults that may act now (run windows, this case's instances)
        self.templates: list[Fault] = []    # case+ faults: an instance of each for every case
        self.history: list[Fault] = []      # every fault of the run, in the order added (for the record)
        self._case_instances: list[Fault] = []
        self.last_case_instances: list[Fault] = []   # the case+ instances of the case that ended last
        self._rng = random.Random(RANDOM_SEED)
        self.listener: Callable[[Fault], None] | None = None   # told of every fault added (the MCAP log)

    def add(self, fault: Fault) -> Fault:
        check_fault(fault, self.codebook, self.simulated)
        if fault.relative == CASE:
            self.templates.append(fault)
        else:
            self.faults.append(fault)
        self.history.append(fault)
        if self.listener is not None:
            self.listener(fault)
        return fault

    def extend(self, faults: Iterable[Fault]) -> None:
        for fault in faults:
            self.add(fault)

    def begin_case(self, t: float) -> list[Fault]:
        """A case starts at bench time `t`: every case+ fault gets its window in this case."""
        self.end_case(t)
        for template in self.templates:
            instance = Fault(template.kind, template.target, t + template.start, t + template.end, template.param,
                             source=template.source, parent=template)
            self._case_instances.append(instance)
            self.faults.append(instance)
        return list(self._case_instances)

    def end_case(self, t: float) -> None:
        """The case ends at `t`: its case+ windows close (an open END lasts to here)."""
        if not self._case_instances:
            return
        for instance in self._case_instances:
            instance.end = min(instance.end, t)
            if instance in self.faults:
                self.faults.remove(instance)
        self.last_case_instances = self._case_instances
        self._case_instances = []

    def records(self) -> list[FaultRecord]:
        """Every fault of the run (case+ ones once, with their frames summed over the cases)."""
        return [fault.record() for fault in self.history]

    @property
    def any(self) -> bool:
        """Whether a fault was ever added (or case+ ones wait). It stays true after a window ends: on socketcan
        it keeps a message on the tick scheduler, so no frame of a later fault's window can still come from the
        kernel's broadcast manager, which a fault cannot reach (bench/transport/periodic.py stops a task only at its
        next quiet moment)."""
        return bool(self.faults or self.templates)

    # -- applied by stations ----------------------------------------------------------------------
    def babble(self, t: float, dt: float) -> list[tuple[int, bytes]]:
        """Frames the babbling node and error-frame faults put on the bus this tick: (frame_id, data), bench.canid."""
        out: list[tuple[int, bytes]] = []
        for fault in self.faults:
            if fault.active(t):
                frames = KINDS[fault.kind].babble(fault, dt)
                if frames:
                    out.extend(frames)
                    fault.hit(len(frames))
        return out

    def apply(self, t: float, frame_id: int, data: bytes) -> list[tuple[float, bytes]]:
        """The frames that go on the bus instead of `data`, each with its delay (0: now), s."""
        codec = self.codebook.by_id.get(frame_id & IDENTITY)
        if codec is None:
            return [(0.0, data)]
        out: Outgoing | None = None
        for fault in self.faults:
            if not fault.start <= t < fault.end:   # Fault.active, written out (every frame asks every fault)
                continue
            kind = KINDS[fault.kind]
            if not kind.applies(fault, frame_id, codec):
                continue
            if out is None:
                out = Outgoing(frame_id, [data], self._rng, codec.protection)
            fault.hit()
            kind.act(fault, out)
            if out.dropped:
                return []
        if out is None:
            return [(0.0, data)]
        return [(out.delay, f) for f in out.frames]
