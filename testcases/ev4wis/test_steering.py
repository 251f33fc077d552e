"""4WIS EV: steering angles against docs/spec/formulas.md §2 ([P0] eq. 1-4) for more than 50 rotation centres.

PIVOT centres in all four quadrants, on both axes, on the axle lines, near the wheel columns, between the
wheels of an axle (§2 folds the angle and reverses the wheel) and far away (≥ 1 km); LATERAL; NORMAL and
ADAPTIVE from the hand-wheel angle (docs/spec/vehicles.md A: X = HandWheelAngle / 15; NORMAL's centre on y = -L,
ADAPTIVE's on y = 0). Each wheel's commanded (VCU_WheelCmd_xx) and reached (WHL_Status_xx) angle within
0.05° of the oracle; the wheel speeds of the same request within 0.5 % or 0.2 rpm; the VCU's curvature
angle, rotation centre, yaw-rate target and mode.
"""

from __future__ import annotations

from dataclasses import dataclass

import pytest

from testcases.ev4wis import oracle
from testcases.ev4wis.plots import plot_wheels
from testcases.ev4wis.steps import (
    ANGLE_TOL,
    CENTRE_ABS_TOL,
    CLEAN_BUS_REQS,
    MODE_VALUE,
    SPEED_REL_TOL,
    VCU_AND_WHEELS,
    YAW_ABS_TOL,
    expect_fault,
    expect_wheels,
    send_car_mode,
    send_pivot,
    speed_for,
    start,
    wait_for_targets,
)

pytestmark = [pytest.mark.dut(*VCU_AND_WHEELS)]


@dataclass(frozen=True)
class Request:
    mode: str
    centre: tuple[float, float] | None = None   # PIVOT
    hand_wheel: float = 0.0                       # NORMAL, ADAPTIVE
    v: float | None = None                        # LATERAL (signed); others: chosen from the centre

    @property
    def id(self) -> str:
        if self.mode == "PIVOT":
            return f"PIVOT centre=({self.centre[0]:g},{self.centre[1]:g})"
        if self.mode == "LATERAL":
            return f"LATERAL v={self.v:+g}"
        return f"{self.mode} handwheel={self.hand_wheel:g}"


_PIVOT_CENTRES = {
    "quadrant I": [(3.0, 2.0), (5.0, 8.0), (1.2, 0.6), (0.8, 3.5)],
    "quadrant II": [(-3.0, 2.0), (-6.0, 4.5), (-1.0, 0.4), (-0.3, 2.5)],
    "quadrant III": [(-3.0, -2.0), (-8.0, -5.0), (-1.5, -0.5), (-0.2, -3.0)],
    "quadrant IV": [(3.0, -2.0), (7.0, -4.0), (0.9, -0.7), (0.4, -2.4)],
    "x axis": [(3.0, 0.0), (-3.0, 0.0), (12.0, 0.0), (-0.3, 0.0), (0.8, 0.0)],
    "y axis": [(0.0, 3.0), (0.0, -3.0), (0.0, 0.5), (0.0, -0.8), (0.0, 9.0)],
    "front axle line y = L": [(4.0, 1.38), (-4.0, 1.38), (0.0, 1.38), (0.3, 1.38), (-1.2, 1.38)],
    "rear axle line y = -L": [(4.08, -1.38), (-5.0, -1.38), (0.0, -1.38), (-0.3, -1.38), (1.0, -1.38)],
    "near a wheel column x = ±K": [(0.56, 4.0), (-0.56, -4.0)],
    "far away (≥ 1 km)": [(1000.0, 0.0), (-1200.0, 0.0), (0.0, 1000.0), (0.0, -1100.0), (900.0, 900.0),
                          (-1000.0, -600.0)],
}

REQUESTS = (
    [Request("PIVOT", centre=c) for group in _PIVOT_CENTRES.values() for c in group]
    + [Request("LATERAL", v=1.5), Request("LATERAL", v=-1.5)]
    + [Request("NORMAL", hand_wheel=hw) for hw in (-900.0, -510.4, -200.0, -30.0, 0.0, 45.0, 300.0, 900.0)]
    + [Request("ADAPTIVE", hand_wheel=hw) for hw in (-900.0, -450.6, -120.0, 0.0, 75.0, 450.0, 900.0)]
)


