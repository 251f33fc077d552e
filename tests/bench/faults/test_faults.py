"""Fault injection: each kind changes the frames as specified, and the monitor notices it; the kinds are one
registry (bench/faults/kinds.py) from which the checks, the --fault help and docs/reliability.md's table come."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from bench import canid
from bench.cli import main
from bench.database.codec import Codebook, load_codebook
from bench.errors import ConfigError
from bench.faults import kinds as fault_kinds
from bench.faults.kinds import FaultKind, Outgoing
from bench.faults.plan import KINDS, Fault, FaultPlan, parse_fault, validate
from bench.sim.restbus import Restbus
from tests import repo
from tests.reference import COUNTER_VALUES, contract_checksum

MSG = "VCU_WheelCmd_FL"
ROOT = repo.ROOT


def _frame(codebook: Codebook, counter: int = 5) -> tuple[int, bytes]:
    restbus = Restbus(codebook, ["VCU"])
    slot = restbus.slots[MSG]
    slot.counter = counter
    restbus.set(MSG, SteerAngleCmd=12.5)
    return slot.codec.frame_id, restbus.build(slot)


def _apply(codebook: Codebook, fault: Fault, t: float = 1.0) -> list[tuple[float, bytes]]:
    plan = FaultPlan(codebook)
    plan.add(fault)
    frame_id, data = _frame(codebook)
    return plan.apply(t, frame_id, data)


def test_parse_round_trip_and_errors() -> None:
    fault = parse_fault("checksum_offset:IMU_Motion:1@2-4")
    assert (fault.kind, fault.target, fault.param, fault.start, fault.end) == ("checksum_offset", "IMU_Motion", 1, 2, 4)
    assert parse_fault("silence:WHL_FR@1.5-").end == math.inf
    for bad in ("nope:X@1", "drop:VCU_WheelCmd_FL", "drop:VCU_WheelCmd_FL@3-2", "drop:X:a@1"):
        with pytest.raises(ConfigError, match="--fault"):
            parse_fault(bad)


def test_window_and_target(codebook: Codebook) -> None:
    frame_id, data = _frame(codebook)
    plan = FaultPlan(codebook)
    plan.add(Fault("drop", MSG, 1.0, 2.0))
    assert plan.apply(0.99, frame_id, data) == [(0.0, data)]
    assert plan.apply(1.0, frame_id, data) == []
    assert plan.apply(2.0, frame_id, data) == [(0.0, data)]
    other = codebook["VCU_WheelCmd_FR"].frame_id
    assert plan.apply(1.5, other, data) == [(0.0, data)]


def test_a_plan_takes_only_faults_on_frames_its_stations_send(codebook: Codebook) -> None:
    """A fault acts on frames the bench sends; on an external node's it would act on nothing, silently."""
    plan = FaultPlan(codebook, simulated=frozenset({"DRIVER", "WHL_FL"}))
    plan.add(Fault("drop", "DRV_Steering", 1.0, 2.0))                 # DRIVER's
    plan.add(Fault("silence", "WHL_FL", 1.0, 2.0))
    plan.add(Fault("flood", "0x000", 1.0, 2.0, 1.0))                  # the bench's own frames: always its to send
    with pytest.raises(ConfigError, match=r"drop:VCU_WheelCmd_FL.*sent by VCU, which the bench does not simulate"):
        plan.add(Fault("drop", MSG, 1.0, 2.0))
    with pytest.raises(ConfigError, match=r"silence:VCU.*VCU is a node the bench does not simulate"):
        plan.add(Fault("silence", "VCU", 1.0, 2.0))
    assert [f.target for f in plan.history] == ["DRV_Steering", "WHL_FL", "0x000"]


