"""`bench diag NODE ACTION`: the tester at the command line (bench/cli/diag.py, docs/contract/diagnostics.md).

On the embedded default every node is the bench's reference ECU and the command runs in virtual time, in this
process: each call is a new bench run (its nodes start as delivered, DIAG-COD-01's `default`). Bad input is one
line on stderr (`bench diag: error: ...`), exit 2, never a traceback. The realtime tests reach a real bus: a silent
group (nobody answers) and `bench plant` in another process (whose nodes keep a written coding between two calls).
"""

from __future__ import annotations

import re
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from bench.cli import main
from tests.child import Child
from tests.fakes import ipv4_group
from tests.repo import ROOT

CONFIG = ROOT / "bench.toml"
ERROR = "bench diag: error: "


def diag(capsys: pytest.CaptureFixture[str], *argv: str, config: Path = CONFIG) -> tuple[int, str, str]:
    code = main(["diag", *argv, "--config", str(config)])
    captured = capsys.readouterr()
    assert "Traceback" not in captured.out + captured.err
    return code, captured.out, captured.err


def ok(capsys: pytest.CaptureFixture[str], *argv: str) -> list[str]:
    code, out, err = diag(capsys, *argv)
    assert code == 0 and err == "", err
    return out.splitlines()


def refused(capsys: pytest.CaptureFixture[str], *argv: str, config: Path = CONFIG) -> str:
    """The one error line of a command that must stop with exit 2 and print nothing else."""
    code, out, err = diag(capsys, *argv, config=config)
    lines = err.splitlines()
    assert code == 2 and len(lines) == 1 and lines[0].startswith(ERROR), err
    assert out == ""
    return lines[0][len(ERROR):]


# -- the actions -----------------------------------------------------------------------------------------------
def test_dtc_lists_the_vcus_request_timeout(capsys: pytest.CaptureFixture[str]) -> None:
    """With no driver on the bus the VCU's motion request times out (VCU-FLT-01): failing, not yet confirmed."""
    lines = ok(capsys, "VCU", "dtc")
    assert lines[0] == "VCU: 1 DTC(s) with status & 0xFF"
    assert lines[1].split() == ["C1C05-87", "0x5C0587", "REQUEST_TIMEOUT:", "Motion", "request", "(DRV_MotionRequest,",
                                "or", "DRV_Steering", "in", "NORMAL/ADAPTIVE)", "timed", "out", "status", "0x27",
                                "testFailed", "testFailedThisOperationCycle", "pendingDTC", "testFailedSinceLastClear"]
    assert len(lines) == 2
    assert ok(capsys, "VCU", "dtc", "--mask", "0x08") == ["VCU: 0 DTC(s) with status & 0x08"]   # not confirmed
    assert ok(capsys, "VCU", "dtc", "--mask", "1")[0] == "VCU: 1 DTC(s) with status & 0x01"
    assert ok(capsys, "WHL_FL", "dtc") == ["WHL_FL: 0 DTC(s) with status & 0xFF"]   # tested, never failed: 0x00
    assert ok(capsys, "IMU", "dtc") == ["IMU: 0 DTC(s) with status & 0xFF"]         # no DTC at all


def test_dtc_with_a_fault(capsys: pytest.CaptureFixture[str]) -> None:
    """--fault acts on the frames the bench's simulated nodes send (it was accepted and ignored before)."""
    lines = ok(capsys, "WHL_FL", "dtc", "--fault", "drop:VCU_WheelCmd_FL@0-")
    assert lines[0] == "WHL_FL: 1 DTC(s) with status & 0xFF"
    assert lines[1].startswith("  C1D03-87 0x5D0387 CMD_TIMEOUT: ") and "status 0x27 testFailed " in lines[1]
    assert ok(capsys, "WHL_FL", "read", "WheelFault", "--fault", "drop:VCU_WheelCmd_FL@0-") == [
        "WHL_FL: 0xFD13 WheelFault = CMD_TIMEOUT (3)"]


def test_read_by_id_and_by_name(capsys: pytest.CaptureFixture[str]) -> None:
    lines = ok(capsys, "SBW", "read", "0xF187", "EcuSerialNumber", "0xf190", "SoftwareVersionNumber", "IdealYawGain")
    assert lines == ["SBW: 0xF187 SparePartNumber = SBW-000001",
                     "SBW: 0xF18C EcuSerialNumber = SBW-REF00001",
                     "SBW: 0xF190 VehicleIdentificationNumber = BENCH000000000001",
                     "SBW: 0xF195 SoftwareVersionNumber = REF-1.0",
                     "SBW: 0xFDC1 IdealYawGain = 0.28 1/s"]
    [line] = ok(capsys, "WHL_RR", "read", "OperatingTime")
    match = re.fullmatch(r"WHL_RR: 0xDD00 OperatingTime = ([0-9.]+) s", line)
    assert match and 0.2 <= float(match[1]) < 0.5, line            # the 0.2 s the bus ran before the request
    assert ok(capsys, "WHL_FR", "read", "EcuSerialNumber") == ["WHL_FR: 0xF18C EcuSerialNumber = WFR-REF00001"]


