"""Lost frames under AUTOSAR E2E: a consumer applies a frame whose counter stepped by 2 (OKSOMELOST).

docs/spec/e2e.md ("OKSOMELOST") chooses MaxDeltaCounter 2 so that one lost or corrupted frame costs only itself,
and docs/contract/common.md COM-RX-01 has a receiver apply a frame whose status is OK or OKSOMELOST while the state
machine is VALID. Here every other `DRV_MotionRequest` frame is dropped for 1 s, so that every frame the VCU
receives comes one counter step late: with the contract's receiver each is OKSOMELOST and applied, its request
arrives every 40 ms, within its 60 ms timeout (VCU-FLT-01), and VcuFault stays OK (0). A VCU that took OKSOMELOST
for an error would report REQUEST_INVALID (VCU-FLT-02) at the first of them. The bench's monitor, a receiver with
the message's own parameters, counts the statuses on the bus: one OKSOMELOST per dropped frame and nothing rejected.
Those are the bench's own part, judged as the stimulus node DRIVER's: in real time a late bench may send a window's
frame outside it, which is no fault of the VCU's.
"""

from __future__ import annotations

import statistics

import pytest

from testcases.stimulus import STIMULUS

CYCLE = 0.020          # DRV_MotionRequest's GenMsgCycleTime
LOST = 25              # frames dropped, every other one: 1 s
HALF_TICK = 0.0005     # a drop window opens half a tick before its frame: a frame is never on its edge
REACTION_S = 0.1       # s after the last dropped frame in which VcuFault must still be OK


def next_due(bench) -> float:
    """s from now to the next DRV_MotionRequest frame the bench sends, at least half a tick away: from the phase of
    its latest frames (their median, so that a late one does not move it)."""
    t, _ = bench.history("DRV_MotionRequest", "TargetSpeed", since=bench.now - 10 * CYCLE)
    assert len(t) >= 3, f"the bench sent {len(t)} DRV_MotionRequest frames in {10 * CYCLE:g} s"
    last = float(t[-1])
    offset = statistics.median((float(ti) - last + CYCLE / 2) % CYCLE - CYCLE / 2 for ti in t)
    due = last + offset + CYCLE
    while due - bench.now < HALF_TICK:
        due += CYCLE
    return due - bench.now


@pytest.mark.dut("VCU")
@pytest.mark.req("COM-RX-01", "VCU-FLT-02")
def test_every_other_request_frame_lost(bench) -> None:
    bench.start_scenario(Vehicle="EV4WIS", stimulus=STIMULUS["EV4WIS"])
    bench.set("DRV_MotionRequest", DriveMode="PIVOT", PivotX=6.0, PivotY=-1.38, TargetSpeed=1.0)
    bench.run(1.5)
    bench.received("VCU_VehicleState", "VcuFault")   # a silent VCU ends the case here, in one line
    bench.expect("no fault before the frames are lost", bench.value("VCU_VehicleState", "VcuFault"), 0)
    before = bench.e2e_statuses("DRV_MotionRequest")
    # windows of one cycle, one cycle apart, each opening half a tick before a frame is due: each holds exactly that
    # frame, and a frame must be almost a cycle late to leave its window or enter the next (in real time the bench
    # may be late by a few ms: a window a few ms after a frame, as the schedule's phase happened to put it, dropped
    # the frame before it too, once in a CI rehearsal)
    due = next_due(bench)
    faults = [bench.inject("drop", "DRV_MotionRequest", after=due - HALF_TICK + 2 * k * CYCLE, duration=CYCLE)
              for k in range(LOST)]
    t0 = bench.now
    bench.run(2 * LOST * CYCLE + REACTION_S)   # the whole pattern, whatever the VCU does (judged below)
    t, codes = bench.history("VCU_VehicleState", "VcuFault", since=t0)
    faulty = [(float(ti - t0), int(code)) for ti, code in zip(t, codes, strict=True) if code != 0]
    bench.expect_true("VcuFault stays OK (0) while every other DRV_MotionRequest frame is lost",
                      len(t) > 0 and not faulty, measured=f"{len(faulty)} of {len(t)} frames not 0" + (
                          f", the first {faulty[0][1]} at +{faulty[0][0]:.3f} s" if faulty else ""),
                      expected="0 in every VCU_VehicleState frame")
    # The bench's own part, judged as the stimulus node's (a late bench in real time may send a window's frame
    # outside it, or two in one): shown under DRIVER, it never fails the VCU, and a VCU failure beside it is
    # inconclusive
    dropped = [fault.frames for fault in faults]
    bench.expect_true("the bench dropped exactly one DRV_MotionRequest frame per window", dropped == [1] * LOST,
                      measured=" ".join(map(str, dropped)), expected=" ".join(["1"] * LOST), node="DRIVER")
    statuses = bench.e2e_statuses("DRV_MotionRequest")
    lost = statuses.get("OKSOMELOST", 0) - before.get("OKSOMELOST", 0)
    bench.expect("DRV_MotionRequest frames one counter step late (OKSOMELOST), as the monitor saw them", lost,
                 sum(n == 1 for n in dropped), detail="one per window that dropped one frame: the frame after it",
                 node="DRIVER")
    rejected = {name: n - before.get(name, 0) for name, n in statuses.items()
                if name not in ("OK", "OKSOMELOST") and n > before.get(name, 0)}
    bench.expect_true("no DRV_MotionRequest frame with another status than OK or OKSOMELOST", not rejected,
                      measured=", ".join(f"{name} {n}" for name, n in rejected.items()) or "none", expected="none",
                      node="DRIVER")
    speeds = [bench.value(f"VCU_WheelCmd_{w}", "WheelSpeedCmd") for w in ("FL", "FR", "RL", "RR")]
    bench.expect_true("the VCU still commands the pivot's wheel speeds", all(s != 0.0 for s in speeds),
                      measured=", ".join(f"{s:g}" for s in speeds), expected="none 0 rpm")
