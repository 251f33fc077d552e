"""The ABS turning-state estimator without the bus (plant/ecus/abs_estimator.py, [P4] eq. 5-14,
docs/spec/formulas.md §6): eq. 13 with erratum E3 corrected, eq. 11/12, the wheel selection, identification before and
during ABS control on synthetic wheel speeds of the four-wheel model, and the mirrors of the DBC ranges."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import cantools
import pytest
from hypothesis import given
from hypothesis import strategies as st

from plant import signal_ranges as ranges
from plant.ecus import abs as abs_ecu
from plant.ecus.abs import estimator_config
from plant.ecus.abs_estimator import (
    DECREASE,
    INCREASE,
    TurnStateEstimator,
    front_wheel_angle,
    nth_largest,
    turn_direction,
    yaw_rate,
)
from plant.vehicles import AbsParams, load_file, load_parameters
from tests import repo
from tests.repo import BENCH_DBC, CHASSIS_DBC

CAR, PARAMS = load_parameters("ACLASS"), load_parameters("ABS")
CONFIG = estimator_config(PARAMS, CAR)
B, L, A, K = 1.55, 2.65, 1.06, 1.90e-3          # docs/spec/vehicles.md B
L0, L1, L2 = CONFIG.v_l0, CONFIG.v_l1, CONFIG.v_l2
KMH = 3.6


def wheel_speeds(x_kmh: float, delta: float) -> list[float]:
    """Four-wheel model ([P4] eq. 4 with small angles, eq. 11 for r): FL, FR, RL, RR in km/h; delta rad, left +."""
    x = x_kmh / KMH
    r = x * delta / L / (1 + K * x * x)
    return [(x + (A * delta - B / 2) * r) * KMH, (x + (A * delta + B / 2) * r) * KMH,
            (x - B / 2 * r) * KMH, (x + B / 2 * r) * KMH]


# -- eq. 13 and erratum E3 ----------------------------------------------------------------------------------

def test_eq13_cases() -> None:
    assert turn_direction(2.0, 2.1, 0.1, L0, L1, L2) == 1
    assert turn_direction(-2.0, -2.1, 0.1, L0, L1, L2) == -1
    assert turn_direction(0.3, 2.0, 1.7, L0, L1, L2) == 0          # front below V_l0
    assert turn_direction(2.0, L1 + 1, 1.0, L0, L1, L2) == 0       # beyond V_l1
    assert turn_direction(2.0, -2.0, 4.0, L0, L1, L2) == 0         # sides disagree


def test_erratum_e3_the_right_turn_also_needs_ddv_below_v_l2() -> None:
    # printed: "-ddV < V_l2" would accept this right turn although ddV is far beyond V_l2
    dv1, dv2 = -2.0, -2.0 - (L2 + 0.5)
    assert turn_direction(dv1, dv2, abs(dv1 - dv2), L0, L1, L2) == 0
    assert turn_direction(-dv1, -dv2, abs(dv1 - dv2), L0, L1, L2) == 0


@given(st.floats(-12, 12), st.floats(-12, 12))
def test_eq13_is_mirror_symmetric(dv1: float, dv2: float) -> None:
    ddv = abs(dv1 - dv2)
    assert turn_direction(dv1, dv2, ddv, L0, L1, L2) == -turn_direction(-dv1, -dv2, ddv, L0, L1, L2)


# -- eq. 11 / 12 --------------------------------------------------------------------------------------------

@given(st.floats(10.0, 150.0), st.floats(-0.3, 0.3))
def test_eq12_inverts_eq11(x_kmh: float, delta: float) -> None:
    r = yaw_rate(delta, x_kmh, L, K)
    assert r == pytest.approx((x_kmh / KMH) * delta / L / (1 + K * (x_kmh / KMH) ** 2), rel=1e-12, abs=1e-15)
    assert front_wheel_angle(B * r * KMH, x_kmh, L, B, K) == pytest.approx(delta, rel=1e-9, abs=1e-12)


def test_nth_largest() -> None:
    assert nth_largest([3.0, 1.0, 4.0, 2.0], 2) == 3.0 and nth_largest([3.0, 1.0, 4.0, 2.0], 3) == 2.0


# -- before ABS control ([P4] §3.1) ------------------------------------------------------------------------

def run(estimator: TurnStateEstimator, speeds: list[float], n: int, *, states=(INCREASE,) * 4, active=False,
        braking=False):
    est = None
    for _ in range(n):
        est = estimator.update(speeds, states, active, braking)
    return est


@pytest.mark.parametrize("delta_deg", [10.0, -10.0, 4.0])
@pytest.mark.parametrize("x_kmh", [25.0, 60.0])
def test_steady_turn_before_braking(delta_deg: float, x_kmh: float) -> None:
    est = TurnStateEstimator(CONFIG)
    speeds = wheel_speeds(x_kmh, math.radians(delta_deg))
    first = run(est, speeds, round(CONFIG.t1 / CONFIG.period) - 1)
    assert first.turn == 0, "a turn is taken only after it held t1"
    res = run(est, speeds, 100)
    assert res.turn == (1 if delta_deg > 0 else -1)
    assert res.delta_deg == pytest.approx(delta_deg, rel=1e-6)
    assert res.ref_speed == pytest.approx((speeds[2] + speeds[3]) / 2, rel=1e-12)      # eq. 5, 10
    assert res.yaw_rate == pytest.approx(yaw_rate(math.radians(delta_deg), x_kmh, L, K), rel=1e-6)


def test_wheel_selection_straight_and_braking() -> None:
    est = TurnStateEstimator(CONFIG)
    speeds = [50.0, 50.3, 49.8, 50.1]
    assert run(est, speeds, 5).ref_speed == 50.0                          # third-largest when straight
    assert run(est, speeds, 1, braking=True).ref_speed == 50.1           # second-largest when braking


def test_no_turn_below_the_minimum_speed_and_inside_the_thresholds() -> None:
    est = TurnStateEstimator(CONFIG)
    assert run(est, wheel_speeds(CONFIG.min_turn_speed - 1, 0.3), 50).turn == 0
    est.reset()
    assert run(est, [60.0, 60.0 + L0 / 2, 60.0, 60.0 + L0 / 2], 50).turn == 0


# -- during ABS control ([P4] §3.2, §3.3) --------------------------------------------------------------------

def test_identification_under_abs_and_delta_on_the_released_rear_axle() -> None:
    est = TurnStateEstimator(CONFIG)
    delta = math.radians(10.0)
    speeds = wheel_speeds(40.0, delta)
    run(est, speeds, 10, braking=True)                      # straight-line braking before ... (T needs time)
    est.reset()
    left = (DECREASE, INCREASE, DECREASE, INCREASE)
    t0 = round(CONFIG.t0 / CONFIG.period)
    assert run(est, speeds, t0, states=left, active=True, braking=True).turn == 0      # step 1: pattern held t0
    # step 2: the inner wheels switch to INCREASE while the outer ones increase -> axle differences, eq. 13
    res = run(est, speeds, 1, states=(INCREASE,) * 4, active=True, braking=True)
    assert res.turn == 0, "a candidate must hold t1 first"
    res = run(est, speeds, round(CONFIG.t1 / CONFIG.period) + 1, states=(INCREASE,) * 4, active=True, braking=True)
    assert res.turn == 1 and res.delta_deg == 0.0, "T confirmed, delta not yet identified"
    # step 3: the ECU releases the rear axle (both rear DECREASE); delta from it once the window is full
    released = (INCREASE, INCREASE, DECREASE, DECREASE)
    n = round(CONFIG.rear_release_time / CONFIG.period) + CONFIG.delta_average_points
    res = run(est, speeds, n, states=released, active=True, braking=True)
    assert res.turn == 1
    assert res.delta_deg == pytest.approx(10.0, rel=1e-6)
    assert res.ref_speed == pytest.approx((speeds[2] + speeds[3]) / 2, rel=1e-12)
    # the driver straightens: the averaged dV2 falls under V_l0 and T returns to 0 after t1
    res = run(est, wheel_speeds(40.0, 0.0), 2 * CONFIG.delta_average_points, states=released, active=True,
              braking=True)
    assert res.turn == 0 and res.delta_deg == 0.0


def test_no_identification_under_abs_without_the_side_pattern() -> None:
    est = TurnStateEstimator(CONFIG)
    speeds = wheel_speeds(40.0, math.radians(10.0))
    cycle = [(DECREASE, DECREASE, INCREASE, INCREASE), (INCREASE,) * 4, (DECREASE, INCREASE, INCREASE, DECREASE),
             (INCREASE,) * 4]
    for k in range(200):
        res = est.update(speeds, cycle[(k // 3) % 4], True, True)
        assert res.turn == 0


def _inner_cycles(est: TurnStateEstimator, speeds: list[float], side: int, offset: int, n: int, *, cycle: int = 12,
                  stretch: int = 3) -> list[int]:
    """Under ABS, the two inner wheels of `side` (1 left, -1 right) each run a pressure cycle of `cycle` updates
    with DECREASE in its first `stretch` updates; the rear one `offset` updates after the front one (the phase
    between the individually controlled front wheel and the select-low rear axle); the outer wheels stay in
    INCREASE. Returns T per update."""
    inner_front, inner_rear = (0, 2) if side == 1 else (1, 3)
    turns = []
    for k in range(n):
        states = [INCREASE] * 4
        if k % cycle < stretch:
            states[inner_front] = DECREASE
        if (k - offset) % cycle < stretch and k >= offset:
            states[inner_rear] = DECREASE
        turns.append(est.update(speeds, states, True, True).turn)
    return turns


@pytest.mark.parametrize("side", [1, -1])
@pytest.mark.parametrize("offset", range(12))
def test_identification_under_abs_whatever_the_phase_of_the_inner_wheels(side: int, offset: int) -> None:
    # [P4] §3.2 step 1 (docs/contract/abs.md ABS-TURN-01): the inner side's wheels decrease while the outer ones
    # increase. Front and rear inner wheels cycle on their own, so for offsets 3..9 their DECREASE stretches never
    # share an update; the side still decreases while the other increases, and the turn must be identified.
    # Bound from the rule: both inner wheels have decreased within pattern_window (0.1 s = 10 updates) by the
    # rear's first stretch (update offset, at most 11): armed; each inner wheel then reaches a switching point
    # (DECREASE -> INCREASE, outer INCREASE) within one more cycle (12 updates), and the candidate of eq. 13 on
    # dV1 = dV2 = 3.3 km/h (10 deg at 40 km/h, inside V_l0..V_l1, ddV = 0) is confirmed after t1 (5 updates).
    est = TurnStateEstimator(CONFIG)
    speeds = wheel_speeds(40.0, math.radians(10.0 * side))
    turns = _inner_cycles(est, speeds, side, offset, 60)
    assert -side not in turns, "never the opposite turn"
    assert side in turns[: 11 + 12 + 1 + round(CONFIG.t1 / CONFIG.period) + 1], f"T = {side} in time: {turns}"


def test_identification_under_abs_with_alternating_inner_wheels_in_detail() -> None:
    # offset 6: FL in DECREASE at updates 0-2, 12-14, ..., RL at 6-8, 18-20, ...; never both in one update.
    # By the rule: update 6 is the first with both inner wheels decreasing within 0.1 s (FL's last DECREASE 4
    # updates back) and both outer ones in INCREASE: the pattern holds, and t0 = one update arms LEFT. RL's
    # switching point is update 9 (dV2 stored), FL's update 15 (dV1 stored: both, candidate T = 1), confirmed
    # once t1 = 0.05 s (5 updates) has passed: T = 1 from update 20 on.
    est = TurnStateEstimator(CONFIG)
    turns = _inner_cycles(est, wheel_speeds(40.0, math.radians(10.0)), 1, 6, 24)
    assert turns.index(1) == 20
    assert turns[20:] == [1] * 4


def test_side_pattern_counts_a_decrease_only_within_the_pattern_window() -> None:
    # the inner wheels' DECREASE stretches 17 updates (0.17 s > pattern_window 0.1 s) apart, outer wheels in
    # INCREASE: the side is never seen decreasing together, nothing is armed and T stays 0
    est = TurnStateEstimator(CONFIG)
    turns = _inner_cycles(est, wheel_speeds(40.0, math.radians(10.0)), 1, 20, 200, cycle=40)
    assert set(turns) == {0}


def test_reference_speed_under_abs_follows_the_interpolation_points() -> None:
    est = TurnStateEstimator(replace(CONFIG, point_slip_stiffness=1e9))   # no point-slip allowance here
    decel = 30.0                                      # km/h per s
    v = 80.0
    run(est, [v] * 4, 5, braking=True)
    errors = []
    for k in range(150):
        v -= decel * CONFIG.period
        # each wheel in turn ends a cycle (DECREASE -> INCREASE) at the vehicle speed; the others slip 10 %
        wheel = (k // 2) % 4
        states = [INCREASE] * 4
        speeds = [v * 0.9] * 4
        if k % 2 == 0:
            states[wheel] = DECREASE
        else:
            speeds[wheel] = v
        res = est.update(speeds, states, True, True)
        if k > 40:
            errors.append(res.ref_speed - v)
    assert max(abs(e) for e in errors) < 0.2
    assert -res.slope == pytest.approx(decel, rel=0.05)


# -- configuration, parameters, ranges -------------------------------------------------------------------------

@pytest.mark.parametrize("field,value", [("track", 0.0), ("v_l0", 10.0), ("t1", -1.0), ("stability_factor", math.nan),
                                         ("delta_average_points", 0)])
def test_bad_config_is_refused(field: str, value: float) -> None:
    with pytest.raises(ValueError, match="estimator config"):
        replace(CONFIG, **{field: value})


def test_parameter_file_errors_name_the_key(tmp_path: Path) -> None:
    text = (repo.ROOT / "plant" / "vehicles" / "abs.toml").read_text()
    bad = tmp_path / "abs.toml"
    bad.write_text(text.replace('v_l0                  = { value = 0.6,', 'v_l0                  = { value = 12.0,'))
    with pytest.raises(ValueError, match="v_l0"):
        load_file(bad, AbsParams)
    bad.write_text(text.replace('unit = "s^2/m^2"', 'unit = "s2/m2"'))
    with pytest.raises(ValueError, match="stability_factor"):
        load_file(bad, AbsParams)


def test_estimator_uses_the_car_of_vehicles_md_b() -> None:
    assert (CONFIG.track, CONFIG.wheelbase, CONFIG.cog_to_front_axle) == pytest.approx((B, L, A))
    assert CONFIG.stability_factor == pytest.approx(K)
    # K of docs/spec/vehicles.md B from the car's own numbers: m / L^2 (b / C_f - a / C_r)
    k = CAR.mass / CAR.wheelbase ** 2 * (CAR.cog_to_rear_axle / CAR.cornering_stiffness_front
                                         - CAR.cog_to_front_axle / CAR.cornering_stiffness_rear)
    assert k == pytest.approx(K, rel=0.01)


def _signal(db, message: str, signal: str):
    return db.get_message_by_name(message).get_signal_by_name(signal)


def test_mirrored_ranges_match_the_dbcs() -> None:
    chassis, bench = cantools.database.load_file(CHASSIS_DBC), cantools.database.load_file(BENCH_DBC)
    for w in ("FL", "FR", "RL", "RR"):
        s = _signal(chassis, "ABS_WheelSpeeds", f"WheelSpeed{w}")
        assert (s.minimum, s.maximum) == ranges.ABS_WHEEL_SPEED
        assert s.scale == PARAMS.sensor_quantum
        for sig, rng in (("WheelSpeed", ranges.PLANT_ABS_WHEEL_SPEED), ("Slip", ranges.PLANT_ABS_SLIP),
                         ("BrakePressure", ranges.PLANT_ABS_PRESSURE), ("NormalLoad", ranges.PLANT_ABS_LOAD)):
            s = _signal(bench, f"PLANT_AbsWheel_{w}", sig)
            assert (s.minimum, s.maximum) == rng, sig
    s = _signal(chassis, "ABS_SteerState", "RefVehicleSpeed")
    assert (s.minimum, s.maximum) == ranges.ABS_REF_SPEED
    s = _signal(chassis, "ABS_SteerState", "FrontWheelAngleEst")
    assert (s.minimum, s.maximum) == ranges.ABS_ANGLE
    for sig, rng in (("VehicleSpeed", ranges.PLANT_ABS_SPEED), ("FrontWheelAngle", ranges.PLANT_ABS_ANGLE),
                     ("MasterPressure", ranges.PLANT_ABS_PRESSURE)):
        s = _signal(bench, "PLANT_AbsVehicle", sig)
        assert (s.minimum, s.maximum) == rng, sig
    assert chassis.get_message_by_name("ABS_SteerState").cycle_time == abs_ecu.OUTPUT_PERIOD_MS
    assert {int(k): str(v) for k, v in _signal(chassis, "ABS_SteerState", "PressureStateFL").choices.items()} == \
        {0: "HOLD", 1: "INCREASE", 2: "DECREASE"}
    assert {int(k): str(v) for k, v in _signal(chassis, "ABS_SteerState", "AbsFault").choices.items()} == \
        {f.value: f.name for f in abs_ecu.AbsFault}
