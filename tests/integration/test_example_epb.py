"""The example project without a plant (examples/epb, README "A network without a plant"): `bench run` on the
embedded bus plays the park brake from its database and skips the cases that judge it, saying why; with the example
ECU on UDP multicast every case runs and passes. Its run log holds CAN FD frames with their flags, 29-bit frames and
the multiplexed pages, read back by python-can (not by the bench's reader) and checked against the database with
cantools and autosar-e2e; `bench replay`'s loop puts them back on a bus unchanged.

Expected values come from examples/epb/epb.dbc as cantools reads it and from the profiles' own checks, never from
the bench's codec."""

from __future__ import annotations

import os
import random
import shutil
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import can
import cantools
import pytest
from e2e import p05, p07

from tests.external_ecu import third_party_imports
from tests.fakes import ipv4_group
from tests.repo import ROOT

EXAMPLE = ROOT / "examples" / "epb"
ECU = EXAMPLE / "epb_ecu.py"
#: cases of examples/epb/cases: those that judge the EPB (dut) and those that need none (the bus, the restbus)
EPB_CASES, OTHER_CASES = 7, 2


def _project(tmp_path: Path) -> Path:
    """A copy of the example (its reports stay out of the repository)."""
    project = tmp_path / "epb"
    shutil.copytree(EXAMPLE, project, ignore=shutil.ignore_patterns("reports", "__pycache__"))
    return project


def _bench_run(project: Path, *args: str, timeout: float) -> tuple[subprocess.CompletedProcess[str], Path]:
    out = project / "reports" / "run"
    result = subprocess.run([sys.executable, "-m", "bench", "run", "--out", str(out), *args], cwd=project,
                            capture_output=True, text=True, timeout=timeout, env={**os.environ, "COLUMNS": "200"})
    return result, out


def _verdicts(junit: Path) -> dict[str, tuple[str, str]]:
    """case name -> (passed/failed/skipped, skip message)."""
    out = {}
    for case in ET.parse(junit).getroot().iter("testcase"):
        skipped = case.find("skipped")
        failed = case.find("failure") is not None or case.find("error") is not None
        out[case.get("name", "")] = ("failed" if failed else "skipped" if skipped is not None else "passed",
                                     "" if skipped is None else skipped.get("message", ""))
    return out


@pytest.fixture(scope="module")
def embedded(tmp_path_factory: pytest.TempPathFactory) -> tuple[subprocess.CompletedProcess[str], Path]:
    return _bench_run(_project(tmp_path_factory.mktemp("epb")), timeout=300)


def test_on_the_embedded_bus_the_cases_of_the_absent_epb_are_skipped(
        embedded: tuple[subprocess.CompletedProcess[str], Path]) -> None:
    result, out = embedded
    assert result.returncode == 0, result.stdout[-2000:] + result.stderr[-2000:]
    verdicts = _verdicts(out / "junit.xml")
    skipped = {name: why for name, (outcome, why) in verdicts.items() if outcome == "skipped"}
    assert len(skipped) == EPB_CASES and all("--external EPB" in why for why in skipped.values()), skipped
    assert sum(outcome == "passed" for outcome, _ in verdicts.values()) == OTHER_CASES, verdicts
    # no reference ECU plays the absent EPB: the report says what does
    heading = (out / "report.html").read_text().split('id="node-EPB"', 1)[1].split("</h2>", 1)[0]
    assert "start values: the project has no plant" in heading and "reference ECU" not in heading, heading


