"""4WIS EV: bad requests (docs/spec/formulas.md §2 "undefined cases"; fault codes: VCU_VehicleState.VcuFault value
table).

Each undefined or bad request must give its VcuFault, zero wheel-speed commands (and wheels that stop),
wheel angles held at the last valid command (docs/contract/vcu.md VCU-FLT-08: a wheel never swings on bad
input), and no invalid frame on the bus (no out-of-range value; a NaN cannot be encoded, and a sender that
tries one stops, which these steps would see as a missing message).

Each case first drives a valid PIVOT request (about S0 = (3, 2) m, 1 m/s), then sends the bad one.

What the contract's ranges allow and what they do not:
- ANGLE_OVER_90 ("a wheel would need more than 90°"): the VCU raises it (VCU-FLT-06) in NORMAL/ADAPTIVE for a
  centre strictly between the wheels of an axle, i.e. |X| > atan(2L/K) = 78.6° (NORMAL) or atan(L/K) = 68.1°
  (ADAPTIVE). X = HandWheelAngle / 15 and the DBC limits HandWheelAngle to ±900°, so |X| ≤ 60°: it cannot
  be reached from the bus. The case checks the ends of the range instead, and PIVOT's fold (§2: a centre
  between the wheels of an axle folds the angle and reverses the wheel, a valid request).
- An invalid DRV_MotionRequest: the DBC range of DriveMode [0, 3] has no undefined value and bench.set refuses
  out-of-range values, so an unknown mode with a valid checksum cannot be sent; a frame with a wrong checksum
  is injected instead (bench.inject), and a request no wheel can execute is the other REQUEST_INVALID.
"""

from __future__ import annotations

import pytest

from testcases.ev4wis import oracle
from testcases.ev4wis.oracle import WHEELS
from testcases.ev4wis.plots import plot_vcu_state, plot_wheels
from testcases.ev4wis.steps import (
    ANGLE_TOL,
    CENTRE_ABS_TOL,
    CLEAN_BUS_REQS,
    FAULT_VALUE,
    VCU_AND_WHEELS,
    expect_fault,
    expect_wheels,
    limit,
    send_car_mode,
    send_pivot,
    start,
    wait_for_targets,
)
from testcases.fault_memory import FaultMemory

S0, V0 = (3.0, 2.0), 1.0          # the valid request before the bad one
FAULT_WITHIN_S = limit("fault_within")    # s: 3 × 20 ms timeout + the VCU's task and 20 ms VehicleState cycle
CMD_CYCLE_S = 0.02                # s: VCU_WheelCmd_xx is a 10 ms message, sent in its own phase after VehicleState
STOP_WITHIN_S = limit("stop_within")      # s: the hub motors' speed lag (100 ms) from ~50 rpm to 0.1 rpm: ~0.65 s

#: what every rejection checks (_expect_rejected after _valid_first): the valid PIVOT request first, then the
#: fault reaction and its timing, the wheels stopping, YawRateTarget 0, a clean bus
REJECTED = ("VCU-MODE-02", "VCU-FLT-08", "VCU-FLT-09", "VCU-OUT-04", "WHL-CTL-02", *CLEAN_BUS_REQS)
pytestmark = [pytest.mark.dut(*VCU_AND_WHEELS)]


class Held(dict[str, float]):
    """The commanded angles the valid request left, and the VCU's fault memory, cleared before the bad request."""

    memory: FaultMemory
    since: float


def _valid_first(bench) -> Held:
    """Drive the valid request S0 and return the commanded angles it leaves (and the cleared fault memory)."""
    start(bench)
    send_pivot(bench, *S0, V0)
    wait_for_targets(bench, oracle.rotation_targets(*S0, V0))
    held = Held({w: bench.value(f"VCU_WheelCmd_{w}", "SteerAngleCmd") for w in WHEELS})
    held.memory = FaultMemory(bench, "VCU")
    held.since = bench.now
    return held


