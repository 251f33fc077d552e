"""`bench plant --fault`: a case+ window, which counts from each case's start, is refused with one line (exit 2);
bench plant runs no cases, so such a fault would never act (it dropped nothing)."""

from __future__ import annotations

import pytest

from bench.cli import main
from bench.cli.plant import plant_faults
from bench.errors import ConfigError
from bench.faults import RUN

SPEC = "drop:IMU_Motion@case+3.5-3.8"


def test_case_window_refused_in_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["plant", "--interface", "udp_multicast", "--fault", SPEC])
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2
    assert len(lines) == 1, err
    assert "--fault" in lines[0] and SPEC in lines[0] and "runs no cases" in lines[0]
    assert "drop:IMU_Motion@3.5-3.8" in lines[0]            # the window it takes instead
    assert "Traceback" not in err


def test_run_windows_accepted() -> None:
    faults = plant_faults(["drop:IMU_Motion@3.5-3.8", "silence:IMU@run+1-"])
    assert [(f.relative, f.start, f.end) for f in faults] == [(RUN, 3.5, 3.8), (RUN, 1.0, float("inf"))]


def test_open_case_window_refused() -> None:
    with pytest.raises(ConfigError, match=r"case\+ counts from each case's start.*silence:IMU@0\.5-\)"):
        plant_faults(["silence:IMU@case+0.5-"])


def test_help_says_so(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["plant", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "from bench plant's start" in text and "refuses it" in text