def test_write_then_read(capsys: pytest.CaptureFixture[str]) -> None:
    """The write is accepted (extended session, security unlocked by the tester); the next `bench diag` is a new
    bench run whose SBW starts as delivered, so on the embedded bus it reads the default again (DIAG-COD-01).
    That the node keeps it: test_write_then_read_on_the_plant."""
    assert ok(capsys, "SBW", "write", "SteeringMode", "YAW_RATE") == ["SBW: wrote 0xFDC0 SteeringMode = YAW_RATE"]
    assert ok(capsys, "SBW", "write", "0xFDC1", "0.3") == ["SBW: wrote 0xFDC1 IdealYawGain = 0.3"]
    assert ok(capsys, "SBW", "write", "SteeringMode", "2") == ["SBW: wrote 0xFDC0 SteeringMode = 2"]
    [line] = ok(capsys, "SBW", "read", "SteeringMode")
    assert re.fullmatch(r"SBW: 0xFDC0 SteeringMode = DIRECT \(0\)", line), line


def test_routine(capsys: pytest.CaptureFixture[str]) -> None:
    assert ok(capsys, "SBW", "routine", "SteeringAngleSensorZero") == [
        "SBW: routine 0x0201 SteeringAngleSensorZero done"]
    assert ok(capsys, "ABS", "routine", "0x0202") == ["ABS: routine 0x0202 ValveAndPumpTest done"]


def test_clear(capsys: pytest.CaptureFixture[str]) -> None:
    assert ok(capsys, "VCU", "clear") == ["VCU: cleared DTC group 0xFFFFFF"]
    assert ok(capsys, "VCU", "clear", "C1C05-87") == ["VCU: cleared DTC group 0x5C0587"]
    assert ok(capsys, "VCU", "clear", "REQUEST_TIMEOUT") == ["VCU: cleared DTC group 0x5C0587"]


def test_snapshot(capsys: pytest.CaptureFixture[str]) -> None:
    """The VCU's record of its request timeout: its 12 snapshot DIDs in the declared order, taken at the first
    failed result after the start-up time (DIAG-OPC-01: 100 ms)."""
    for key in ("C1C05-87", "REQUEST_TIMEOUT", "0x5C0587"):
        lines = ok(capsys, "VCU", "snapshot", key)
        assert lines[0] == ("VCU: C1C05-87 status 0x27 testFailed testFailedThisOperationCycle pendingDTC "
                            "testFailedSinceLastClear")
        names = [line.split()[3] for line in lines[1:]]
        assert names == ["OperatingTime", "VehicleSpeed", "RequestedDriveMode", "TargetSpeed", "PivotX", "PivotY",
                         "HandWheelAngle", "WheelFaultFL", "WheelFaultFR", "WheelFaultRL", "WheelFaultRR",
                         "WheelStatusTimedOut"]
        assert all(line.startswith("  record 0x01 0x") for line in lines[1:])
        match = re.fullmatch(r"  record 0x01 0xDD00 OperatingTime = ([0-9.]+) s", lines[1])
        assert match and 0.1 <= float(match[1]) <= 0.12, lines[1]
    # a DTC never failed since the last clear has no record (DIAG-DTC-05): its status line only
    assert ok(capsys, "VCU", "snapshot", "CENTRE_AT_ORIGIN") == ["VCU: C1C01-64 status 0x00 (no bit set)"]


