"""EPB-02 to EPB-07: apply, release, their refusals, the events and the service mode, judged on the EPB's frames.
Each case first brings the EPB to the state it starts from (the EPB keeps its state from case to case); the
expected numbers are contract.md's (rig.py)."""

from __future__ import annotations

import numpy as np
import pytest
from rig import (
    FORCE_KN,
    RAMP_S,
    RATE_KN_S,
    REACTION_S,
    bring_to,
    expect_events,
    in_state,
    park_state,
    service,
    switch,
    vehicle,
)

from bench.case import Case

pytestmark = pytest.mark.dut("EPB")


@pytest.mark.req("EPB-03", "EPB-05", "EPB-06")
def test_apply_at_standstill(bench: Case) -> None:
    bring_to(bench, "RELEASED")
    count_before = bench.value("EPB_Info", "ApplyCount")
    t0 = switch(bench, "APPLY")
    bench.eventually("APPLYING", in_state(bench, "APPLYING"), REACTION_S)
    bench.expect("motor current while applying", bench.value("EPB_Status", "MotorCurrentLeft"), 8.0, abs_tol=0.005,
                 unit="A")
    bench.eventually("APPLIED", in_state(bench, "APPLIED"), RAMP_S + 0.05)
    bench.expect("clamp force applied", bench.value("EPB_Status", "ClampForce"), FORCE_KN, abs_tol=0.0005, unit="kN")
    bench.expect("motor current when applied", bench.value("EPB_Status", "MotorCurrentRight"), 0.0, unit="A")
    t, force = bench.history("EPB_Status", "ClampForce", since=t0)
    ramp = (force > 1.0) & (force < FORCE_KN - 1.0)
    slope = float(np.polyfit(t[ramp], force[ramp], 1)[0]) if ramp.sum() >= 5 else float("nan")
    bench.expect("clamp force rate", slope, RATE_KN_S, rel_tol=0.05, unit="kN/s",
                 detail="least squares over the frames between 1 kN and 15 kN")
    bench.run(0.35)   # every EPB_Info page once more
    expect_events(bench, t0, ["APPLIED"])
    bench.expect("ApplyCount after the apply", bench.value("EPB_Info", "ApplyCount"), count_before + 1)


@pytest.mark.req("EPB-03", "EPB-06")
def test_apply_is_refused_while_moving(bench: Case) -> None:
    bring_to(bench, "RELEASED")
    vehicle(bench, 30.0, "RELEASED")
    bench.run(0.05)
    t0 = switch(bench, "APPLY")
    bench.always("stays RELEASED", in_state(bench, "RELEASED"), 0.5)
    expect_events(bench, t0, ["REFUSED_MOVING"])


@pytest.mark.req("EPB-04", "EPB-05", "EPB-06")
def test_release_needs_the_brake_pedal(bench: Case) -> None:
    bring_to(bench, "APPLIED")
    vehicle(bench, 0.0, "RELEASED")
    bench.run(0.05)
    t0 = switch(bench, "RELEASE")
    bench.always("stays APPLIED without the brake pedal", in_state(bench, "APPLIED"), 0.3)
    vehicle(bench, 0.0, "PRESSED")
    bench.run(0.05)
    switch(bench, "RELEASE")
    bench.eventually("RELEASING", in_state(bench, "RELEASING"), REACTION_S)
    bench.expect("motor current while releasing", bench.value("EPB_Status", "MotorCurrentLeft"), 8.0, abs_tol=0.005,
                 unit="A")
    bench.eventually("RELEASED", in_state(bench, "RELEASED"), RAMP_S + 0.05)
    bench.expect("clamp force released", bench.value("EPB_Status", "ClampForce"), 0.0, abs_tol=0.0005, unit="kN")
    bench.run(0.05)
    expect_events(bench, t0, ["REFUSED_NO_BRAKE", "RELEASED"])
    _, counts = bench.history("EPB_Event", "EventCount", since=t0)
    bench.expect_true("EventCount up by one per event", len(counts) == 2 and (counts[1] - counts[0]) % 256 == 1,
                      measured=" ".join(f"{c:g}" for c in counts), expected="n, n+1")


@pytest.mark.req("EPB-02", "EPB-03", "EPB-06")
@pytest.mark.parametrize("fault", ["drop", "checksum_offset"])
def test_no_apply_without_a_trusted_speed(bench: Case, fault: str) -> None:
    """HIL_VehicleState lost (drop) or with a wrong Profile 5 CRC (checksum_offset): the speed is not valid within
    70 ms of the last good frame, an apply is refused, and the speed is valid again once good frames come."""
    bring_to(bench, "RELEASED")
    bench.inject(fault, "HIL_VehicleState", duration=0.6, param=1 if fault == "checksum_offset" else 0)
    bench.eventually("SpeedValid INVALID", lambda: bench.value("EPB_Status", "SpeedValid") == 0, 0.070 + 0.020)
    t0 = switch(bench, "APPLY")
    bench.run(0.2)
    expect_events(bench, t0, ["REFUSED_NO_SPEED"])
    bench.expect("still RELEASED", bench.value("EPB_Status", "ParkState"), park_state(bench, "RELEASED"))
    bench.eventually("SpeedValid VALID after the fault", lambda: bench.value("EPB_Status", "SpeedValid") == 1, 0.6)


@pytest.mark.req("EPB-07")
def test_service_mode(bench: Case) -> None:
    bring_to(bench, "RELEASED")
    service(bench, "ON")
    bench.eventually("SERVICE", in_state(bench, "SERVICE"), REACTION_S)
    t0 = switch(bench, "APPLY")
    bench.always("the switch does nothing in SERVICE", in_state(bench, "SERVICE"), 0.3)
    expect_events(bench, t0, [])
    service(bench, "OFF")
    bench.eventually("RELEASED after ServiceMode OFF", in_state(bench, "RELEASED"), REACTION_S)
    bench.set("HIL_ParkSwitch", Switch="NEUTRAL")
    service(bench, "ON")
    bench.eventually("SERVICE again", in_state(bench, "SERVICE"), REACTION_S)
    bench.stop_sending("HIL_Service")
    sent, _ = bench.history("HIL_Service", "ServiceMode")
    last = float(sent[-1])   # the last ON frame: the silence counts from it
    bench.always("SERVICE through 140 ms of silence", in_state(bench, "SERVICE"),
                 max(0.0, last + 0.140 - bench.now))
    bench.eventually("RELEASED at most 200 ms after the last frame", in_state(bench, "RELEASED"),
                     max(0.0, last + 0.200 + 0.020 - bench.now))
    bench.set("HIL_Service", ServiceMode="OFF")
    bench.resume_sending("HIL_Service")
