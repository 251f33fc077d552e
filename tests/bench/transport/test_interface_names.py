"""One name per bus (issue 28, acceptance 4): `embedded` is the bench's own bus (in process, virtual time);
`virtual` is python-can's own VirtualBus, which a run then reaches (real time, in process); the embedded bus's
old name `bench_virtual` is refused with one line naming the new one.

Why `virtual` reaches python-can's bus rather than being refused: the bench takes any python-can interface by its
python-can name, and a user's own in-process model on python-can's virtual bus (a pytest case that opens
`can.Bus(interface="virtual", channel=...)`) can then talk to the bench's stations, as the session test shows.
"""

from __future__ import annotations

import re
import subprocess
import sys
import uuid
from pathlib import Path

import can
import pytest
from can.interfaces.virtual import VirtualBus

from bench.cli import main
from bench.config import RunSettings, load_config
from bench.errors import ConfigError
from bench.session import BenchSession
from bench.transport import EMBEDDED, VirtualTimeBus, check_interface, open_bus
from tests.repo import ROOT

MINI = ROOT / "tests" / "fixtures" / "cases" / "test_mini.py"


def test_the_embedded_bus_is_the_default_and_runs_in_virtual_time() -> None:
    settings = RunSettings()
    assert settings.interface == "embedded" and settings.virtual_time
    bus = open_bus("embedded", None)
    try:
        assert isinstance(bus, VirtualTimeBus)
    finally:
        bus.shutdown()


def test_python_can_finds_the_embedded_bus_by_its_name() -> None:
    """The entry point of pyproject.toml (group can.interface): the same name as on the command line."""
    bus = can.Bus(interface=EMBEDDED, channel=f"names-{uuid.uuid4()}")
    try:
        assert isinstance(bus, VirtualTimeBus)
    finally:
        bus.shutdown()


def test_virtual_opens_python_cans_own_bus() -> None:
    channel = f"names-{uuid.uuid4()}"
    bus = open_bus("virtual", channel)
    user = can.Bus(interface="virtual", channel=channel)   # a user's own, opened by python-can alone
    try:
        assert type(bus) is VirtualBus and not isinstance(bus, VirtualTimeBus)
        bus.send(can.Message(arbitration_id=0x123, data=b"\x01\x02", is_extended_id=False))
        got = user.recv(1.0)
        assert got is not None and (got.arbitration_id, bytes(got.data)) == (0x123, b"\x01\x02")
    finally:
        bus.shutdown()
        user.shutdown()


def test_a_session_on_virtual_is_real_time_and_reaches_a_users_python_can_bus() -> None:
    channel = f"names-{uuid.uuid4()}"
    session = BenchSession(load_config(ROOT / "bench.toml"), RunSettings(interface="virtual", channel=channel))
    user = can.Bus(interface="virtual", channel=channel)
    try:
        assert session.clock.realtime and not session.settings.virtual_time
        assert session.runner is not None and type(session.runner.bus) is VirtualBus
        session.runner.send(0.0, 0x321, b"\xAA" * 8)
        got = user.recv(1.0)
        assert got is not None and (got.arbitration_id, bytes(got.data)) == (0x321, b"\xAA" * 8)
    finally:
        session.close()
        user.shutdown()


def test_a_session_on_virtual_without_a_channel_gets_one_of_its_own() -> None:
    """As on the embedded bus: two sessions in one process never hear each other."""
    project = load_config(ROOT / "bench.toml")
    first = BenchSession(project, RunSettings(interface="virtual"))
    second = BenchSession(project, RunSettings(interface="virtual"))
    try:
        assert first.channel and second.channel and first.channel != second.channel
    finally:
        first.close()
        second.close()


@pytest.mark.parametrize("option", ["--interface", "--bench-interface"])
def test_the_old_name_is_one_line_naming_the_new_one(option: str) -> None:
    with pytest.raises(ConfigError) as info:
        check_interface("bench_virtual", option)
    assert str(info.value) == (f"{option} bench_virtual: renamed to embedded (the bench's in-process "
                               "virtual-time bus)")


def test_bench_run_refuses_the_old_name_before_any_case(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["run", str(MINI), "--interface", "bench_virtual", "--out", str(tmp_path / "out")]) == 2
    captured = capsys.readouterr()
    assert captured.err.strip() == "bench run: error: --interface bench_virtual: renamed to embedded (the bench's " \
                                   "in-process virtual-time bus)"
    assert not (tmp_path / "out" / "report.html").exists()


def test_plain_pytest_refuses_the_old_name(tmp_path: Path) -> None:
    result = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(MINI),
                             "--bench-interface", "bench_virtual", "--bench-out", str(tmp_path / "out")],
                            cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert result.returncode == 4, result.stdout + result.stderr   # pytest's usage error
    assert "--bench-interface bench_virtual: renamed to embedded" in result.stderr, result.stderr


def test_the_help_names_both_buses(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["run", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "'embedded' for the bench's own bus (in process, virtual time)" in text
    assert "virtual: python-can's in-process bus, real time" in text and "(default: embedded)" in text


@pytest.mark.realtime
def test_bench_run_on_virtual_runs_in_real_time(tmp_path: Path) -> None:
    """`bench run --interface virtual`: the cases pass on python-can's bus and the report says so."""
    result = subprocess.run([sys.executable, "-m", "bench", "run", f"{MINI}::test_normal_mode_drives_straight",
                             "--interface", "virtual", "--out", str(tmp_path / "out")],
                            cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout + result.stderr
    html = (tmp_path / "out" / "report.html").read_text(encoding="utf-8")
    facts = {name: re.sub(r"<[^>]+>", "", value).strip()
             for name, value in re.findall(r"<dt>(.*?)</dt><dd>(.*?)</dd>", html, re.S)}
    assert facts["Interface"] == "virtual" and facts["Time mode"] == "real", facts
