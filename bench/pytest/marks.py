"""The conformance markers of a test case: which nodes it judges, which requirements it checks,
and whether it only makes sense while a node is the bench's own simulation.

    @pytest.mark.dut("ECU", ...)                       the node(s) the case judges
    @pytest.mark.req("ECU-FLT-03", ...)                the requirement id(s) it checks
    @pytest.mark.reference_only("ECU", reason="...")   skipped while ECU is external (a real ECU)
    @pytest.mark.campaign(name="smoke")                the campaign it belongs to (-m "campaign(name='smoke')")
    @pytest.mark.calibration("ECU", v_l0="km/h")       bench.toml [calibration.ECU] values it needs while ECU is
                                                       external (checked before the first case)

Reading and checking them is plain code on pytest's marks, so the plugin only wires hooks and the
checks can be tested without running pytest.
"""

from __future__ import annotations

import difflib
from collections.abc import Collection, Iterable, Mapping
from dataclasses import dataclass, field

import pytest

DUT, REQ, REFERENCE_ONLY, CAMPAIGN, CALIBRATION = "dut", "req", "reference_only", "campaign", "calibration"
MARKER_HELP = {
    DUT: "dut(NODE, ...): the node(s) of the databases this case judges",
    REQ: "req(ID, ...): the requirement id(s) of the contract documents this case checks",
    REFERENCE_ONLY: "reference_only(NODE, ..., reason=TEXT): the case only makes sense while NODE is the "
                    "bench's own simulation; skipped with TEXT when NODE is external",
    CAMPAIGN: "campaign(name=NAME): the campaign the case belongs to (select one with -m \"campaign(name='NAME')\")",
    CALIBRATION: "calibration(NODE, NAME=UNIT, ...): the values of bench.toml's [calibration.NODE] the case needs "
                 "while NODE is external, checked (present, in UNIT) before the first case runs",
}


@dataclass(frozen=True)
class ReferenceOnly:
    nodes: tuple[str, ...]
    reason: str


@dataclass
class CaseMarks:
    """The markers of one case (module, class and function marks together), and what is wrong with them."""

    duts: list[str] = field(default_factory=list)
    reqs: list[str] = field(default_factory=list)
    reference_only: list[ReferenceOnly] = field(default_factory=list)
    calibration: dict[str, dict[str, str]] = field(default_factory=dict)   # node -> name -> unit
    problems: list[str] = field(default_factory=list)

    @property
    def any(self) -> bool:
        return bool(self.duts or self.reqs or self.reference_only or self.calibration or self.problems)


def _strings(mark: pytest.Mark, what: str, problems: list[str]) -> list[str]:
    if not mark.args:
        problems.append(f"@pytest.mark.{mark.name} without a {what}")
    out = []
    for arg in mark.args:
        if isinstance(arg, str) and arg:
            out.append(arg)
        else:
            problems.append(f"@pytest.mark.{mark.name}: {arg!r} is not a {what} (a non-empty string)")
    return out


def read_marks(item: pytest.Item) -> CaseMarks:
    """The case's markers, outermost first, each value once; malformed markers become problems."""
    marks = CaseMarks()
    for mark in reversed(list(item.iter_markers())):      # iter_markers: closest (function) first
        if mark.name == CALIBRATION:
            _read_calibration(mark, marks)
            continue
        if mark.name not in (DUT, REQ, REFERENCE_ONLY):
            continue
        extra = set(mark.kwargs) - ({"reason"} if mark.name == REFERENCE_ONLY else set())
        if extra:
            marks.problems.append(f"@pytest.mark.{mark.name}: unknown keyword(s) {', '.join(sorted(extra))}")
        if mark.name == DUT:
            marks.duts.extend(n for n in _strings(mark, "node name", marks.problems) if n not in marks.duts)
        elif mark.name == REQ:
            marks.reqs.extend(r for r in _strings(mark, "requirement id", marks.problems) if r not in marks.reqs)
        else:
            nodes = _strings(mark, "node name", marks.problems)
            reason = mark.kwargs.get("reason")
            if not isinstance(reason, str) or not reason.strip():
                marks.problems.append(f"@pytest.mark.reference_only{tuple(mark.args)!r}: reason=\"...\" is "
                                      f"required (a non-empty string), got {reason!r}")
            elif nodes:
                marks.reference_only.append(ReferenceOnly(tuple(nodes), reason.strip()))
    return marks