def _expected(req: Request) -> tuple[dict[str, oracle.WheelTarget], tuple[float, float] | None, float, float | None,
                                      float, str]:
    """(wheel targets, centre or None, TargetSpeed, curvature angle X or None, yaw rate deg/s, source)."""
    if req.mode == "PIVOT":
        x, y = req.centre
        v = speed_for(req.centre)
        return (oracle.rotation_targets(x, y, v), req.centre, v, oracle.curvature_angle(x, y),
                oracle.yaw_rate(x, y, v), "docs/spec/formulas.md §2, eq. 1-4 and 7-10 (E1 corrected)")
    if req.mode == "LATERAL":
        return (oracle.lateral_targets(req.v), None, req.v, 90.0, 0.0,
                "docs/contract/vcu.md VCU-MODE-08 LATERAL: all +90°, one signed speed (eq. 6)")
    centre = (oracle.normal_centre if req.mode == "NORMAL" else oracle.adaptive_centre)(req.hand_wheel)
    v = speed_for(centre)
    yaw = 0.0 if centre is None else oracle.yaw_rate(*centre, oracle.forward_v_o(centre[0], v))
    where = "y = -L" if req.mode == "NORMAL" else "y = 0"
    return (oracle.car_mode_targets(centre, v), centre, v, oracle.curvature_from_hand_wheel(req.hand_wheel), yaw,
            f"docs/spec/vehicles.md A {req.mode}: X = HandWheelAngle/15, centre on {where}; docs/spec/formulas.md §2")


#: what every request checks: §2's angles and speeds commanded and reached, the VehicleState fields, a clean bus
_COMMON_REQS = ("VCU-MODE-01", "VCU-REQ-01", "VCU-OUT-01", "VCU-OUT-02", "VCU-OUT-03", "VCU-OUT-04", "VCU-FLT-03",
                "WHL-CTL-01", "WHL-CTL-02", "WHL-STA-01", *CLEAN_BUS_REQS)
_MODE_REQS = {"PIVOT": ("VCU-MODE-02", "VCU-OUT-06"), "LATERAL": ("VCU-MODE-08",),
              "NORMAL": ("VCU-MODE-04", "VCU-OUT-06"), "ADAPTIVE": ("VCU-MODE-05", "VCU-MODE-06", "VCU-OUT-06")}


def _param(req: Request):
    reqs = _MODE_REQS[req.mode] + (("VCU-MODE-07",) if req.mode in ("NORMAL", "ADAPTIVE") and req.hand_wheel == 0.0
                                      else ())
    return pytest.param(req, id=req.id, marks=pytest.mark.req(*_COMMON_REQS, *reqs))


@pytest.mark.parametrize("req", [_param(r) for r in REQUESTS])
def test_steering_angles(bench, req: Request) -> None:
    targets, centre, v, x_angle, yaw, source = _expected(req)
    start(bench)
    if req.mode == "PIVOT":
        send_pivot(bench, *req.centre, v)
    elif req.mode == "LATERAL":
        bench.set("DRV_MotionRequest", DriveMode="LATERAL", TargetSpeed=v)
    else:
        send_car_mode(bench, req.mode, req.hand_wheel, v)
    if centre is not None:
        bench.note(f"centre S = ({centre[0]:.4f}, {centre[1]:.4f}) m, TargetSpeed {v:+g} m/s")
    else:
        bench.note(f"centre at infinity (translation), TargetSpeed {v:+g} m/s")

    wait_for_targets(bench, targets)
    expect_fault(bench, "OK")
    bench.expect("ActiveMode", bench.value("VCU_VehicleState", "ActiveMode"), MODE_VALUE[req.mode],
                 detail="DriveMode value table")
    expect_wheels(bench, targets, source)
    if x_angle is None:
        bench.note("curvature angle X not checked: the centre is the front-axle centre itself, whose heading "
                   "is undefined (docs/spec/formulas.md and the DBC do not define X there)")
    else:
        bench.expect("curvature angle X (VCU_VehicleState.CurvatureAngle)",
                     bench.value("VCU_VehicleState", "CurvatureAngle"), x_angle, abs_tol=ANGLE_TOL, unit="deg",
                     detail="heading of a virtual wheel at the front-axle centre (0, L) about S ([P2], DBC)")
    bench.expect("YawRateTarget = v_o / r_o", bench.value("VCU_VehicleState", "YawRateTarget"), yaw,
                 abs_tol=YAW_ABS_TOL, rel_tol=SPEED_REL_TOL, unit="deg/s", detail="[P0] eq. 5")
    if centre is not None:
        bench.expect("RotationCentreX", bench.value("VCU_RotationCentre", "RotationCentreX"), centre[0],
                     abs_tol=CENTRE_ABS_TOL, unit="m")
        bench.expect("RotationCentreY", bench.value("VCU_RotationCentre", "RotationCentreY"), centre[1],
                     abs_tol=CENTRE_ABS_TOL, unit="m")
    bench.expect_clean_bus()
    plot_wheels(bench)