def test_each_frame_fault(codebook: Codebook) -> None:
    frame_id, data = _frame(codebook)
    assert _apply(codebook, Fault("delay", MSG, 0, 9, 0.05)) == [(0.05, data)]
    assert _apply(codebook, Fault("duplicate", MSG, 0, 9)) == [(0.0, data), (0.0, data)]
    (_, flipped), = _apply(codebook, Fault("bitflip", MSG, 0, 9, 3))
    assert flipped[0] == data[0] ^ 0x08 and flipped[1:] == data[1:]
    # the E2E kinds act on the message's Profile 11 fields: the counter in bits 56-59, the CRC in byte 6
    (_, jumped), = _apply(codebook, Fault("counter_jump", MSG, 0, 9, 3))
    assert jumped[7] & 0x0F == 8 and jumped[6] == contract_checksum(frame_id, jumped)
    assert jumped[:6] == data[:6] and jumped[7] & 0xF0 == data[7] & 0xF0
    (_, wrapped), = _apply(codebook, Fault("counter_jump", MSG, 0, 9, 12))
    assert wrapped[7] & 0x0F == (5 + 12) % COUNTER_VALUES and wrapped[6] == contract_checksum(frame_id, wrapped)
    (_, value), = _apply(codebook, Fault("checksum_value", MSG, 0, 9, 0xAB))
    assert value[6] == 0xAB and value[:6] == data[:6] and value[7] == data[7]
    (_, offset), = _apply(codebook, Fault("checksum_offset", MSG, 0, 9, 1))
    assert offset[6] == (data[6] + 1) & 0xFF and offset[7] == data[7]


def test_freezes_hold_the_value_at_the_fault_start(codebook: Codebook) -> None:
    plan = FaultPlan(codebook)
    counter_fault = plan.add(Fault("counter_freeze", MSG, 0, 9))
    restbus = Restbus(codebook, ["VCU"])
    slot = restbus.slots[MSG]
    frame_id = slot.codec.frame_id
    counters = []
    for _ in range(3):
        (_, frame), = plan.apply(1.0, frame_id, restbus.build(slot))
        counters.append(frame[7] & 0x0F)
        assert frame[6] == contract_checksum(frame_id, frame)
    assert counters == [0, 0, 0] and counter_fault.frozen == 0


def test_e2e_kinds_refuse_an_unprotected_message() -> None:
    """Counter and CRC faults act on a message's profile fields: an unprotected message (here VCU_WheelCmd_FL with
    bench.toml's [e2e] Profile = "None") has none, and the fault is refused at the door, naming why."""
    unprotected = load_codebook([repo.CHASSIS_DBC, repo.BENCH_DBC], {MSG: {"Profile": "None"}})
    assert unprotected[MSG].protection is None
    for kind in ("counter_freeze", "counter_jump", "checksum_value", "checksum_freeze", "checksum_random",
                 "checksum_offset"):
        with pytest.raises(ConfigError, match=f"{MSG} is not E2E-protected: {kind} acts on"):
            FaultPlan(unprotected).add(Fault(kind, MSG, 0, 9, 1))
    FaultPlan(unprotected).add(Fault("bitflip", MSG, 0, 9, 3))   # a frame fault of any message still applies


def test_node_and_bus_faults(codebook: Codebook) -> None:
    frame_id, data = _frame(codebook)
    assert _apply(codebook, Fault("silence", "VCU", 0, 9)) == []
    assert _apply(codebook, Fault("silence", "WHL_FL", 0, 9)) == [(0.0, data)]
    assert _apply(codebook, Fault("flood", "0x000", 0, 9, 8)) == []          # saturating: 0x110 loses
    assert _apply(codebook, Fault("flood", "0x000", 0, 9, 1)) == [(0.0, data)]  # below saturation
    plan = FaultPlan(codebook)
    plan.add(Fault("flood", "0x000", 0, 9, 8))
    plan.add(Fault("error_frame", "bus", 0, 9))
    frames = plan.babble(1.0, 0.001)
    assert frames.count((0x000, bytes(8))) == 8 and frames.count((canid.ERR, b"")) == 1 and len(frames) == 9


def test_unknown_targets_are_clear_errors(codebook: Codebook) -> None:
    plan = FaultPlan(codebook)
    with pytest.raises(Exception, match="NOPE"):
        plan.add(Fault("drop", "NOPE", 0, 1))
    with pytest.raises(ConfigError, match="unknown node"):
        plan.add(Fault("silence", "NOPE", 0, 1))
    assert set(KINDS) >= {"drop", "delay", "duplicate", "bitflip", "silence", "flood", "error_frame"}


