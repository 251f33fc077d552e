"""Conformance: the contract parser (hypothesis), [contract] in bench.toml, the dut/req/reference_only
markers on a small fixture project (collection errors, the skip, --bench-dut / bench run --dut, JUnit
properties, the report's conformance section), and the section's verdicts on hand-made results."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import xml.etree.ElementTree as ET
from dataclasses import asdict
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bench.config import load_config
from bench.contract import ContractError, is_requirement_id, load_requirements, parse_requirements
from bench.errors import ConfigError
from bench.pytest.marks import CaseMarks, ReferenceOnly, skip_reason, split_names
from bench.report.conformance import build_conformance
from bench.report.html import render_html
from bench.report.junit import build_junit
from bench.results import store as results_io
from bench.results.model import CaseRef, CaseResult, RequirementInfo, RunResult, Step
from tests.repo import BENCH_DBC, CHASSIS_DBC, ROOT

PYTEST = [sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-q"]
BENCH = [sys.executable, "-m", "bench"]
DOC = Path("doc.md")

# -- the parser ----------------------------------------------------------------------------------------------
IDS = st.from_regex(r"[A-Z][A-Z0-9]{0,4}(-[A-Z0-9]{1,4}){0,2}-[0-9]{2}", fullmatch=True)
TITLES = (st.text(st.characters(blacklist_categories=("Cc", "Cs", "Zl", "Zp", "Zs")) | st.just(" "), min_size=1,
                  max_size=30)
          .map(str.strip).filter(lambda t: t and not re.search(r"(^| )#+$", t)))
FILLER = st.sampled_from(["", "Body text: VCU_WheelCmd_FL.SteerAngleCmd = 0 within 20 ms.", "## VCU-FLT-09 — level 2",
                          "#### VCU-FLT-08 — level 4", "    ### VCU-FLT-07 — indented code", "- VCU-FLT-06 in a list",
                          "`### VCU-FLT-05 — inline code`", "### Overview", "### COM-E2E overview"])


def render(reqs: list[tuple[str, str]], fillers: list[str]) -> tuple[str, list[int]]:
    lines, where = [], []
    for i, (rid, title) in enumerate(reqs):
        lines.append(fillers[i % len(fillers)] if fillers else "")
        lines.append(f"### {rid} — {title}")
        where.append(len(lines))
    return "\n".join(lines) + "\n", where


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(IDS, TITLES), max_size=8, unique_by=lambda r: r[0]), st.lists(FILLER, max_size=5))
def test_parser_reads_back_every_heading(reqs: list[tuple[str, str]], fillers: list[str]) -> None:
    text, where = render(reqs, fillers)
    found = parse_requirements(text, DOC)
    assert [(r.id, r.title, r.line) for r in found] == [(i, t, n) for (i, t), n in zip(reqs, where)]


@settings(max_examples=100, deadline=None)
@given(st.lists(st.tuples(IDS, TITLES), min_size=1, max_size=5), st.sampled_from(["```", "~~~~", "```python"]))
def test_headings_in_fenced_code_are_examples(reqs: list[tuple[str, str]], fence: str) -> None:
    inner, _ = render(reqs, [])
    close = fence.rstrip("python")
    text = f"{fence}\n{inner}{close}\n### REAL-01 — after the fence\n"
    assert [r.id for r in parse_requirements(text, DOC)] == ["REAL-01"]


@settings(max_examples=300, deadline=None)
@given(st.text(max_size=400) | st.lists(st.sampled_from(["### ", "VCU-FLT-03", " — ", "x", "\n", "```", "-", "#",
                                                        "01", " "]), max_size=40).map("".join))
def test_parser_on_any_text_finds_ids_or_names_the_line(text: str) -> None:
    try:
        found = parse_requirements(text, DOC)
    except ContractError as exc:
        assert re.match(r"doc\.md:\d+: requirement heading must read", str(exc)), exc
        return
    for req in found:
        assert is_requirement_id(req.id) and req.title and 1 <= req.line <= len(text.splitlines())


@pytest.mark.parametrize("line", ["### VCU-FLT-03", "### VCU-FLT-03: Priority", "### VCU-FLT-03 – Priority (en dash)",
                                  "### VCU-FLT-03 —"])
def test_malformed_heading_names_file_and_line(line: str) -> None:
    with pytest.raises(ContractError, match=r"^doc\.md:3: requirement heading must read '### VCU-FLT-03 — <title>'"):
        parse_requirements(f"# VCU\n\n{line}\n", DOC)


def test_ids_follow_the_convention() -> None:
    assert all(map(is_requirement_id, ["VCU-FLT-03", "VCU-4WS-02", "COM-E2E-01", "PLANT-01"]))
    assert not any(map(is_requirement_id,
                       ["vcu-FLT-03", "VCU-FLT-3", "VCU-FLT-003", "VCU_FLT-03", "VCU-FLT-٠٣", "-01"]))


def test_duplicate_id_names_both_places(tmp_path: Path) -> None:
    (tmp_path / "a.md").write_text("### VCU-FLT-01 — one\n")
    (tmp_path / "b.md").write_text("text\n### VCU-FLT-01 — again\n")
    with pytest.raises(ContractError,
                       match=r"b\.md:2: duplicate requirement id VCU-FLT-01 \(first defined at .*a\.md:1\)"):
        load_requirements([tmp_path / "a.md", tmp_path / "b.md"])


# -- [contract] in bench.toml --------------------------------------------------------------------------------
def project(tmp_path: Path, contract: str) -> Path:
    path = tmp_path / "bench.toml"
    path.write_text(f'[bench]\ndatabases = ["{CHASSIS_DBC}", "{BENCH_DBC}"]\nstimulus = ["DRIVER", "TESTER"]\n'
                    f'plant = "tests.fixtures.echo_plant:build"\ntestcases = "cases"\nreports = "reports"\n\n'
                    f"{contract}")
    return path


def test_contract_documents_are_globs_relative_to_bench_toml(tmp_path: Path) -> None:
    (tmp_path / "contract").mkdir()
    (tmp_path / "contract" / "b.md").write_text("### B-01 — bee\n")
    (tmp_path / "contract" / "a.md").write_text("### A-01 — ay\n\n### A-02 — ay two\n")
    config = load_config(project(tmp_path, '[contract]\ndocuments = ["contract/*.md", "contract/a.md"]\n'))
    assert config.contract == (tmp_path / "contract" / "a.md", tmp_path / "contract" / "b.md")
    assert [(r.id, r.title, r.line) for r in config.requirements] == [("A-01", "ay", 1), ("A-02", "ay two", 3),
                                                                        ("B-01", "bee", 1)]
    assert load_config(project(tmp_path, "")).requirements == ()     # no [contract]: no requirement


@pytest.mark.parametrize("contract, words", [
    ('[contract]\ndocuments = [\n  "contract/*.md",\n  "nothing/*.md",\n]\n',
     ["bench.toml:11:", "'nothing/*.md' matches no file"]),
    ('[contract]\ndocuments = "contract/*.md"\n', ["bench.toml", "non-empty list of glob strings"]),
    ('[contract]\ndocuments = []\n', ["bench.toml", "non-empty list"]),
    ('[contract]\ndocument = ["contract/*.md"]\n', ["bench.toml", "unknown key(s) document"]),
    ('[[contract]]\ndocuments = ["contract/*.md"]\n', ["bench.toml", "[contract] must be a table"]),
], ids=["no-match", "not-a-list", "empty", "unknown-key", "not-a-table"])
def test_bad_contract_table(tmp_path: Path, contract: str, words: list[str]) -> None:
    (tmp_path / "contract").mkdir()
    (tmp_path / "contract" / "a.md").write_text("### A-01 — ay\n")
    with pytest.raises(ConfigError) as info:
        load_config(project(tmp_path, contract))
    assert all(w in str(info.value) for w in words), info.value


def test_duplicate_id_in_contract_is_a_config_error(tmp_path: Path) -> None:
    (tmp_path / "contract").mkdir()
    (tmp_path / "contract" / "a.md").write_text("### A-01 — ay\n")
    (tmp_path / "contract" / "b.md").write_text("\n\n### A-01 — ay again\n")
    with pytest.raises(ConfigError, match=r"b\.md:3: duplicate requirement id A-01"):
        load_config(project(tmp_path, '[contract]\ndocuments = ["contract/*.md"]\n'))


# -- markers on a fixture project ----------------------------------------------------------------------------
CONTRACT_VCU = """# VCU