#: (label, mode, hand wheel or TargetSpeed) of the translations: the centre is at infinity.
END = 5242.87   # m: VCU_RotationCentre's range end, the contract's "infinity" (VCU-OUT-07)
#: (label, mode, hand wheel or TargetSpeed, expected (X, Y) on the bus). Translations have their centre at
#: infinity to the right of the wheels' common heading θ, (cos θ, −sin θ) scaled to the range end: straight
#: (θ = 0) (+END, 0), LATERAL (θ = +90° either way) (0, −END). A far finite centre is saturated per coordinate.
_TRANSLATIONS = [("NORMAL straight", "NORMAL", 0.0, (END, 0.0)), ("ADAPTIVE straight", "ADAPTIVE", 0.0, (END, 0.0)),
                 ("NORMAL hand wheel 0.3° (centre 7907 m to the right)", "NORMAL", 0.3, (END, -oracle.L)),
                 ("LATERAL right", "LATERAL", 1.0, (0.0, -END)), ("LATERAL left", "LATERAL", -1.0, (0.0, -END))]


@pytest.mark.req("VCU-OUT-07", "VCU-OUT-06", "VCU-MODE-07", "VCU-MODE-08", "COM-VAL-01", *CLEAN_BUS_REQS)
def test_rotation_centre_at_infinity(bench) -> None:
    """VCU_RotationCentre for a centre at infinity (docs/contract/vcu.md VCU-OUT-07): the DBC has no value beyond
    ±5242.87 m, and an out-of-range value would make the frame invalid (COM-VAL-01), so the range end is the
    contract's "infinity": straight ahead (+5242.87, 0), LATERAL (0, -5242.87) whichever way it moves; a finite
    centre farther away is saturated per coordinate (VCU-OUT-06). A finite centre must never be reported for a
    translation."""
    for label, mode, value, expected in _TRANSLATIONS:
        start(bench)
        if mode == "LATERAL":
            bench.set("DRV_MotionRequest", DriveMode="LATERAL", TargetSpeed=value)
            targets = oracle.lateral_targets(value)
        else:
            send_car_mode(bench, mode, value, 1.0)
            centre = oracle.normal_centre(value) if mode == "NORMAL" else oracle.adaptive_centre(value)
            targets = oracle.car_mode_targets(centre, 1.0)
        wait_for_targets(bench, targets)
        for signal, want in zip(("RotationCentreX", "RotationCentreY"), expected):
            bench.expect(f"{label}: {signal}", bench.value("VCU_RotationCentre", signal), want,
                         abs_tol=CENTRE_ABS_TOL, unit="m", detail="docs/contract/vcu.md VCU-OUT-07 (one LSB)")
        bench.expect_clean_bus()
    plot_wheels(bench, "last request (LATERAL left)")
    bench.plot("VCU_RotationCentre (last request)", [("VCU_RotationCentre", "RotationCentreX"),
                                                     ("VCU_RotationCentre", "RotationCentreY")], ylabel="m")