def test_docs_table_is_the_registry() -> None:
    """docs/reliability.md's table of kinds is what the registry gives (`python -m bench.faults.kinds FILE`)."""
    text = (ROOT / "docs" / "reliability.md").read_text(encoding="utf-8")
    table = fault_kinds.documented_table(text)
    assert table is not None, "docs/reliability.md lost its generated block"
    assert table == fault_kinds.markdown_table(), "out of date: run python -m bench.faults.kinds docs/reliability.md"
    for name in KINDS:
        assert f"| `{name}` |" in table


def test_help_names_every_kind_with_its_pattern() -> None:
    text = fault_kinds.help_text()
    for name, kind in KINDS.items():
        assert f"{name}:{kind.target}" in text
    assert "delay:MESSAGE:SECONDS" in text and "flood:IDENTIFIER:RATE" in text


def test_each_kind_checks_its_own_target_and_param(codebook: Codebook) -> None:
    """Every kind rejects a target of the wrong sort, named in one line with the spec (checked per kind, so
    a new kind's check is exercised too)."""
    wrong = {fault_kinds.MESSAGE: "NoSuchMessage", fault_kinds.NODE: "NOBODY", fault_kinds.IDENTIFIER: "VCU"}
    expected = {fault_kinds.MESSAGE: "unknown message", fault_kinds.NODE: "unknown node",
                fault_kinds.IDENTIFIER: "TARGET must be an identifier"}
    for name, kind in KINDS.items():
        if kind.target in wrong:
            spec = f"{name}:{wrong[kind.target]}:1@1-2"
            [line] = validate([spec], codebook)
            assert line.startswith(f"--fault {spec!r}: ") and expected[kind.target] in line, line
    assert "a delay needs PARAM > 0 s" in validate([f"delay:{MSG}:0@1-2"], codebook)[0]
    assert "frames per ms > 0" in validate(["flood:0x000:0@1-2"], codebook)[0]
    assert validate(["error_frame:bus@1-2"], codebook) == []


class _Invert(FaultKind):
    """A kind that exists only in this test: every payload byte inverted."""

    name, summary = "invert", "every byte inverted"

    def act(self, fault: Fault, out: Outgoing) -> None:
        out.frames = [bytes(b ^ 0xFF for b in frame) for frame in out.frames]


def test_a_new_kind_is_one_class_and_one_entry(codebook: Codebook, monkeypatch: pytest.MonkeyPatch) -> None:
    """Registering a kind is all it takes: parsing, checking, applying, help and docs follow."""
    monkeypatch.setitem(fault_kinds.KINDS, "invert", _Invert())   # type: ignore[index]
    fault = parse_fault(f"invert:{MSG}@0-9")
    frame_id, data = _frame(codebook)
    assert _apply(codebook, fault) == [(0.0, bytes(b ^ 0xFF for b in data))]
    assert fault.frames == 1
    assert validate(["invert:NoSuchMessage@0-1"], codebook)[0].endswith("unknown message 'NoSuchMessage' "
                                                                         "(in none of the databases)")
    assert "invert:MESSAGE" in fault_kinds.help_text() and "| `invert` |" in fault_kinds.markdown_table()


def test_a_flood_is_bounded_by_what_the_bus_carries(codebook: Codebook, tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    """Issue 27 finding 1: `flood:0x000:1e9` was accepted and built 10^9 frames per 1 ms tick (7.9 GB, deaf to
    Ctrl-C). RATE is frames per ms, at most what a classic CAN bus at 500 kbit/s carries; the help says so."""
    assert validate([f"flood:0x000:{fault_kinds.FLOOD_MAX_RATE:g}@1-2"], codebook) == []   # the limit itself
    [line] = validate(["flood:0x000:1e9@0-1"], codebook)
    assert "frames per ms, at most 8" in line and "1e+09" in line, line
    with pytest.raises(ConfigError, match="at most 8"):
        FaultPlan(codebook).add(Fault("flood", "0x000", 0, 1, 9))          # bench.inject from a case too
    assert "flood:IDENTIFIER:RATE (RATE: frames per ms" in fault_kinds.help_text()
    assert main(["run", str(ROOT / "tests/fixtures/cases/test_mini.py"), "--out", str(tmp_path / "out"),
                 "--fault", "flood:0x000:1e9@0-1"]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err.count("\n") == 1, captured
    assert captured.err.startswith("bench run: error: --fault 'flood:0x000:1e9@0-1': RATE is frames per ms")