def test_the_log_holds_fd_29_bit_and_multiplexed_frames_as_the_database_declares(
        embedded: tuple[subprocess.CompletedProcess[str], Path]) -> None:
    _, out = embedded
    db = cantools.database.load_file(EXAMPLE / "epb.dbc")
    frames = list(can.LogReader(out / "run.mcap"))        # python-can's reader (the bench registers the format)
    by_name: dict[str, list[can.Message]] = {}
    for frame in frames:
        try:
            message = db.get_message_by_frame_id(frame.arbitration_id)
        except KeyError:
            continue
        if frame.is_extended_id == message.is_extended_frame:
            by_name.setdefault(message.name, []).append(frame)
    for message in db.messages:
        got = by_name.get(message.name, [])
        if message.name in ("HIL_ParkSwitch", "EPB_Event"):   # on change: nothing changes them in this run
            continue
        assert got, message.name
        assert {(f.is_fd, f.bitrate_switch, len(f.data)) for f in got} == {
            (message.is_fd, message.is_fd, message.length)}, message.name
    status = by_name["EPB_Status"]
    assert all(p07.e2e_p07_check(bytearray(f.data), 0x0EB00200) for f in status)
    counters = [int.from_bytes(f.data[12:16], "big") for f in status]
    assert counters == list(range(counters[0], counters[0] + len(counters)))
    assert all(p05.e2e_p05_check(bytearray(f.data), 0x1100) for f in by_name["HIL_VehicleState"])
    pages = [db.decode_message("EPB_Info", bytes(f.data))["InfoPage"] for f in by_name["EPB_Info"]]
    assert pages[:6] == [0, 1, 2, 0, 1, 2]
    odometer = db.decode_message("GW_Odometer", bytes(by_name["GW_Odometer"][0].data))
    assert odometer["TotalDistance"] == pytest.approx(12000.0)
    service = [db.decode_message("HIL_Service", bytes(f.data), decode_choices=False)["ServiceMode"]
               for f in by_name["HIL_Service"]]
    assert 9 <= service.count(1) <= 11 and service.count(0) == 1 and service[-1] == 0


def test_replay_puts_the_logged_frames_back_unchanged(embedded: tuple[subprocess.CompletedProcess[str], Path]) -> None:
    from bench.cli.replay import Counts, play
    from bench.log.canio import log_reader

    _, out = embedded
    logged = [(m.arbitration_id, m.is_extended_id, m.is_fd, m.bitrate_switch, bytes(m.data))
              for m in can.LogReader(out / "run.mcap") if not m.is_error_frame]
    channel = f"replay-epb-{random.randrange(1 << 30)}"
    with can.Bus(interface="virtual", channel=channel, receive_own_messages=False) as sender, \
            can.Bus(interface="virtual", channel=channel) as receiver:
        counts = Counts()
        reader = log_reader(out / "run.mcap")
        try:
            play(reader, sender, 1000.0, "all", counts)
        finally:
            reader.stop()
        got = []
        while (message := receiver.recv(0.5)) is not None:
            got.append((message.arbitration_id, message.is_extended_id, message.is_fd, message.bitrate_switch,
                        bytes(message.data)))
    assert counts.sent == len(logged) > 0 and counts.failed == 0
    assert got == logged


def test_the_example_ecu_needs_nothing_of_the_bench() -> None:
    assert third_party_imports(ECU) == {"can", "cantools", "e2e"}


@pytest.mark.realtime
def test_every_case_passes_against_the_example_ecu_on_udp_multicast(tmp_path: Path) -> None:
    project = _project(tmp_path)
    channel = ipv4_group()
    log = (tmp_path / "ecu.log").open("w")
    ecu = subprocess.Popen([sys.executable, str(ECU), "--interface", "udp_multicast", "--channel", channel],
                           stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
    try:
        time.sleep(1.0)
        assert ecu.poll() is None, (tmp_path / "ecu.log").read_text()
        result, out = _bench_run(project, "--interface", "udp_multicast", "--channel", channel, "--external", "EPB",
                                 timeout=300)
    finally:
        ecu.terminate()
        ecu.wait(10)
        log.close()
    assert result.returncode == 0, result.stdout[-3000:] + (tmp_path / "ecu.log").read_text()[-1000:]
    verdicts = _verdicts(out / "junit.xml")
    assert sorted(outcome for outcome, _ in verdicts.values()) == ["passed"] * (EPB_CASES + OTHER_CASES)
