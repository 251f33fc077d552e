"""A case's diagnostic exchange in its report: each request and response of its testers, under the node it went
to, described with the node's declaration (DTCs by name, as the run log's /diag topics show them)."""

from __future__ import annotations

from bench.case import Case
from bench.checks.steps import StepLog
from bench.config import RunSettings, load_config
from bench.results.model import CaseResult
from bench.session import BenchSession


def test_the_exchange_table_names_the_node_and_the_services() -> None:
    session = BenchSession(load_config(), RunSettings())
    session.start()
    try:
        steps = StepLog(session.now)
        case = Case(session, CaseResult(nodeid="t", name="t", outcome="passed", steps=steps.steps), steps)
        client = case.diag("VCU")
        client.clear_dtc(0xFFFFFF)
        client.get_dtc_by_status_mask(0x2F)
        case.close()
    finally:
        session.close()
    [table] = [t for t in case.result.tables if t.title == "Diagnostic exchange"]
    assert table.columns == ["t (s)", "node", "", "message"]
    nodes = {row[1] for row in table.rows}
    messages = [str(row[3]) for row in table.rows]
    assert nodes == {"VCU"}, table.rows
    assert messages == ["ClearDiagnosticInformation [14 FF FF FF]", "positive ClearDiagnosticInformation [54]",
                        "ReadDTCInformation 0x02 [19 02 2F]",
                        "positive ReadDTCInformation: no DTC [59 02 FF]"], messages
