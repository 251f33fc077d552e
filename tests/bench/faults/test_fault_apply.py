"""FaultPlan.apply: a frame no acting fault targets comes back as it was, and no fault counts it."""

from __future__ import annotations

from bench.database.codec import Codebook
from bench.faults.plan import Fault, FaultPlan
from bench.sim.restbus import Restbus

MSG = "VCU_WheelCmd_FL"


def _frame(codebook: Codebook) -> tuple[int, bytes]:
    restbus = Restbus(codebook, ["VCU"])
    slot = restbus.slots[MSG]
    restbus.set(MSG, SteerAngleCmd=12.5)
    return slot.codec.frame_id, restbus.build(slot)


def test_apply_without_an_acting_fault_gives_the_frame_back(codebook: Codebook) -> None:
    frame_id, data = _frame(codebook)
    plan = FaultPlan(codebook)
    fault = plan.add(Fault("drop", "VCU_WheelCmd_FR", 0.0))   # another message: never acts on this one
    assert plan.apply(1.0, frame_id, data) == [(0.0, data)]
    assert fault.frames == 0
