"""FaultPlan.expire: a fault whose window ended stops costing every frame, and stays on the record."""

from __future__ import annotations

from bench.codec import Codebook
from bench.faults import CASE, Fault, FaultPlan
from bench.restbus import Restbus

MSG = "VCU_WheelCmd_FL"


def _frame(codebook: Codebook) -> tuple[int, bytes]:
    restbus = Restbus(codebook, ["VCU"])
    slot = restbus.periodic[MSG]
    restbus.set(MSG, SteerAngleCmd=12.5)
    return slot.codec.frame_id, restbus.build(slot)


def test_a_case_start_forgets_ended_windows_and_keeps_later_ones(codebook: Codebook) -> None:
    plan = FaultPlan(codebook)
    ended = plan.add(Fault("drop", MSG, 1.0, 2.0))
    later = plan.add(Fault("drop", MSG, 5.0, 6.0))
    plan.begin_case(2.0)                  # the first window ended at 2.0 (active is start <= t < end)
    assert plan.faults == [later]
    assert plan.history == [ended, later]
    assert plan.any
    plan.begin_case(6.0)
    assert plan.faults == [] and not plan.any
    assert [r.spec for r in plan.records()] == [ended.describe(), later.describe()]


def test_an_open_window_stays(codebook: Codebook) -> None:
    plan = FaultPlan(codebook)
    forever = plan.add(Fault("drop", MSG, 1.0))
    plan.begin_case(1000.0)
    assert plan.faults == [forever]


def test_case_templates_keep_the_plan_busy(codebook: Codebook) -> None:
    plan = FaultPlan(codebook)
    plan.add(Fault("drop", MSG, 0.5, 1.0, relative=CASE))
    plan.begin_case(10.0)
    plan.begin_case(20.0)                 # the first case's instance is gone, the second's is there
    assert [(f.start, f.end) for f in plan.faults] == [(20.5, 21.0)]


def test_apply_without_an_acting_fault_gives_the_frame_back(codebook: Codebook) -> None:
    frame_id, data = _frame(codebook)
    plan = FaultPlan(codebook)
    fault = plan.add(Fault("drop", "VCU_WheelCmd_FR", 0.0))   # another message: never acts on this one
    assert plan.apply(1.0, frame_id, data) == [(0.0, data)]
    assert fault.frames == 0
