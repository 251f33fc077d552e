"""A campaign split over machines and merged back (issue 18): `bench run --shard K/N` in three separate
processes, `bench report merge`, and the merged report against the one-process report, case for case.

The subset is a small real part of the campaign (about a dozen fast cases of two vehicles); the shards run
at the same time, as on three CI machines, the first with two workers (-n 2). The mismatch checks then edit
copies of the real shard folders.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import pytest

from bench.cli import main
from tests.repo import ROOT

pytest.importorskip("pytest_split")

SUBSET = "test_ackermann_normal or test_beyond_geometry_not_reachable or test_sbw_step_50kmh"
SHARDS = 3


def bench(*argv: str) -> subprocess.Popen[str]:
    return subprocess.Popen([sys.executable, "-m", "bench", *argv], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)


def finish(process: subprocess.Popen[str]) -> str:
    out, _ = process.communicate(timeout=600)
    assert process.returncode == 0, out
    return out


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """The one-process run, the three shards (side by side) and their merge."""
    base = tmp_path_factory.mktemp("shards")
    one = base / "one"
    shards = [base / f"shard{k}" for k in range(1, SHARDS + 1)]
    merged = base / "merged"
    # shard 1 also shares its cases between two workers (-n 2): shards and -n combine
    processes = [bench("run", "-k", SUBSET, "--shard", f"{k}/{SHARDS}", "--out", str(folder),
                       *(["-n", "2"] if k == 1 else []))
                 for k, folder in enumerate(shards, 1)]
    for process in processes:
        finish(process)
    finish(bench("run", "-k", SUBSET, "--out", str(one)))
    merge_output = finish(bench("report", "merge", *map(str, shards), "--out", str(merged)))
    return {"base": base, "one": one, "shards": shards, "merged": merged, "merge_output": merge_output}


def results(folder: Path) -> dict[str, Any]:
    data: dict[str, Any] = json.loads((folder / "results.json").read_text())
    return data


def cases(folder: Path) -> dict[str, tuple[str, list[str], list[str], int]]:
    """nodeid -> (outcome, requirement ids, duts, steps)."""
    return {c["nodeid"]: (c["outcome"], c["reqs"], c["duts"], len(c["steps"])) for c in results(folder)["cases"]}


def junit(folder: Path) -> dict[tuple[str, str], tuple[str, list[tuple[str, str]]]]:
    """(classname, name) -> (verdict, its req and dut properties) of every testcase in junit.xml."""
    out = {}
    for case in ET.parse(folder / "junit.xml").getroot().iter("testcase"):
        verdict = next((child.tag for child in case if child.tag in ("failure", "error", "skipped")), "passed")
        properties = sorted((p.get("name", ""), p.get("value", "")) for p in case.iter("property")
                            if p.get("name") in ("req", "dut"))
        out[(case.get("classname", ""), case.get("name", ""))] = (verdict, properties)
    return out


def test_each_case_ran_in_exactly_one_shard(runs: dict[str, Any]) -> None:
    ran = [nodeid for folder in runs["shards"] for nodeid in cases(folder)]
    assert len(ran) == len(set(ran)), "a case ran in two shards"
    assert set(ran) == set(cases(runs["one"]))
    assert len(ran) >= 9, ran                                   # the subset is real: about a dozen cases
    assert all(cases(folder) for folder in runs["shards"]), "a shard got no case"


def test_merged_results_equal_the_one_process_run(runs: dict[str, Any]) -> None:
    merged, one = cases(runs["merged"]), cases(runs["one"])
    assert merged == one
    assert all(outcome == "passed" for outcome, *_ in one.values())
    assert all(reqs for _, reqs, _, _ in one.values()), "the subset's cases carry requirement ids"
    assert results(runs["merged"])["sim_time"] == pytest.approx(sum(results(f)["sim_time"] for f in runs["shards"]))


def test_merged_junit_is_the_union_and_equals_the_one_process_junit(runs: dict[str, Any]) -> None:
    union: dict[tuple[str, str], tuple[str, list[tuple[str, str]]]] = {}
    for folder in runs["shards"]:
        union.update(junit(folder))
    merged, one = junit(runs["merged"]), junit(runs["one"])
    assert merged == union == one
    assert all(any(name == "req" for name, _ in properties) for _, properties in one.values())


def test_merged_html_and_log_index(runs: dict[str, Any], capsys: pytest.CaptureFixture[str]) -> None:
    merged = runs["merged"]
    html = (merged / "report.html").read_text()
    for nodeid in cases(runs["one"]):
        assert nodeid.rpartition("::")[2].split("[")[0] in html
    assert "Shards: one report folder and MCAP log each" in html and 'href="logs.json"' in html
    index = json.loads((merged / "logs.json").read_text())["logs"]
    assert [entry["shard"] for entry in index] == [f"{k}/{SHARDS}" for k in range(1, SHARDS + 1)]
    for entry in index:
        for name in entry["logs"]:
            assert (merged / name).is_file()
    logs = [name for entry in index for name in entry["logs"]]
    assert [name.rpartition("/")[2] for name in logs] == ["run-gw0.mcap", "run-gw1.mcap", "run.mcap", "run.mcap"]
    assert main(["log", "info", str(merged)]) == 0
    assert capsys.readouterr().out.count("complete") == len(logs)


# -- shards that do not make one campaign: each is a clear error naming the folder -------------------------
def copies(runs: dict[str, Any], tmp_path: Path) -> list[Path]:
    out = []
    for folder in runs["shards"]:
        target = tmp_path / folder.name
        shutil.copytree(folder, target)
        out.append(target)
    return out


def merge_errors(capsys: pytest.CaptureFixture[str], folders: list[Path], out: Path) -> str:
    assert main(["report", "merge", *map(str, folders), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and not (out / "report.html").exists()
    return err


def edit(path: Path, **changes: Any) -> None:
    data = json.loads(path.read_text())
    data.update(changes)
    path.write_text(json.dumps(data))


def test_missing_shard(runs: dict[str, Any], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    folders = copies(runs, tmp_path)
    err = merge_errors(capsys, folders[:2], tmp_path / "out")
    assert f"shard(s) 3/{SHARDS} missing" in err


def test_the_same_shard_twice(runs: dict[str, Any], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    folders = copies(runs, tmp_path)
    shutil.copytree(folders[0], tmp_path / "again")
    err = merge_errors(capsys, [*folders, tmp_path / "again"], tmp_path / "out")
    assert f"{tmp_path / 'again'}: shard 1/{SHARDS} again" in err
    assert "ran here and in" in err                            # its cases overlap the first copy's


def test_other_databases(runs: dict[str, Any], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    folders = copies(runs, tmp_path)
    record = json.loads((folders[1] / "shard.json").read_text())
    edit(folders[1] / "shard.json", databases={**record["databases"], "chassis.dbc": "0" * 64})
    err = merge_errors(capsys, folders, tmp_path / "out")
    assert f"{folders[1]}: databases (DBC files)" in err


def test_other_bench_version(runs: dict[str, Any], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    folders = copies(runs, tmp_path)
    edit(folders[2] / "shard.json", bench_version="0.0.1")
    err = merge_errors(capsys, folders, tmp_path / "out")
    assert f"{folders[2]}: bench version 0.0.1 differs" in err


def test_shard_that_lost_cases(runs: dict[str, Any], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """An aborted shard: its results lack cases it was given (and the campaign it knows is smaller)."""
    folders = copies(runs, tmp_path)
    data = results(folders[0])
    lost = data["cases"].pop()["nodeid"]
    (folders[0] / "results.json").write_text(json.dumps(data))
    err = merge_errors(capsys, folders, tmp_path / "out")
    assert f"{folders[0]}: 1 cases given to this shard but not in its results (aborted?): {lost}" in err


def test_a_folder_that_is_not_a_shard(runs: dict[str, Any], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    err = merge_errors(capsys, [runs["one"], *runs["shards"][1:]], tmp_path / "out")
    assert f"{runs['one']}: no shard.json: not a shard" in err


@pytest.mark.parametrize("spec", ["0/3", "4/3", "3", "a/b", "1/0"])
def test_bad_shard_is_an_error_before_the_first_case(spec: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(["run", "--shard", spec])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert f"argument --shard: '{spec}'" in err and "K/N" in err


def test_plain_pytest_takes_the_same_shard_option(tmp_path: Path) -> None:
    result = subprocess.run([sys.executable, "-m", "pytest", "-q", "testcases", "--bench-shard", "4/3",
                             "--bench-out", str(tmp_path / "out")], cwd=ROOT, capture_output=True, text=True,
                            timeout=300)
    assert result.returncode == 4 and "--bench-shard: '4/3': K/N needs 1 <= K <= N" in result.stderr, result.stderr


def test_a_shard_no_case_fell_to_still_reports(tmp_path: Path) -> None:
    """More shards than cases: the empty shard passes and writes its folder, so that the merge gets all N."""
    one_case = "test_ackermann_normal and 900"
    folders = [tmp_path / "s1", tmp_path / "s2"]
    processes = [bench("run", "-k", one_case, "--shard", f"{k}/2", "--out", str(f)) for k, f in enumerate(folders, 1)]
    for process in processes:
        finish(process)
    ran = [cases(f) for f in folders]
    assert sorted(len(r) for r in ran) == [0, 1]
    out = finish(bench("report", "merge", *map(str, folders), "--out", str(tmp_path / "merged")))
    assert "1 cases (1 passed): PASS" in out
    assert cases(tmp_path / "merged") == {**ran[0], **ran[1]}