def _expect_rejected(bench, fault: str, held: dict[str, float], *, plots: bool = True) -> None:
    """The fault, zero speed commands, angles held, wheels stopped, clean bus."""
    bench.eventually(f"VcuFault becomes {fault}",
                     lambda: bench.value("VCU_VehicleState", "VcuFault") == FAULT_VALUE[fault], FAULT_WITHIN_S)
    bench.eventually("four speed commands 0 (next VCU_WheelCmd frames)",
                     lambda: all(bench.value(f"VCU_WheelCmd_{w}", "WheelSpeedCmd") == 0.0 for w in WHEELS),
                     CMD_CYCLE_S)
    for w in WHEELS:
        bench.expect(f"{w} speed command 0", bench.value(f"VCU_WheelCmd_{w}", "WheelSpeedCmd"), 0.0, unit="rpm")
    bench.eventually("four wheels stopped (|WheelSpeed| ≤ 0.1 rpm)",
                     lambda: all(abs(bench.value(f"WHL_Status_{w}", "WheelSpeed")) <= 0.1 for w in WHEELS),
                     STOP_WITHIN_S)
    expect_fault(bench, fault)
    if isinstance(held, Held):   # the DTC side: the fault's DTC stored while the bad request lasts
        held.memory.during(fault, held.since)
    for w in WHEELS:
        bench.expect(f"{w} angle command held", bench.value(f"VCU_WheelCmd_{w}", "SteerAngleCmd"), held[w],
                     abs_tol=ANGLE_TOL, unit="deg", detail="held at the last valid command (VCU-FLT-08)")
    bench.expect("YawRateTarget 0", bench.value("VCU_VehicleState", "YawRateTarget"), 0.0, unit="deg/s")
    bench.expect_clean_bus()
    if plots:
        plot_wheels(bench)
        plot_vcu_state(bench)


@pytest.mark.req("VCU-FLT-04", "VCU-FLT-03", *REJECTED)
def test_centre_at_origin_with_speed(bench) -> None:
    """r_o = 0 with v_o ≠ 0: v_o / r_o is undefined (§2)."""
    held = _valid_first(bench)
    send_pivot(bench, 0.0, 0.0, 1.0)
    _expect_rejected(bench, "CENTRE_AT_ORIGIN", held)


@pytest.mark.req("VCU-MODE-03", "VCU-FLT-04", "VCU-MODE-01", "WHL-CTL-01", *CLEAN_BUS_REQS)
def test_centre_at_origin_at_standstill_is_valid(bench) -> None:
    """The contrast to the case above: with v_o = 0 the centre at the origin is defined (spin-in-place angles
    by eq. 1-4, every speed 0): no fault."""
    start(bench)
    send_pivot(bench, 0.0, 0.0, 0.0)
    targets = {w: oracle.WheelTarget(oracle.paper_angle(0.0, 0.0, w), 0.0) for w in WHEELS}
    wait_for_targets(bench, targets)
    expect_fault(bench, "OK")
    expect_wheels(bench, targets, "docs/spec/formulas.md §2 eq. 1-4 at S = (0, 0), v_o = 0")
    bench.expect_clean_bus()
    plot_wheels(bench)


@pytest.mark.req("VCU-FLT-05", *REJECTED)
@pytest.mark.parametrize("wheel", WHEELS, ids=[f"centre on {w}" for w in WHEELS])
def test_centre_on_wheel(bench, wheel: str) -> None:
    """r_i = 0: that wheel's angle is undefined (§2). PivotX/PivotY carry 0.02 m steps, so the nearest centre
    the bus can carry is 5 mm from the contact point (±0.56 instead of ±0.555 m); the VCU treats a
    centre within 1 cm of a contact point as on it (docs/contract/vcu.md VCU-FLT-05)."""
    px, py = oracle.WHEEL_POSITION[wheel]
    x = round(px / oracle.PIVOT_RESOLUTION) * oracle.PIVOT_RESOLUTION
    y = round(py / oracle.PIVOT_RESOLUTION) * oracle.PIVOT_RESOLUTION
    x, y = round(x, 2), round(y, 2)
    bench.note(f"requested centre ({x:g}, {y:g}) m, {1000 * ((x - px) ** 2 + (y - py) ** 2) ** 0.5:.1f} mm from "
               f"{wheel}'s contact point ({px:g}, {py:g}) m")
    held = _valid_first(bench)
    send_pivot(bench, x, y, 1.0)
    _expect_rejected(bench, "CENTRE_ON_WHEEL", held)


@pytest.mark.req("VCU-LIM-01", "VCU-FLT-02", *REJECTED)
def test_request_no_wheel_can_execute(bench) -> None:
    """PIVOT about (0.02, 0) at 2 m/s: ω = 100 rad/s (5730 °/s, beyond YawRateTarget's ±300 °/s) and wheel
    speeds of about 5000 rpm (beyond WheelSpeedCmd's ±3000 rpm): no valid command exists; the VCU answers
    REQUEST_INVALID (docs/contract/vcu.md VCU-LIM-01: more than 1500 rpm on a wheel or more than 120 °/s of
    yaw)."""
    worst = max(abs(t.rpm) for t in oracle.rotation_targets(0.02, 0.0, 2.0).values())
    bench.note(f"§2 would need {worst:.0f} rpm on the fastest wheel and {oracle.yaw_rate(0.02, 0.0, 2.0):.0f} °/s")
    held = _valid_first(bench)
    send_pivot(bench, 0.02, 0.0, 2.0)
    _expect_rejected(bench, "REQUEST_INVALID", held)


