"""4WIS EV: the VCU uses only the values of valid frames (docs/contract/vcu.md VCU-REQ-02).

A valid PIVOT request about S0 is executed first. Then every DRV_MotionRequest frame is corrupted (bench.inject
checksum_offset: a wrong CRC, E2E status ERROR, docs/spec/e2e.md) and, while it is, the request changes to another
centre S1. The corrupted frames carry S1, but they are invalid: no VCU_WheelCmd_xx frame may show S1's angles or
speeds while the fault lasts (the angles stay those of S0, the speeds are S0's until the VCU has seen the first
invalid frame and 0 from then on, VCU-FLT-08). Once the frames are valid again, S1 is executed (VCU-FLT-10).

The existing fault cases corrupt frames that carry the request already executed, so they cannot tell a VCU that
uses an invalid frame's values from one that does not; this case can.

The DTC side (testcases/fault_memory.py): the VCU's fault memory is cleared before the fault; after it, the DTC of
each fault code the VCU showed meanwhile (REQUEST_INVALID, REQUEST_TIMEOUT) is judged as every fault case judges
it: testFailed clear, the failure remembered, confirmed only if it lasted its confirmation time, one occurrence
per run of the code on the bus, a snapshot consistent with the bus.
"""

from __future__ import annotations

import pytest

from testcases.ev4wis import oracle
from testcases.ev4wis.oracle import WHEELS
from testcases.ev4wis.plots import plot_vcu_state, plot_wheels
from testcases.ev4wis.steps import (
    ANGLE_TOL,
    FAULT_VALUE,
    SPEED_ABS_TOL,
    VCU_AND_WHEELS,
    expect_fault,
    limit,
    send_pivot,
    start,
    wait_for_targets,
)
from testcases.fault_memory import FaultMemory

S0, V0 = (3.0, 2.0), 1.0           # the valid request before the fault
S1, V1 = (-2.0, 0.0), 1.0          # the request the corrupted frames carry: every angle and speed differs from S0's
FAULT_S = 0.5                      # s of corrupted DRV_MotionRequest frames
CHANGE_AFTER_S = 0.05              # s into the fault at which the request changes to S1
FAULT_WITHIN_S = limit("fault_within")

pytestmark = [pytest.mark.dut(*VCU_AND_WHEELS)]


@pytest.mark.req("VCU-REQ-02", "VCU-FLT-02", "VCU-FLT-08", "VCU-FLT-10", "COM-RX-01", "VCU-MODE-02")
def test_invalid_frames_carry_no_request(bench) -> None:
    start(bench)
    send_pivot(bench, *S0, V0)
    wait_for_targets(bench, oracle.rotation_targets(*S0, V0))
    held = {w: bench.value(f"VCU_WheelCmd_{w}", "SteerAngleCmd") for w in WHEELS}
    old_rpm = {w: bench.value(f"VCU_WheelCmd_{w}", "WheelSpeedCmd") for w in WHEELS}
    new = oracle.rotation_targets(*S1, V1)
    for w in WHEELS:   # the case can only tell S1 from S0 where their commands differ
        assert abs(new[w].angle - held[w]) > 10 * ANGLE_TOL and abs(new[w].rpm - old_rpm[w]) > 10 * SPEED_ABS_TOL

    memory = FaultMemory(bench, "VCU")
    fault = bench.inject("checksum_offset", "DRV_MotionRequest", param=1, duration=FAULT_S)
    bench.note(f"injected fault {fault.describe()} (bench time); request changed to S1 = {S1} m, {V1} m/s "
               f"{CHANGE_AFTER_S} s into it")
    bench.run(CHANGE_AFTER_S)
    send_pivot(bench, *S1, V1)

    def nothing_of_s1() -> bool:
        return all(abs(bench.value(f"VCU_WheelCmd_{w}", "SteerAngleCmd") - held[w]) <= ANGLE_TOL
                   and bench.value(f"VCU_WheelCmd_{w}", "WheelSpeedCmd") in (0.0, old_rpm[w]) for w in WHEELS)

    bench.always("while the frames are invalid: the angles stay S0's, the speeds S0's or 0, never S1's",
                 nothing_of_s1, fault.end - bench.now)
    bench.expect_true("the VCU reported the invalid request (VcuFault REQUEST_INVALID or REQUEST_TIMEOUT)",
                      bench.value("VCU_VehicleState", "VcuFault") in (FAULT_VALUE["REQUEST_INVALID"],
                                                                      FAULT_VALUE["REQUEST_TIMEOUT"]),
                      measured=bench.value("VCU_VehicleState", "VcuFault"), expected="4 or 5")
    bench.wait_until(lambda: bench.now >= fault.end, 1.0)
    wait_for_targets(bench, new)
    expect_fault(bench, "OK")
    invalid = bench.invalid_log()
    others = [f for f in invalid if f.message != "DRV_MotionRequest"]
    bench.expect_true("invalid frames on the bus: only the injected DRV_MotionRequest ones", not others,
                      measured=f"{len(invalid) - len(others)} injected, {len(others)} other", expected="0 other",
                      detail="; ".join(f"{f.message}: {f.reason}" for f in others[:5]))
    shown = {int(v) for v in bench.history("VCU_VehicleState", "VcuFault", since=fault.start)[1]}
    for name in ("REQUEST_INVALID", "REQUEST_TIMEOUT"):
        if FAULT_VALUE[name] in shown:
            memory.after(name, fault.start)
    plot_wheels(bench)
    plot_vcu_state(bench)