```
### VCU-EX-01 — an example in a fence: not a requirement
```

### VCU-FLT-01 — Fault one
### VCU-FLT-02 — Fault two
### VCU-FLT-03 — Never checked
"""
CONTRACT_COMMON = "### COM-E2E-01 — Every node protects its frames\n### WHL-STS-01 — Wheel status\n"
CASES = '''import pytest

@pytest.mark.dut("VCU")
@pytest.mark.req("VCU-FLT-02")
@pytest.mark.reference_only("VCU", reason="configures the reference VCU")
def test_ref(bench):
    bench.expect("three", 1.0, 1.0, abs_tol=0.1)

@pytest.mark.dut("VCU")
@pytest.mark.req("VCU-FLT-01", "COM-E2E-01")
def test_pass(bench):
    bench.expect("one", 1.0, 1.0, abs_tol=0.1)

@pytest.mark.dut("VCU")
@pytest.mark.req("VCU-FLT-02")
def test_fail(bench):
    bench.expect("two", 1.0, 2.0, abs_tol=0.1)

@pytest.mark.dut("WHL_FL")
@pytest.mark.req("WHL-STS-01")
def test_wheel(bench):
    bench.expect("four", 1.0, 1.0, abs_tol=0.1)
'''


@pytest.fixture(scope="module")
def fixture_project(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("conformance")
    (root / "contract").mkdir()
    (root / "contract" / "vcu.md").write_text(CONTRACT_VCU)
    (root / "contract" / "common.md").write_text(CONTRACT_COMMON)
    (root / "cases").mkdir()
    (root / "cases" / "test_x.py").write_text(CASES)
    project(root, '[contract]\ndocuments = ["contract/*.md"]\n')
    return root


def run_pytest(root: Path, out: Path, *extra: str, cases: str = "cases") -> subprocess.CompletedProcess:
    return subprocess.run([*PYTEST, str(root / cases), "--bench-config", str(root / "bench.toml"),
                           "--bench-out", str(out), *extra], cwd=ROOT, capture_output=True, text=True, timeout=300)


def junit_cases(out: Path) -> dict[str, ET.Element]:
    return {tc.get("name"): tc for tc in ET.parse(out / "junit.xml").getroot().iter("testcase")}


def properties(testcase: ET.Element) -> list[tuple[str, str]]:
    return [(p.get("name"), p.get("value")) for p in testcase.findall("properties/property")]


def test_external_node_skips_reference_cases_and_the_report_judges_requirements(fixture_project: Path,
                                                                                 tmp_path: Path) -> None:
    result = run_pytest(fixture_project, tmp_path, "--bench-external", "VCU")
    assert result.returncode == 1, result.stdout + result.stderr      # test_fail fails on purpose
    cases = junit_cases(tmp_path)
    # the skipped case came first, before any case had started the run: it is in the report all the same
    assert list(cases) == ["test_ref", "test_pass", "test_fail", "test_wheel"]
    skipped = cases["test_ref"].find("skipped")
    assert skipped is not None
    assert "reference_only: configures the reference VCU (VCU is external)" in skipped.get("message")
    assert properties(cases["test_pass"]) == [("dut", "VCU"), ("req", "VCU-FLT-01"), ("req", "COM-E2E-01")]
    assert properties(cases["test_wheel"]) == [("dut", "WHL_FL"), ("req", "WHL-STS-01")]
    assert cases["test_fail"].find("failure") is not None
    html = (tmp_path / "report.html").read_text()
    section = html[html.index('<section id="conformance">'):]
    section = section[:section.index("</section>")]
    rows = dict(re.findall(r'<span class="mono rid">([A-Z0-9-]+)</span>.*?<span class="badge ([a-z-]+)">',
                           section, re.S))
    # VCU-FLT-02: test_fail failed (test_ref skipped); VCU-FLT-03: no case; COM-E2E-01 in the VCU table
    assert rows == {"COM-E2E-01": "pass", "VCU-FLT-01": "pass", "VCU-FLT-02": "fail", "VCU-FLT-03": "uncovered",
                    "WHL-STS-01": "pass"}
    assert "VCU-EX-01" not in section
    assert re.search(r'<h2 id="node-VCU">VCU <span class="node-kind">external \(the real ECU\)', section)
    assert re.search(r'<h2 id="node-WHL_FL">WHL_FL <span class="node-kind">simulated \(the reference ECU\)', section)
    assert '<a href="#case-3">test_fail</a>' in section and 'id="case-3"' in html


def test_simulated_node_runs_reference_cases(fixture_project: Path, tmp_path: Path) -> None:
    result = run_pytest(fixture_project, tmp_path, "-k", "ref or wheel")
    assert result.returncode == 0, result.stdout + result.stderr
    cases = junit_cases(tmp_path)
    assert list(cases) == ["test_ref", "test_wheel"] and cases["test_ref"].find("skipped") is None
    html = (tmp_path / "report.html").read_text()
    # -k deselected test_pass (VCU-FLT-01) and test_fail: counted as such, not uncovered
    row = re.search(r'VCU-FLT-01</span>.*?</tr>', html, re.S)
    assert row and "1 deselected case (not run here)" in row.group(0) and "badge not-run" in row.group(0)


def test_external_all_skips_reference_cases(fixture_project: Path, tmp_path: Path) -> None:
    result = run_pytest(fixture_project, tmp_path, "-k", "ref", "--bench-external", "all")
    assert result.returncode == 0, result.stdout + result.stderr
    skipped = junit_cases(tmp_path)["test_ref"].find("skipped")
    assert skipped is not None and "(VCU is external)" in skipped.get("message")


def test_bench_run_dut_runs_only_the_cases_that_judge_it(fixture_project: Path, tmp_path: Path) -> None:
    result = subprocess.run([*BENCH, "run", str(fixture_project / "cases"),
                             "--config", str(fixture_project / "bench.toml"),
                             "--out", str(tmp_path), "--dut", "VCU"], cwd=ROOT, capture_output=True, text=True,
                            timeout=300)
    assert result.returncode == 1, result.stdout + result.stderr
    assert list(junit_cases(tmp_path)) == ["test_ref", "test_pass", "test_fail"]
    html = (tmp_path / "report.html").read_text()
    row = re.search(r'WHL-STS-01</span>.*?</tr>', html, re.S)
    assert 'id="node-WHL_FL"' not in html and row and "1 deselected case (not run here)" in row.group(0)


def test_plugin_dut_option_deselects(fixture_project: Path, tmp_path: Path) -> None:
    result = run_pytest(fixture_project, tmp_path, "--bench-dut", "WHL_FL")
    assert result.returncode == 0 and "1 passed, 3 deselected" in result.stdout, result.stdout + result.stderr


@pytest.mark.parametrize("command", ["pytest", "bench"])
def test_unknown_dut_stops_before_any_case(fixture_project: Path, tmp_path: Path, command: str) -> None:
    if command == "pytest":
        result = run_pytest(fixture_project, tmp_path, "--bench-dut", "NOPE")
        assert result.returncode == pytest.ExitCode.USAGE_ERROR, result.stdout + result.stderr
        assert "--bench-dut: unknown node(s) NOPE" in result.stderr
    else:
        result = subprocess.run([*BENCH, "run", str(fixture_project / "cases"), "--config",
                                 str(fixture_project / "bench.toml"), "--out", str(tmp_path), "--dut", "NOPE"],
                                cwd=ROOT, capture_output=True, text=True, timeout=300)
        assert result.returncode == 2 and result.stderr.strip().count("\n") == 0, result.stdout + result.stderr
        assert "bench run: error: --dut: unknown node(s) NOPE" in result.stderr
    assert not (tmp_path / "junit.xml").exists()


BAD_CASES = '''import pytest

pytestmark = [pytest.mark.dut("VCU")]

def test_good(bench):
    pass

@pytest.mark.req("VCU-FLT-99")
def test_unknown_req(bench):
    pass

@pytest.mark.dut("BOGUS", 3)
def test_bad_node(bench):
    pass

@pytest.mark.req()
@pytest.mark.reference_only("ABS")
def test_empty(bench):
    pass
'''


def test_bad_markers_are_a_collection_error_naming_case_and_value(fixture_project: Path, tmp_path: Path) -> None:
    (fixture_project / "bad").mkdir(exist_ok=True)
    (fixture_project / "bad" / "test_bad.py").write_text(BAD_CASES)
    result = run_pytest(fixture_project, tmp_path, cases="bad")
    assert result.returncode == pytest.ExitCode.INTERRUPTED, result.stdout + result.stderr
    out = result.stdout
    assert "Interrupted: 1 error during collection" in out and "passed" not in out
    for words in (["test_unknown_req", "'VCU-FLT-99' is not a requirement of the contract",
                   "(nearby ids: VCU-FLT-01, VCU-FLT-02, VCU-FLT-03)"],
                  ["test_bad_node", "3 is not a node name"],
                  ["test_bad_node", "'BOGUS' is not a node of the databases"],
                  ["test_empty", "@pytest.mark.req without a requirement id"],
                  ["test_empty", "reference_only('ABS',): reason=\"...\" is required"]):
        assert any(all(w in line for w in words) for line in out.splitlines()), (words, out)
    assert "test_good" not in out and not (tmp_path / "junit.xml").exists()


def test_skip_reason_names_the_external_nodes() -> None:
    marks = CaseMarks(reference_only=[ReferenceOnly(("VCU", "WHL_FL"), "faults on the reference's frames")])
    assert skip_reason(marks, {"ABS"}) is None
    assert skip_reason(marks, {"WHL_FL"}) == "reference_only: faults on the reference's frames (WHL_FL is external)"
    assert skip_reason(marks, {"VCU", "WHL_FL", "ABS"}) == \
        "reference_only: faults on the reference's frames (VCU, WHL_FL are external)"
    assert split_names(["VCU,WHL_FL", "VCU ABS"]) == ["VCU", "WHL_FL", "ABS"]


# -- the section and the JUnit properties on hand-made results -----------------------------------------------
def catalogue() -> list[RequirementInfo]:
    return [RequirementInfo(rid, f"title of {rid}", "contract/x.md", i) for i, rid in enumerate(
        ["COM-E2E-01", "COM-E2E-02", "VCU-A-01", "VCU-A-02", "VCU-A-03", "VCU-A-04", "VCU-A-05", "WHL-S-01",
         "ABS-X-01"], 1)]


def case(name: str, outcome: str, duts: list[str], reqs: list[str]) -> CaseResult:
    return CaseResult(nodeid=f"testcases/test_m.py::{name}", name=name, outcome=outcome, duts=duts, reqs=reqs)  # type: ignore[arg-type]


def sample_run() -> RunResult:
    run = RunResult(started="2026-01-01T00:00:00", interface="embedded", channel="", time_mode="virtual",
                    external=["VCU"], requirements=catalogue())
    run.cases = [case("t_pass", "passed", ["VCU"], ["VCU-A-01", "COM-E2E-01"]),
                 case("t_fail", "failed", ["VCU"], ["VCU-A-02"]),
                 case("t_also", "passed", ["VCU"], ["VCU-A-02"]),
                 case("t_error", "error", ["VCU"], ["VCU-A-03"]),
                 case("t_skip", "skipped", ["VCU"], ["VCU-A-04"]),
                 case("t_abort", "aborted", ["VCU"], ["VCU-A-04"]),
                 case("t_wheel", "passed", ["WHL_RR"], ["WHL-S-01", "COM-E2E-01"]),
                 case("t_mixed", "skipped", ["WHL_RR"], ["WHL-S-01"])]
    run.deselected = [CaseRef("testcases/test_m.py::t_abs", "t_abs", ["ABS"], ["ABS-X-01"])]
    return run


def test_verdict_per_requirement_and_node() -> None:
    section = build_conformance(sample_run())
    assert section is not None
    tables = {t.node: t for t in section.nodes}
    assert list(tables) == ["VCU", "WHL_RR"] and tables["VCU"].external and not tables["WHL_RR"].external
    vcu = {r.requirement.id: r.verdict for r in tables["VCU"].rows}
    assert vcu == {"COM-E2E-01": "pass", "VCU-A-01": "pass", "VCU-A-02": "fail", "VCU-A-03": "fail",
                   "VCU-A-04": "not run", "VCU-A-05": "uncovered"}
    whl = {r.requirement.id: (r.verdict, r.ran, len(r.cases)) for r in tables["WHL_RR"].rows}
    assert whl == {"COM-E2E-01": ("pass", 1, 1), "WHL-S-01": ("pass", 1, 2)}
    # COM-E2E-01 in each node's table with that node's cases only
    com = next(r for r in tables["VCU"].rows if r.requirement.id == "COM-E2E-01")
    assert [c.name for c in com.cases] == ["t_pass"] and com.cases[0].anchor == "case-1"
    assert section.others is not None
    others = {r.requirement.id: r.verdict for r in section.others.rows}
    assert others == {"COM-E2E-02": "uncovered", "ABS-X-01": "not run"}      # ABS: only a deselected case
    assert tables["VCU"].counts == {"pass": 2, "fail": 2, "not run": 1, "uncovered": 1}


def test_parametrized_cases_take_one_line_and_failures_are_named() -> None:
    run = sample_run()
    run.cases = [case(f"t_p[{i}]", "failed" if i == 3 else "passed", ["VCU"], ["VCU-A-01"]) for i in range(6)]
    run.cases.append(case("t_q", "skipped", ["VCU"], ["VCU-A-01"]))
    section = build_conformance(run)
    assert section is not None
    row = next(r for r in section.nodes[0].rows if r.requirement.id == "VCU-A-01")
    (p, q) = row.groups
    assert (p.name, p.outcomes, [c.name for c in p.failed]) == ("t_p", {"passed": 5, "failed": 1}, ["t_p[3]"])
    assert (q.name, q.outcomes) == ("t_q", {"skipped": 1})
    html = render_html(run)
    assert '<a href="#case-1">t_p</a> ×6:' in html and '<a href="#case-4">t_p[3]</a>' in html


def test_no_contract_and_no_marks_means_no_section() -> None:
    run = RunResult(started="x", interface="embedded", channel="", time_mode="virtual",
                    cases=[case("t", "passed", [], [])])
    assert build_conformance(run) is None and 'id="conformance"' not in render_html(run)


def test_section_escapes_contract_text() -> None:
    run = sample_run()
    run.requirements[2] = RequirementInfo("VCU-A-01", '<img src=x onerror="alert(1)"> & co', "<b>doc</b>.md", 3)
    html = render_html(run)
    assert "<img src=x" not in html and "&lt;img src=x onerror=&#34;alert(1)&#34;&gt; &amp; co" in html
    assert "&lt;b&gt;doc&lt;/b&gt;.md:3" in html


def test_junit_properties_carry_dut_and_req() -> None:
    run = sample_run()
    run.cases[1].steps = [Step("x", 1.0, 2.0, "±0.1", "fail", 0.0)]
    tree = build_junit(run)
    cases = {tc.get("name"): tc for tc in tree.getroot().iter("testcase")}
    assert properties(cases["t_pass"]) == [("dut", "VCU"), ("req", "VCU-A-01"), ("req", "COM-E2E-01")]
    assert [child.tag for child in cases["t_fail"]][:2] == ["properties", "failure"]
    run.cases[0].duts, run.cases[0].reqs = [], []
    assert build_junit(run).getroot().find(".//testcase[@name='t_pass']/properties") is None


def test_parts_keep_the_catalogue_and_old_parts_still_load(tmp_path: Path) -> None:
    run = sample_run()
    results_io.dump(run, tmp_path / "a.json")
    back = results_io.load(tmp_path / "a.json")
    assert asdict(back) == asdict(run)
    old = asdict(run)
    del old["requirements"], old["deselected"]
    for c in old["cases"]:
        del c["duts"], c["reqs"]
    (tmp_path / "old.json").write_text(json.dumps(old))
    loaded = results_io.load(tmp_path / "old.json")
    assert loaded.requirements == [] and loaded.cases[0].duts == []
    # two workers deselect the same case; a case deselected by -k on one worker but run by another stays run
    other = sample_run()
    other.cases = [case("t_abs", "passed", ["ABS"], ["ABS-X-01"])]
    merged = results_io.merge([("gw0", run), ("gw1", other), ("gw2", sample_run())], 1.0)
    assert merged.deselected == [] and merged.requirements == catalogue()
    other.cases = []
    merged = results_io.merge([("gw0", run), ("gw1", other)], 1.0)
    assert [d.nodeid for d in merged.deselected] == ["testcases/test_m.py::t_abs"]


# -- steps judge the node they name (issue 26) ----------------------------------------------------------------
CONTRACT_STEPS = ("### SBW-CTL-01 — Follows\n### SBW-CTL-02 — Steps\n### SBW-CTL-03 — Holds\n"
                  "### PLANT-DYN-02 — Single-track model\n")
STEP_CASES = '''import pytest

@pytest.mark.dut("SBW")
@pytest.mark.req("SBW-CTL-01", "PLANT-DYN-02")
def test_plant_fails(bench):
    bench.expect("pinion tracks", 0.2, 0.0, abs_tol=0.5, unit="deg")
    bench.expect("plant vs model", 0.3, 0.0, abs_tol=0.1, unit="deg/s", node="PLANT")

@pytest.mark.dut("SBW")
@pytest.mark.req("SBW-CTL-02", "PLANT-DYN-02")
def test_sbw_fails(bench):
    bench.expect("pinion tracks", 0.9, 0.0, abs_tol=0.5, unit="deg")
    bench.expect("plant vs model", 0.05, 0.0, abs_tol=0.1, unit="deg/s", node="PLANT")

@pytest.mark.dut("SBW")
@pytest.mark.req("SBW-CTL-03")
def test_both_fail(bench):
    bench.expect("pinion tracks", 0.9, 0.0, abs_tol=0.5, unit="deg")
    bench.expect_true("the plant's sensor model", False, node="PLANT")

@pytest.mark.dut("SBW")
def test_typo(bench):
    bench.expect("x", 1.0, 1.0, node="PLANTT")
'''


@pytest.fixture(scope="module")
def step_nodes_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[subprocess.CompletedProcess, Path]:
    """`bench run` (virtual time) of four SBW cases whose steps name the PLANT or not; (the process, its out dir)."""
    root = tmp_path_factory.mktemp("step_nodes")
    (root / "contract").mkdir()
    (root / "contract" / "c.md").write_text(CONTRACT_STEPS)
    (root / "cases").mkdir()
    (root / "cases" / "test_s.py").write_text(STEP_CASES)
    project(root, '[contract]\ndocuments = ["contract/*.md"]\n')
    out = root / "out"
    result = subprocess.run([*BENCH, "run", str(root / "cases"), "--config", str(root / "bench.toml"), "--out",
                             str(out)], cwd=ROOT, capture_output=True, text=True, timeout=300)
    return result, out


def conformance_rows(html: str) -> dict[str, dict[str, str]]:
    """Per node table of the report's conformance section: requirement id -> verdict."""
    section = html[html.index('<section id="conformance">'):]
    section = section[:section.index("</section>")]
    tables = {}
    for part in section.split('<h2 id="node-')[1:]:
        node = part[:part.index('"')]
        tables[node] = dict(re.findall(r'<span class="mono rid">([A-Z0-9-]+)</span>.*?<span class="badge ([a-z-]+)">',
                                       part, re.S))
    return tables