@pytest.mark.req("VCU-FLT-01", "VCU-FLT-10", "COM-RX-02", *REJECTED)
def test_motion_request_timeout(bench) -> None:
    """DRV_MotionRequest stops (docs/spec/k-matrix.md: timed out after 3 × 20 ms): REQUEST_TIMEOUT; when it comes back,
    the VCU recovers on the next valid request."""
    held = _valid_first(bench)
    bench.stop_sending("DRV_MotionRequest")
    _expect_rejected(bench, "REQUEST_TIMEOUT", held, plots=False)
    bench.resume_sending("DRV_MotionRequest")
    wait_for_targets(bench, oracle.rotation_targets(*S0, V0))
    expect_fault(bench, "OK")
    bench.expect_clean_bus()
    plot_wheels(bench)
    plot_vcu_state(bench)


@pytest.mark.req("VCU-FLT-01", "VCU-MODE-04", "COM-RX-02", *REJECTED)
def test_steering_timeout_in_normal(bench) -> None:
    """NORMAL needs DRV_Steering (the hand-wheel angle): when it stops, REQUEST_TIMEOUT (docs/contract/vcu.md
    VCU-FLT-01)."""
    start(bench)
    centre = oracle.normal_centre(300.0)
    send_car_mode(bench, "NORMAL", 300.0, 1.0)
    wait_for_targets(bench, oracle.car_mode_targets(centre, 1.0))
    held = {w: bench.value(f"VCU_WheelCmd_{w}", "SteerAngleCmd") for w in WHEELS}
    bench.stop_sending("DRV_Steering")
    _expect_rejected(bench, "REQUEST_TIMEOUT", held)


@pytest.mark.req("VCU-FLT-02", "VCU-FLT-01", "VCU-FLT-03", "VCU-FLT-08", "VCU-FLT-09", "VCU-FLT-10", "COM-RX-01",
                 "COM-RX-02", "VCU-MODE-02", "WHL-CTL-02", "VCU-GEN-01")
def test_invalid_motion_request_frame(bench) -> None:
    """DRV_MotionRequest frames with a wrong checksum (bench.inject checksum_offset): the receiver treats them
    as invalid (docs/spec/k-matrix.md) and the VCU answers REQUEST_INVALID while the last frame was invalid; once no
    valid frame came for 3 × 20 ms the message is timed out and REQUEST_TIMEOUT follows (REQUEST_TIMEOUT is checked
    first, docs/contract/vcu.md VCU-FLT-03; the timeout runs from the last valid frame, COM-RX-02); a valid
    frame again recovers. The only invalid frames on the bus are the injected
    ones: the VCU and the wheels never send one.

    An unknown DriveMode with a valid checksum cannot be produced: the DBC range [0, 3] leaves no undefined
    value, bench.set refuses out-of-range values, and a bitflip fault corrupts the checksum as well."""
    held = _valid_first(bench)
    fault = bench.inject("checksum_offset", "DRV_MotionRequest", param=1, duration=1.0)
    bench.note(f"injected fault {fault.describe()} (bench time)")
    bench.eventually("VcuFault becomes REQUEST_INVALID (first bad frame)",
                     lambda: bench.value("VCU_VehicleState", "VcuFault") == FAULT_VALUE["REQUEST_INVALID"],
                     FAULT_WITHIN_S)
    bench.eventually("four speed commands 0 (next VCU_WheelCmd frames)",
                     lambda: all(bench.value(f"VCU_WheelCmd_{w}", "WheelSpeedCmd") == 0.0 for w in WHEELS),
                     CMD_CYCLE_S)
    for w in WHEELS:
        bench.expect(f"{w} speed command 0", bench.value(f"VCU_WheelCmd_{w}", "WheelSpeedCmd"), 0.0, unit="rpm")
        bench.expect(f"{w} angle command held", bench.value(f"VCU_WheelCmd_{w}", "SteerAngleCmd"), held[w],
                     abs_tol=ANGLE_TOL, unit="deg", detail="held at the last valid command (VCU-FLT-08)")
    bench.eventually("then REQUEST_TIMEOUT (no valid frame for 3 × 20 ms)",
                     lambda: bench.value("VCU_VehicleState", "VcuFault") == FAULT_VALUE["REQUEST_TIMEOUT"],
                     FAULT_WITHIN_S)
    bench.eventually("four wheels stopped (|WheelSpeed| ≤ 0.1 rpm)",
                     lambda: all(abs(bench.value(f"WHL_Status_{w}", "WheelSpeed")) <= 0.1 for w in WHEELS),
                     STOP_WITHIN_S)
    invalid = bench.invalid_log()
    others = [f for f in invalid if f.message != "DRV_MotionRequest"]
    bench.expect_true("invalid frames on the bus: only the injected DRV_MotionRequest ones", not others,
                      measured=f"{len(invalid) - len(others)} injected, {len(others)} other", expected="0 other",
                      detail="; ".join(f"{f.message}: {f.reason}" for f in others[:5]))
    bench.expect_true("the injected frames were detected as CRC errors (AUTOSAR E2E status ERROR)",
                      len(invalid) > len(others)
                      and all(f.reason.startswith("E2E ERROR") for f in invalid if f not in others),
                      measured=len(invalid) - len(others), expected="> 0, E2E ERROR")
    bench.wait_until(lambda: bench.now >= fault.end, 1.0)
    wait_for_targets(bench, oracle.rotation_targets(*S0, V0))
    expect_fault(bench, "OK")
    plot_wheels(bench)
    plot_vcu_state(bench)