# -- bad input: one line, exit 2 --------------------------------------------------------------------------------
@pytest.mark.parametrize(("argv", "says"), [
    (["NOPE", "dtc"], "node 'NOPE' has no diagnostics (nodes with diagnostics: VCU, WHL_FL"),
    (["DRIVER", "dtc"], "node 'DRIVER' has no diagnostics"),
    (["SBW", "read", "0x1234"], "SBW: no DID 0x1234 (DIDs: 0xF187 SparePartNumber"),
    (["SBW", "read", "0xF187", "Nope"], "SBW: no DID 'Nope'"),
    (["SBW", "write", "Nope", "1"], "SBW: no DID 'Nope'"),
    (["SBW", "routine", "0x9999"], "SBW: no routine 0x9999 (routines: 0x0201 SteeringAngleSensorZero)"),
    (["SBW", "routine", "Nope"], "SBW: no routine 'Nope'"),
    (["SBW", "snapshot", "C1C05-87"], "SBW: no DTC 0x5C0587 (DTCs: C1A01-1C HANDWHEEL_RANGE"),   # the VCU's
    (["SBW", "snapshot", "nonsense"], "DTC 'nonsense': not a number"),
    (["SBW", "clear", "C1A99-99"], "SBW: no DTC 0x5A9999"),
    (["SBW", "write", "SteeringMode", "FOO"], "SteeringMode: 'FOO' is not a number or one of DIRECT, YAW_RATE"),
    (["SBW", "write", "SteeringMode", "1.5"], "SteeringMode: '1.5' is none of DIRECT"),   # it wrote 2 before
    (["SBW", "write", "SteeringMode", "-1"], "SteeringMode: -1.0 does not fit its uint8"),   # a traceback before
    (["SBW", "write", "IdealYawGain", "1e9"], "IdealYawGain: 1000000000.0 does not fit its uint16"),
    (["SBW", "write", "IdealYawGain", "nan"], "IdealYawGain: nan is not a finite number"),
    (["SBW", "write", "SteeringMode"], "bench diag SBW write: 1 argument(s), expected 2"),
    (["SBW", "write", "SteeringMode", "1", "2"], "bench diag SBW write: 3 argument(s), expected 2"),
    (["SBW", "dtc", "extra"], "bench diag SBW dtc: 1 argument(s), expected 0"),
    (["SBW", "read"], "bench diag SBW read: 0 argument(s), expected 1 to 99"),
    (["SBW", "routine"], "bench diag SBW routine: 0 argument(s), expected 1"),
    (["SBW", "snapshot"], "bench diag SBW snapshot: 0 argument(s), expected 1"),
    (["SBW", "clear", "C1A01-1C", "C1A02-2A"], "bench diag SBW clear: 2 argument(s), expected 0 to 1"),
    (["SBW", "dtc", "--mask", "nonsense"], "--mask 'nonsense': not a number"),
    (["SBW", "dtc", "--mask", "0x100"], "--mask '0x100': a status mask is one byte"),   # a traceback before
    (["SBW", "dtc", "--fault", "nonsense"], "--fault 'nonsense': expected KIND:TARGET"),
    (["SBW", "dtc", "--fault", "drop:VCU_WheelCmd_FL@case+1-"], "case+ counts from each case's start"),
    (["SBW", "dtc", "--fault", "drop:DRV_MotionRequest@0-"], "DRV_MotionRequest is sent by DRIVER"),
])
def test_bad_input(capsys: pytest.CaptureFixture[str], argv: list[str], says: str) -> None:
    line = refused(capsys, *argv)
    assert says in line, line


@pytest.mark.parametrize(("argv", "nrc"), [
    (["SBW", "write", "SteeringMode", "7"], "RequestOutOfRange (NRC 0x31)"),     # none of its values
    (["SBW", "write", "IdealYawGain", "0.9"], "RequestOutOfRange (NRC 0x31)"),   # max 0.5
    (["SBW", "write", "0xF190", "X"], "RequestOutOfRange (NRC 0x31)"),           # identification: read only
    (["SBW", "write", "VehicleSpeed", "3"], "RequestOutOfRange (NRC 0x31)"),     # a live value, no coding
])
def test_a_value_the_node_refuses_names_its_nrc(capsys: pytest.CaptureFixture[str], argv: list[str],
                                                nrc: str) -> None:
    assert refused(capsys, *argv) == f"SBW refused: {nrc}"