def test_a_failing_plant_step_never_fails_the_sbw(step_nodes_run: tuple[subprocess.CompletedProcess, Path]) -> None:
    result, out = step_nodes_run
    assert result.returncode == 1, result.stdout + result.stderr        # test_sbw_fails and the typo fail
    record = {c["name"]: c for c in json.loads((out / "results.json").read_text())["cases"]}
    assert {n: c["outcome"] for n, c in record.items()} == {
        "test_plant_fails": "passed", "test_sbw_fails": "failed", "test_both_fail": "inconclusive",
        "test_typo": "failed"}
    assert [(s["name"], s["node"], s["verdict"]) for s in record["test_plant_fails"]["steps"]] == [
        ("pinion tracks", "", "pass"), ("plant vs model", "PLANT", "fail")]
    # the console says whose failure it is
    assert re.search(r"PLANT failed in \S*test_plant_fails, not the DUT's verdict: plant vs model: measured 0\.3",
                     result.stdout), result.stdout
    # a problem of the bench's own simulation: a finding of the run
    findings = json.loads((out / "results.json").read_text())["findings"]
    assert any(f["source"] == "bench.steps" and "PLANT failed a step of" in f["message"]
               and "test_plant_fails" in f["message"] for f in findings), findings

    cases = junit_cases(out)
    plant = cases["test_plant_fails"]
    assert plant.find("failure") is None and plant.find("skipped") is None
    props = properties(plant)
    assert ("node_verdict", "PLANT: failed") in props and ("dut", "SBW") in props
    assert [v for k, v in props if k == "node_failure"] == [
        "PLANT: plant vs model: measured 0.30, expected 0.00 (±0.1 deg/s)"]   # 0.01 below the tolerance (checks)
    assert "FAIL [PLANT] plant vs model" in (plant.findtext("system-out") or "")
    failure = cases["test_sbw_fails"].find("failure")
    assert failure is not None and "pinion tracks" in failure.get("message", "")
    assert "plant vs model" not in failure.get("message", "")
    assert ("node_verdict", "PLANT: passed") in properties(cases["test_sbw_fails"])
    skipped = cases["test_both_fail"].find("skipped")
    assert skipped is not None and skipped.get("type") == "inconclusive"
    assert "the bench's own simulation failed a check in this case (PLANT: the plant's sensor model" in \
        skipped.get("message", "")
    typo = cases["test_typo"].find("failure")
    assert typo is not None and "node 'PLANTT' is not a node of the databases" in (typo.get("message") or "")

    tables = conformance_rows((out / "report.html").read_text())
    # the SBW's verdicts are made of its own steps; the PLANT's of the steps that name it
    assert tables["SBW"] == {"SBW-CTL-01": "pass", "SBW-CTL-02": "fail", "SBW-CTL-03": "not-run"}
    assert tables["PLANT"] == {"PLANT-DYN-02": "fail"}