@pytest.mark.req("VCU-FLT-06", "VCU-MODE-04", "VCU-MODE-05", "VCU-MODE-01", "VCU-OUT-06", "WHL-CTL-01",
                 "WHL-CTL-02", *CLEAN_BUS_REQS)
@pytest.mark.parametrize("mode,hand_wheel", [("NORMAL", 900.0), ("NORMAL", -900.0), ("ADAPTIVE", 900.0),
                                             ("ADAPTIVE", -900.0)],
                         ids=["NORMAL handwheel=+900", "NORMAL handwheel=-900", "ADAPTIVE handwheel=+900",
                              "ADAPTIVE handwheel=-900"])
def test_beyond_geometry_not_reachable_from_the_bus(bench, mode: str, hand_wheel: float) -> None:
    """ANGLE_OVER_90 cannot be requested through the DBC's ±900° hand wheel (|X| ≤ 60° < 68.1°); at the end of
    the range every wheel still points within ±90° and rolls forward (positive rpm for a forward request)."""
    bench.note("ANGLE_OVER_90 is unreachable from the bus: X = HandWheelAngle / 15 ≤ 60°, the VCU "
               "raises it above 78.6° (NORMAL) / 68.1° (ADAPTIVE), i.e. for a centre between the wheels of an axle.")
    centre = (oracle.normal_centre if mode == "NORMAL" else oracle.adaptive_centre)(hand_wheel)
    v = 0.5
    targets = oracle.car_mode_targets(centre, v)
    start(bench)
    send_car_mode(bench, mode, hand_wheel, v)
    wait_for_targets(bench, targets)
    expect_fault(bench, "OK")
    bench.note(f"centre ({centre[0]:.3f}, {centre[1]:g}) m: |x| > K = {oracle.K:g} m, outside the track, so every "
               f"wheel points within ±90° and rolls forward")
    bench.expect("RotationCentreX (the VCU steers about the oracle's centre)",
                 bench.value("VCU_RotationCentre", "RotationCentreX"), centre[0], abs_tol=CENTRE_ABS_TOL, unit="m")
    expect_wheels(bench, targets, "docs/spec/formulas.md §2")
    for w in WHEELS:
        n = bench.value(f"WHL_Status_{w}", "WheelSpeed")
        bench.expect_true(f"{w} rolls forward", n > 0, measured=n, expected="> 0 rpm")
    bench.expect_clean_bus()
    plot_wheels(bench)


@pytest.mark.req("VCU-MODE-01", "VCU-MODE-02", "VCU-FLT-06", "WHL-CTL-01", "WHL-CTL-02", *CLEAN_BUS_REQS)
def test_pivot_between_the_wheels_folds(bench) -> None:
    """§2: S between the wheels of one axle, so that a wheel would need more than 90°: the angle is folded into
    (-90°, 90°] and that wheel reversed. In PIVOT this is a valid request (no fault)."""
    x, y, v = 0.2, 2.0, 1.0          # ahead of the front axle, between FL and FR
    targets = oracle.rotation_targets(x, y, v)
    start(bench)
    send_pivot(bench, x, y, v)
    wait_for_targets(bench, targets)
    expect_fault(bench, "OK")
    expect_wheels(bench, targets, "docs/spec/formulas.md §2 (fold and reverse)")
    n_fr = bench.value("WHL_Status_FR", "WheelSpeed")
    bench.expect_true("FR reversed (negative rpm although the rotation is clockwise)", n_fr < 0, measured=n_fr,
                      expected="< 0 rpm")
    bench.expect_clean_bus()
    plot_wheels(bench)