def test_the_nrc_line_is_the_only_line_in_a_terminal() -> None:
    """Outside pytest (whose log capture hides it) udsoncan's logger printed '[NegativeResponseException] : ...'
    on stderr as well, through Python's last-resort handler: two lines."""
    result = subprocess.run([sys.executable, "-m", "bench", "diag", "SBW", "write", "SteeringMode", "7", "--config",
                             str(CONFIG)], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert result.returncode == 2 and result.stdout == ""
    assert result.stderr.splitlines() == [f"{ERROR}SBW refused: RequestOutOfRange (NRC 0x31)"], result.stderr


# -- the project's [diagnostics] ------------------------------------------------------------------------------------
def project(tmp_path: Path, diagnostics: str | None, declaration: str | None = None) -> Path:
    """A copy of this project's bench.toml (its [diagnostics] table replaced by `diagnostics`, or none) beside a copy
    of dbc/ (dbc/diagnostics.toml replaced by `declaration`) and of the contract documents."""
    text = CONFIG.read_text(encoding="utf-8")
    head = text[:text.index("[diagnostics]")]
    config = tmp_path / "bench.toml"
    config.write_text(head + (diagnostics or ""), encoding="utf-8")
    (tmp_path / "dbc").mkdir()
    for file in (ROOT / "dbc").iterdir():
        if file.is_file():
            (tmp_path / "dbc" / file.name).write_bytes(file.read_bytes())
    if declaration is not None:
        (tmp_path / "dbc" / "diagnostics.toml").write_text(declaration, encoding="utf-8")
    (tmp_path / "docs" / "contract").mkdir(parents=True)
    for file in (ROOT / "docs" / "contract").glob("*.md"):
        (tmp_path / "docs" / "contract" / file.name).write_bytes(file.read_bytes())
    return config


def test_the_copy_works(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    config = project(tmp_path, '[diagnostics]\nfile = "dbc/diagnostics.toml"\n')
    code, out, err = diag(capsys, "VCU", "read", "0xF187", config=config)
    assert code == 0 and out == "VCU: 0xF187 SparePartNumber = VCU-000001\n", err


def test_a_project_without_diagnostics(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    line = refused(capsys, "SBW", "dtc", config=project(tmp_path, None))
    assert line == f"{tmp_path / 'bench.toml'}: no [diagnostics] file: the bench knows no node's diagnostics"


def test_a_diagnostics_file_that_does_not_exist(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    line = refused(capsys, "SBW", "dtc", config=project(tmp_path, '[diagnostics]\nfile = "dbc/nowhere.toml"\n'))
    assert line == f"{tmp_path / 'bench.toml'}: [diagnostics] file: no such file {tmp_path / 'dbc' / 'nowhere.toml'}"


@pytest.mark.parametrize(("old", "new", "says"), [
    ("p2_ms = 50 ", 'p2_ms = "x"', "[protocol] p2_ms: 'x' is not a number"),
    ("request = 0x705", 'request = "SBW"', "[nodes.SBW] request:"),
    ("confirm_ms = 500", "confirm_ms = -1", "confirm_ms"),
])
def test_a_broken_key_is_named(tmp_path: Path, capsys: pytest.CaptureFixture[str], old: str, new: str,
                               says: str) -> None:
    text = (ROOT / "dbc" / "diagnostics.toml").read_text(encoding="utf-8")
    assert old in text
    config = project(tmp_path, '[diagnostics]\nfile = "dbc/diagnostics.toml"\n', text.replace(old, new, 1))
    line = refused(capsys, "SBW", "dtc", config=config)
    assert line.startswith(f"{tmp_path / 'dbc' / 'diagnostics.toml'}: ") and says in line, line


# -- on a real bus ---------------------------------------------------------------------------------------------------
@pytest.mark.realtime
def test_a_silent_bus(capsys: pytest.CaptureFixture[str]) -> None:
    """No node on the group: the tester's P2 wait (50 ms + 50 ms) ends, one line, within a few seconds."""
    begun = time.monotonic()
    line = refused(capsys, "SBW", "dtc", "--interface", "udp_multicast", "--channel", "239.255.3.99", "--external",
                   "all")
    took = time.monotonic() - begun
    assert line.startswith("SBW (request 0x705, response 0x70D) did not answer: "), line
    assert took < 3.0, took


@contextmanager
def plant(group: str) -> Iterator[Child]:
    child = Child([sys.executable, "-m", "bench", "plant", "--interface", "udp_multicast", "--channel", group], ROOT)
    try:
        child.wait_for("simulating", 20)
        yield child
    finally:
        output = child.stop()
    assert child.returncode == 0, output


@pytest.mark.realtime
def test_write_then_read_on_the_plant(capsys: pytest.CaptureFixture[str]) -> None:
    """`bench plant`'s SBW keeps its coding between two `bench diag` calls (DIAG-COD-01)."""
    group = ipv4_group()
    bus = ["--interface", "udp_multicast", "--channel", group, "--external", "all"]
    with plant(group):
        [before] = ok(capsys, "SBW", "read", "SteeringMode", *bus)
        assert ok(capsys, "SBW", "write", "SteeringMode", "YAW_RATE", *bus) == [
            "SBW: wrote 0xFDC0 SteeringMode = YAW_RATE"]
        [after] = ok(capsys, "SBW", "read", "SteeringMode", *bus)
        assert ok(capsys, "SBW", "write", "SteeringMode", "DIRECT", *bus) == [
            "SBW: wrote 0xFDC0 SteeringMode = DIRECT"]
        assert refused(capsys, "SBW", "write", "SteeringMode", "7", *bus) == "SBW refused: RequestOutOfRange (NRC 0x31)"
    assert re.fullmatch(r"SBW: 0xFDC0 SteeringMode = DIRECT \(0\)", before), before
    assert re.fullmatch(r"SBW: 0xFDC0 SteeringMode = YAW_RATE \(1\)", after), after