def test_the_plant_table_lists_each_case_with_the_plants_outcome() -> None:
    run = sample_run()
    run.requirements = [*catalogue(), RequirementInfo("PLANT-DYN-02", "model", "contract/plant.md", 1)]
    sbw = case("t_sbw", "passed", ["VCU"], ["VCU-A-05", "PLANT-DYN-02"])
    sbw.steps = [Step("own", 1.0, 1.0, "±0.1", "pass", 0.0),
                 Step("plant vs model", 0.3, 0.0, "±0.1", "fail", 0.1, node="PLANT"),
                 Step("cycle time IMU_Motion", "p50 12", "10 ms", "", "fail", 0.2, node="IMU")]
    late = case("t_late", "inconclusive", ["VCU"], ["PLANT-DYN-02"])
    late.steps = [Step("plant vs model", 0.3, 0.0, "±0.1", "fail", 0.1, node="PLANT")]
    late.inconclusive = "bench late by 80.3 ms on stimulus DRV_Pedals at 0.251 s (bound 20 ms)"
    run.cases = [sbw, late]
    section = build_conformance(run)
    assert section is not None
    tables = {t.node: t for t in section.nodes}
    assert list(tables) == ["IMU", "PLANT", "VCU"] and tables["VCU"].dut and not tables["PLANT"].dut
    vcu = next(r for r in tables["VCU"].rows if r.requirement.id == "VCU-A-05")
    assert (vcu.verdict, [c.outcome for c in vcu.cases]) == ("pass", ["passed"])
    plant = next(r for r in tables["PLANT"].rows if r.requirement.id == "PLANT-DYN-02")
    # the bench's lateness makes every verdict of its case inconclusive, the plant's too
    assert [(c.name, c.outcome) for c in plant.cases] == [("t_sbw", "failed"), ("t_late", "inconclusive")]
    assert plant.verdict == "fail" and tables["PLANT"].steps is None
    # IMU: no requirement of its own in the case: the case is listed in the row of steps under the table
    imu = tables["IMU"].steps
    assert imu is not None and [(c.name, c.outcome) for c in imu.cases] == [("t_sbw", "failed")]
    assert imu.verdict == "fail" and tables["IMU"].counts == {}
    html = render_html(run)
    assert "steps that judge IMU in cases of other nodes" in html and "judged only by steps of other nodes" in html
    assert re.search(r'class="node-step failed"[^>]*>PLANT: failed</span>', html)