def _read_calibration(mark: pytest.Mark, marks: CaseMarks) -> None:
    nodes = _strings(mark, "node name", marks.problems)
    if len(nodes) != 1 or not mark.kwargs:
        marks.problems.append(f"@pytest.mark.calibration: give one node and its names with units, e.g. "
                              f"calibration(\"ECU\", v_max=\"km/h\"), got {mark.args!r} {mark.kwargs!r}")
        return
    for name, unit in mark.kwargs.items():
        if not isinstance(unit, str) or not unit:
            marks.problems.append(f"@pytest.mark.calibration({nodes[0]!r}): {name}={unit!r} is not a unit")
        else:
            marks.calibration.setdefault(nodes[0], {})[name] = unit


def missing_calibration(marks: CaseMarks, external: Collection[str],
                        calibration: Mapping[str, Mapping[str, tuple[float, str]]]) -> list[str]:
    """What bench.toml's [calibration.NODE] lacks for this case while NODE is external: "[calibration.NODE] NAME:
    missing" or "...: unit 'X', the case needs 'Y'" (the bench's own simulated ECU needs none)."""
    found = []
    for node, names in marks.calibration.items():
        if node not in external:
            continue
        table = calibration.get(node, {})
        for name, unit in names.items():
            if name not in table:
                found.append(f"[calibration.{node}] {name}: missing (give {name} = {{ value = <number>, "
                             f"unit = \"{unit}\" }}, the external {node}'s value)")
            elif table[name][1] != unit:
                found.append(f"[calibration.{node}] {name}: unit {table[name][1]!r}, the case needs {unit!r}")
    return found


def check_marks(marks: CaseMarks, nodes: Collection[str], requirements: Collection[str],
                documents: str) -> list[str]:
    """What is wrong with the case's markers against the databases' nodes and the contract's ids."""
    problems = list(marks.problems)
    known = ", ".join(nodes)
    used = [(DUT, n) for n in marks.duts] + [(REFERENCE_ONLY, n) for r in marks.reference_only for n in r.nodes] \
        + [(CALIBRATION, n) for n in marks.calibration]
    for name, node in used:
        if node not in nodes:
            problems.append(f"@pytest.mark.{name}: {node!r} is not a node of the databases (nodes: {known})")
    for rid in marks.reqs:
        if rid not in requirements:
            if not documents:
                problems.append(f"@pytest.mark.req: {rid!r} is not a requirement of the contract: bench.toml has "
                                "no [contract] documents")
                continue
            nearby = sorted(difflib.get_close_matches(rid, list(requirements), n=3, cutoff=0.6))
            problems.append(f"@pytest.mark.req: {rid!r} is not a requirement of the contract"
                            + (f" (nearby ids: {', '.join(nearby)})" if nearby else f" ({documents})"))
    return problems


def skip_reason(marks: CaseMarks, external: Collection[str], start_values_only: Collection[str] = ()) -> str | None:
    """The skip text of a reference-only case while one of its nodes is external, or of a case whose DUT the bench
    plays from the database's start values only (`start_values_only`: a project without a plant simulates every
    node that is not external so, and such a node has no behaviour to judge); else None."""
    for ref in marks.reference_only:
        real = [n for n in ref.nodes if n in external]
        if real:
            verb = "is" if len(real) == 1 else "are"
            return f"reference_only: {ref.reason} ({', '.join(real)} {verb} external)"
    played = [n for n in marks.duts if n in start_values_only]
    if played:
        verb = "is" if len(played) == 1 else "are"
        them = "it" if len(played) == 1 else "them"
        return (f"dut {', '.join(played)} {verb} not on the bus: the bench plays {them} from the database's start "
                f"values (the project has no plant); put the ECU on the bus and give "
                f"--external {','.join(played)}")
    return None


def split_names(values: Iterable[str]) -> list[str]:
    """Node names as given on a command line: repeated options, commas or spaces."""
    out: list[str] = []
    for value in values:
        out.extend(n for n in value.replace(",", " ").split() if n and n not in out)
    return out
