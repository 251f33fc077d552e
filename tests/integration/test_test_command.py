"""The README's test command finishes in a bounded time on a loaded host (issue 27, finding 2 and acceptance 2).

Real-time tests (udp_multicast, socketcan, the wall clock; their verdicts depend on the host's load) carry the
marker `realtime`: the README's test command leaves them out, a second documented command runs them, and `.ci/run`
runs both steps. The campaign (testcases/) runs once: in tests/integration/test_report_campaign.py, not a second
time as a test path.
"""

from __future__ import annotations

import re
import subprocess
import sys
import tomllib

from tests.repo import ROOT

#: The real-time tests that failed the README's command on a loaded 2-core host (issue 27), and one of the
#: stop-signal tests (a second from signal to exit, wall time).
LOADED_HOST_FAILURES = (
    "tests/bench/transport/test_bus_settings.py::test_pytest_plugin_options_reach_python_can",
    "tests/integration/test_duplicate_sender.py::test_two_plant_processes_on_udp_multicast",
    "tests/integration/test_example_ecus.py::test_campaign_passes_against_the_example[VCU]",
    "tests/integration/test_run_integration.py::test_plant_and_runner_in_two_processes_over_udp_multicast",
    "tests/integration/test_stop_signals.py::test_sigterm_during_a_flood_at_the_bus_limit",
)
FAST = "python -m pytest -n auto -m 'not realtime'"
REALTIME = "python -m pytest -m realtime"


def test_the_marker_is_registered_and_the_campaign_is_no_test_path() -> None:
    options = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["pytest"]["ini_options"]
    assert any(m.startswith("realtime:") for m in options["markers"])
    assert options["testpaths"] == ["tests"]                         # testcases/ runs in the report test only
    report_test = (ROOT / "tests" / "integration" / "test_report_campaign.py").read_text(encoding="utf-8")
    assert '"bench", "run", "testcases"' in report_test and "def test_the_campaign_passes" in report_test


def test_readme_and_ci_run_both_steps() -> None:
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    block = re.search(r"```sh\n(.*?)```", readme, re.S)
    assert block is not None
    assert f"pip install -e '.[test]' && {FAST}" in block.group(1) and REALTIME in block.group(1)
    assert re.search(r"about \d+ minutes? on 2 cores", readme), "the README states the command's wall time"
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8")
    fast, realtime = ci.find("python3 -m pytest -q -p no:cacheprovider -n auto -m 'not realtime'"), \
        ci.find("python3 -m pytest -q -p no:cacheprovider -m realtime")
    assert 0 <= fast < realtime, "the suite, then its real-time tests, each a step of .ci/run"


def test_the_real_time_tests_carry_the_marker() -> None:
    listed = subprocess.run([sys.executable, "-m", "pytest", "--collect-only", "-q", "-p", "no:cacheprovider",
                             "-m", "realtime", "tests"], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert listed.returncode == 0, listed.stdout[-2000:] + listed.stderr[-2000:]
    ids = {line.strip() for line in listed.stdout.splitlines() if "::" in line}
    missing = [t for t in LOADED_HOST_FAILURES if t not in ids]
    assert not missing, missing
    assert not any(i.startswith("testcases/") for i in ids)
    assert "tests/integration/test_report_campaign.py::test_the_campaign_passes" not in ids   # virtual time