def test_outcome_of_a_node_follows_its_own_steps() -> None:
    c = case("t", "failed", ["SBW"], [])
    c.steps = [Step("own", 1.0, 0.0, "±0.1", "fail", 0.0), Step("plant", 0.0, 0.0, "±0.1", "pass", 0.0, node="PLANT"),
               Step("both", 0.0, 0.0, "", "pass", 0.0, node="IMU,PLANT"), Step("dut named", 0.0, 0.0, "", "pass", 0.0,
                                                                            node="SBW")]
    assert c.other_nodes == ["PLANT", "IMU"] and [s.name for s in c.failed_steps] == ["own"]
    assert (c.outcome_of("SBW"), c.outcome_of("PLANT"), c.outcome_of("VCU")) == ("failed", "passed", "failed")
    c.steps[1].verdict = "fail"
    c.outcome, c.inconclusive = "inconclusive", "the bench's own simulation failed a check in this case (PLANT: ...)"
    assert (c.outcome_of("SBW"), c.outcome_of("PLANT"), c.outcome_of("IMU")) == ("inconclusive", "failed", "passed")
    c.outcome = "error"
    assert c.outcome_of("PLANT") == "error"
    nodut = case("n", "failed", [], [])
    nodut.steps = [Step("plant", 1.0, 0.0, "", "fail", 0.0, node="PLANT")]
    assert nodut.failed_steps == nodut.steps and nodut.outcome_of("PLANT") == "failed"   # no DUT: every step its
