"""Silent failures are logged and reported (issue 17): a warning of the bench or the plant is a `logging`
record and, during a run, a finding in the report (bench.checks.findings): frames the bus driver refused, and the
kernel's periodic sending given up."""

from __future__ import annotations

import logging
import xml.etree.ElementTree as ET
from collections.abc import Callable
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import can
import pytest

from bench.checks.findings import MAX_FINDINGS, FindingCollector
from bench.config import RunSettings, load_config
from bench.database.codec import load_codebook
from bench.results.model import Finding, RunResult
from bench.results.store import dump, load, merge
from bench.run import BenchRun
from bench.sim.restbus import Restbus
from bench.transport import VirtualTimeBus, periodic


def test_collector_keeps_warnings_of_the_bench_and_the_plant() -> None:
    clock = iter([1.5, 2.5, 3.5])
    collector = FindingCollector(lambda: next(clock)).attach()
    try:
        logging.getLogger("bench.sim.station").warning("frame %s refused", "0x100")
        logging.getLogger("bench.sim.station").warning("frame %s refused", "0x100")    # the same: counted
        logging.getLogger("plant.body").error("model diverged")
        logging.getLogger("bench.sim.station").info("not a finding")
        logging.getLogger("somebody.else").warning("not ours")
    finally:
        findings = collector.detach()
    logging.getLogger("bench.sim.station").warning("after the run: not collected")
    assert [(f.source, f.level, f.message, f.time, f.count) for f in findings] == [
        ("bench.sim.station", "warning", "frame 0x100 refused", 1.5, 2),
        ("plant.body", "error", "model diverged", 2.5, 1)]


def test_collector_is_bounded() -> None:
    collector = FindingCollector().attach()
    try:
        for i in range(MAX_FINDINGS + 50):
            logging.getLogger("bench.x").warning("distinct %d", i)
    finally:
        findings = collector.detach()
    assert len(findings) == MAX_FINDINGS
    assert sum(f.count for f in findings) == MAX_FINDINGS + 50 and findings[-1].count == 51


def test_refused_frames_are_a_warning_and_a_finding(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                     caplog: pytest.LogCaptureFixture) -> None:
    """A station whose driver refuses frames (every frame of one message, as a full transmit queue would): one
    warning at the first, the count at the end, both in the report (HTML, JUnit property, results.json)."""
    refused_id = load_codebook(load_config().databases)["DRV_Steering"].frame_id
    refused: list[float] = []

    def refusing(original: Callable[..., None]) -> Callable[..., None]:
        def send(self: VirtualTimeBus, *args: Any, **kwargs: Any) -> None:
            frame_id = args[0].arbitration_id if isinstance(args[0], can.Message) else args[1]
            if frame_id == refused_id:
                refused.append(frame_id)
                raise can.CanOperationError("transmit buffer full")
            original(self, *args, **kwargs)
        return send

    # both ways a station may send on the virtual bus, patched before the stations take them
    monkeypatch.setattr(VirtualTimeBus, "send", refusing(VirtualTimeBus.send))
    if hasattr(VirtualTimeBus, "send_raw"):
        monkeypatch.setattr(VirtualTimeBus, "send_raw", refusing(VirtualTimeBus.send_raw))
    run = BenchRun(load_config(), RunSettings(), tmp_path)
    with caplog.at_level(logging.WARNING, logger="bench"):
        try:
            run.start()
            assert run.session is not None and run.session.runner is not None
            run.session.run_until(0.2)
        finally:
            result = run.finish()
    assert run.session.runner is not None
    assert len(refused) >= 10                                # DRV_Steering every 10 ms for 0.2 s
    assert run.session.runner.send_errors == len(refused)
    warnings = [r for r in caplog.records if r.name == "bench.sim.station" and r.levelno == logging.WARNING]
    assert len(warnings) == 1 and f"0x{refused_id:03X}" in warnings[0].getMessage()
    texts = [f.message for f in result.findings]
    assert any("refused a frame" in t and f"0x{refused_id:03X}" in t for t in texts), texts
    assert any(f"{len(refused)} frames could not be sent" in t for t in texts), texts
    html = (tmp_path / "report.html").read_text(encoding="utf-8")
    assert 'id="findings"' in html and f"{len(refused)} frames could not be sent" in html
    props = [p.get("value") for p in ET.parse(tmp_path / "junit.xml").getroot().iter("property")
             if p.get("name") == "finding"]
    assert any("could not be sent" in (v or "") for v in props)
    assert load(tmp_path / "results.json").findings == result.findings   # the report folder's record


def test_a_clean_run_has_no_finding(tmp_path: Path) -> None:
    run = BenchRun(load_config(), RunSettings(), tmp_path)
    run.start()
    try:
        assert run.session is not None
        run.session.run_until(0.05)
    finally:
        result = run.finish()
    assert result.findings == []
    assert 'id="findings"' not in (tmp_path / "report.html").read_text(encoding="utf-8")


def test_findings_of_workers_merge(tmp_path: Path) -> None:
    """pytest-xdist parts: the same warning in two workers is one finding with the counts summed."""
    parts = []
    for worker, count in (("gw0", 2), ("gw1", 3)):
        part = RunResult(started="2026-01-01T00:00:00", interface="embedded", channel="", time_mode="virtual",
                         findings=[Finding("bench.sim.station", "warning", "x", 0.5, count)])
        dump(part, tmp_path / f"{worker}.json")
        parts.append((worker, load(tmp_path / f"{worker}.json")))
    merged = merge(parts, 1.0)
    assert [(f.message, f.count) for f in merged.findings] == [("x", 5)]


def test_kernel_periodic_fallback_is_a_warning(codebook: object, monkeypatch: pytest.MonkeyPatch,
                                               caplog: pytest.LogCaptureFixture) -> None:
    """A socketcan bus whose kernel refuses the broadcast manager's sockets: the restbus sends every frame
    itself (as before), and says so."""
    def refuse() -> object:
        raise OSError(97, "Address family not supported by protocol")

    monkeypatch.delenv(periodic.ENV_SWITCH, raising=False)
    monkeypatch.setattr(periodic, "plain_socketcan", lambda bus: True)
    monkeypatch.setattr(periodic, "_raw_socket", refuse)
    restbus = Restbus(codebook, ["TESTER"])   # type: ignore[arg-type]
    with caplog.at_level(logging.WARNING, logger="bench"):
        assert periodic.KernelPeriodic.attach(SimpleNamespace(channel="vcan0"), restbus) is None  # type: ignore[arg-type]
    [record] = [r for r in caplog.records if r.name == "bench.transport.periodic"]
    assert "vcan0" in record.getMessage() and "restbus sends every frame itself" in record.getMessage()


def test_kernel_periodic_given_up_is_said_once(caplog: pytest.LogCaptureFixture) -> None:
    kernel = periodic.KernelPeriodic.__new__(periodic.KernelPeriodic)   # only the state _disable touches
    kernel.enabled, kernel.error, kernel.bus = True, "", SimpleNamespace(channel="vcan0")
    with caplog.at_level(logging.WARNING, logger="bench"):
        kernel._disable("modify_data of X failed: [Errno 105] No buffer space available")
        kernel._disable("stopping the task of X failed: again")
    records = [r for r in caplog.records if r.name == "bench.transport.periodic"]
    assert len(records) == 1 and "No buffer space" in records[0].getMessage()
    assert not kernel.enabled and kernel.error.startswith("stopping")
