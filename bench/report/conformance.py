"""The report's conformance section: per node, requirement -> the cases that check it -> a verdict.

A requirement belongs to the nodes whose name prefix equals its id prefix (MOTOR-STS-01 -> MOTOR_FL,
MOTOR_FR, ...; ECU-FLT-03 -> ECU; see bench.contract). A requirement that belongs to no node with a table of its
own (common rules such as COM-E2E-01) appears in the table of every node judged by a case that checks it,
with those cases. Requirements in no table are listed at the end. Verdicts:

- pass: no case that checks it failed, and at least one passed (the cell says how many of them ran);
- fail: a case that checks it failed or errored;
- not run: every case that checks it was skipped, deselected, cut short or inconclusive (the bench's own timing);
- uncovered: no case of the campaign checks it.

A case judges its DUTs (`dut` markers) and every node its steps name (`bench.expect(..., node="PLANT")`). Under a
node's table each case shows its outcome *for that node* (CaseResult.outcome_of): a DUT's is the case's outcome,
made of the DUT's steps only; another node's is made of the steps that name it. A node a case judges only by such
steps gets the case under the requirements of its own (by id prefix) that the case names; a case that names none
of them is listed under the table, in a row of its own ("steps of cases of other nodes"), so that a failed step is
never shown under no node.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field, replace
from typing import Literal

from bench.contract import node_prefix, owner_prefix
from bench.results.model import CaseResult, RequirementInfo, RunResult

ReqVerdict = Literal["pass", "fail", "not run", "uncovered"]
VERDICTS: tuple[ReqVerdict, ...] = ("pass", "fail", "not run", "uncovered")
_FAILED = ("failed", "error")


@dataclass
class CaseLink:
    """A case under a requirement; `anchor` is the id of its section in the report ("" when it did not run)."""

    nodeid: str
    name: str
    outcome: str            # a CaseResult outcome, or "deselected"
    anchor: str = ""


@dataclass
class CaseGroup:
    """The cases of one test function (its parameters together), so that a requirement checked by thirty
    parametrized cases takes one line; the ones that failed are listed by their parameters."""

    name: str               # the test function's name, without parameters
    cases: list[CaseLink]

    @property
    def outcomes(self) -> dict[str, int]:
        return dict(Counter(c.outcome for c in self.cases))

    @property
    def failed(self) -> list[CaseLink]:
        return [c for c in self.cases if c.outcome in _FAILED]


@dataclass
class Row:
    requirement: RequirementInfo
    cases: list[CaseLink] = field(default_factory=list)

    @property
    def groups(self) -> list[CaseGroup]:
        """The cases that ran or were skipped, grouped by test function, in report order."""
        groups: dict[str, CaseGroup] = {}
        for case in self.cases:
            if case.outcome == "deselected":
                continue
            base = case.nodeid.partition("[")[0]
            groups.setdefault(base, CaseGroup(case.name.partition("[")[0], [])).cases.append(case)
        return list(groups.values())

    @property
    def deselected(self) -> int:
        return sum(1 for c in self.cases if c.outcome == "deselected")

    @property
    def ran(self) -> int:
        return sum(1 for c in self.cases if c.outcome in ("passed", *_FAILED))

    @property
    def verdict(self) -> ReqVerdict:
        if not self.cases:
            return "uncovered"
        outcomes = {c.outcome for c in self.cases}
        if outcomes & set(_FAILED):
            return "fail"
        return "pass" if "passed" in outcomes else "not run"


@dataclass
class NodeTable:
    node: str
    external: bool
    rows: list[Row]
    steps: Row | None = None    # cases of other DUTs that judge this node by steps under none of its requirements
    dut: bool = True            # some case of the run names this node as its DUT (else: only steps judge it)

    @property
    def counts(self) -> dict[str, int]:
        counts = Counter(r.verdict for r in self.rows)
        return {v: counts[v] for v in VERDICTS if counts[v]}


@dataclass
class Conformance:
    nodes: list[NodeTable]
    others: NodeTable | None    # requirements in no node's table (their node judged by no case of this run)


@dataclass
class _Case:
    link: CaseLink
    duts: list[str]
    reqs: list[str]
    result: CaseResult | None = None   # None: deselected
    others: list[str] = field(default_factory=list)   # nodes its steps judge besides its DUTs

    def link_for(self, node: str) -> CaseLink:
        """Its link under `node`'s table: with its outcome for that node (CaseResult.outcome_of)."""
        if self.result is None:
            return self.link
        return replace(self.link, outcome=self.result.outcome_of(node))


def build_conformance(run: RunResult) -> Conformance | None:
    """The section's tables; None when the run has neither a contract nor a case that declares a node."""
    cases = [_Case(CaseLink(c.nodeid, c.name, c.outcome, f"case-{i}"), c.duts, c.reqs, c, c.other_nodes)
             for i, c in enumerate(run.cases, 1)]             # anchors as report.html.j2 numbers the cases
    ran = {c.nodeid for c in run.cases}
    cases += [_Case(CaseLink(d.nodeid, d.name, "deselected"), d.duts, d.reqs)
              for d in run.deselected if d.nodeid not in ran]
    catalogue = list(run.requirements)
    known = {r.id for r in catalogue}
    for case in cases:                                       # ids the contract lacks (an old or foreign result)
        for rid in case.reqs:
            if rid not in known:
                known.add(rid)
                catalogue.append(RequirementInfo(rid, "(not in the contract documents)", ""))
    duts = {n for c in run.cases for n in c.duts}
    judged = sorted(duts | {n for c in cases for n in c.others})
    if not judged and not catalogue:
        return None
    prefixes = {node_prefix(n) for n in judged}
    tables, shown = [], set()
    for node in judged:
        rows = []
        for req in catalogue:
            owned = owner_prefix(req.id) == node_prefix(node)
            links = [c.link_for(node) for c in cases if req.id in c.reqs and (owned or node in c.duts)]
            if owned or (links and owner_prefix(req.id) not in prefixes):
                rows.append(Row(req, links))
                shown.add(req.id)
        # cases that judge the node by steps under none of its requirements: a row of their own, below its table
        loose = [c.link_for(node) for c in cases if node in c.others
                 and not any(owner_prefix(r) == node_prefix(node) for r in c.reqs)]
        steps = Row(RequirementInfo("", f"steps that judge {node} in cases of other nodes (under no requirement of "
                                        f"{node} the case names)", ""), loose) if loose else None
        tables.append(NodeTable(node, node in run.external, rows, steps, node in duts))
    rest = [Row(r, [c.link for c in cases if r.id in c.reqs]) for r in catalogue if r.id not in shown]
    return Conformance(tables, NodeTable("", False, rest) if rest else None)
