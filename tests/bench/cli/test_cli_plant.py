"""`bench plant`: a case+ --fault window, which counts from each case's start, is refused with one line (exit 2);
bench plant runs no cases, so such a fault would never act (it dropped nothing). So is a fault on frames it does not
send (an external node's). Its status lines say why frames were invalid, not only how many."""

from __future__ import annotations

import pytest
from rich.console import Console

from bench.checks.monitor import Monitor
from bench.cli import main
from bench.cli.plant import INVALID_SHOWN, _report_invalid, plant_faults
from bench.database.codec import Codebook
from bench.errors import ConfigError
from bench.faults.plan import RUN
from tests.fakes import ipv4_group

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


@pytest.mark.parametrize(("spec", "named"), [("drop:VCU_WheelCmd_FL@1-2", "sent by VCU"),
                                              ("silence:VCU@1-", "VCU is a node the bench does not simulate")])
def test_a_fault_on_frames_the_plant_does_not_send_is_refused(spec: str, named: str,
                                                              capsys: pytest.CaptureFixture[str]) -> None:
    """It used to start and act on nothing: the external VCU's frames are not the plant's to change."""
    code = main(["plant", "--interface", "udp_multicast", "--channel", ipv4_group(), "--external", "VCU",
                 "--fault", spec])
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2 and len(lines) == 1, err
    assert spec in lines[0] and named in lines[0] and "Traceback" not in err


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


def test_new_invalid_frames_are_described_once(codebook: Codebook) -> None:
    monitor = Monitor(codebook)
    codec = codebook["BENCH_Control"]
    console = Console(record=True, width=200)
    for t in (0.1, 0.2):
        monitor.on_frame(t, codec.frame_id, bytes(codec.length - 1), "rx")   # one byte short
    shown = _report_invalid(console, monitor, 0)
    text = console.export_text()
    assert shown == 2
    assert text.count(f"BENCH_Control (0x{codec.frame_id:X}): length {codec.length - 1}, DBC says {codec.length}") == 2
    assert _report_invalid(console, monitor, shown) == 2 and console.export_text() == ""   # nothing new
    for i in range(INVALID_SHOWN + 2):
        monitor.on_frame(1.0 + i, 0x7FF, b"", "rx")   # unknown identifier
    _report_invalid(console, monitor, shown)
    text = console.export_text()
    assert text.count("unknown identifier") == INVALID_SHOWN and "... and 2 more" in text
