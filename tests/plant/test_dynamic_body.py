"""The EV's dynamics at speed (plant/dynamic_body.py) and [P3]'s rear-steering laws (plant/ecus/rear_steer.py,
the VCU's ADAPTIVE mode), without the bus.

Expected values are the closed forms of docs/spec/formulas.md §5 written out here, and plant/single_track.py (another
implementation of §5: exact zero-order-hold discretisation) for the transient.
"""

from __future__ import annotations

import math

import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from bench.sim.testing import CodedSide, MemoryIO
from plant import signal_ranges as ranges
from plant.dynamic_body import (
    DYNAMIC_OFF_SPEED,
    DYNAMIC_ON_SPEED,
    GRAVITY,
    LINEAR_FRACTION,
    MU_MIN,
    EvBodyNode,
    LateralDynamics,
    SaturatingTyre,
    VehicleBody,
    ev_single_track,
)
from plant.ecus.rear_steer import SeedLaws, Strategy
from plant.ecus.vcu import Vcu, VcuFault
from plant.factory import assemble
from plant.single_track import SingleTrack
from plant.vehicles import load_parameters

DT = 1e-3


P = load_parameters("EV4WIS")
M, IZ, A, B, CF, CR = 900.0, 1100.0, 1.38, 1.38, 45000.0, 55000.0      # docs/spec/vehicles.md A
WB = A + B
KS = M / WB ** 2 * (B / CF - A / CR)                                      # §5 stability factor
RPM_PER_MPS = 30.0 / (math.pi * 0.281)


def closed_form(u: float, df: float, dr: float) -> tuple[float, float]:
    """§5 steady state (sideslip, yaw rate) for front/rear angles (any consistent sign convention):
    r = (u/L)(δ_f − δ_r)/(1 + K u²);  β = [(b − m a u²/(C_r L)) δ_f + (a + m b u²/(C_f L)) δ_r] / (L (1 + K u²))."""
    den = 1.0 + KS * u * u
    r = u / WB * (df - dr) / den
    beta = ((B - M * A * u * u / (CR * WB)) * df + (A + M * B * u * u / (CF * WB)) * dr) / (WB * den)
    return beta, r


def settle(model: LateralDynamics, u: float, df: float, dr: float, seconds: float = 4.0) -> None:
    for _ in range(round(seconds / DT)):
        model.step(DT, u, df, dr)


# -- tyre ---------------------------------------------------------------------------------------------------

@given(alpha=st.floats(-0.5, 0.5), mu=st.floats(0.05, 1.5))
def test_tyre_is_odd_linear_then_bounded(alpha: float, mu: float) -> None:
    tyre = SaturatingTyre(CF, 4415.0, mu)
    f = tyre.force(alpha)
    assert tyre.force(-alpha) == pytest.approx(-f, abs=1e-9)
    assert abs(f) < mu * 4415.0 + 1e-9
    if abs(CF * alpha) <= LINEAR_FRACTION * mu * 4415.0:
        assert f == pytest.approx(CF * alpha, abs=1e-9)
    else:
        assert abs(f) < abs(CF * alpha) and abs(f) >= LINEAR_FRACTION * mu * 4415.0 - 1e-9


def test_tyre_joint_is_smooth_and_saturates() -> None:
    tyre = SaturatingTyre(CF, 4415.0, 1.0)
    knee = LINEAR_FRACTION * 4415.0 / CF
    eps = 1e-7
    assert tyre.force(knee + eps) == pytest.approx(tyre.force(knee - eps), abs=1e-2)
    assert tyre.slope(knee + eps) == pytest.approx(CF, rel=1e-4)
    assert tyre.force(1.0) == pytest.approx(4415.0, rel=1e-6)        # far beyond the knee: μ F_z
    assert tyre.slope(1.0) < 1e-3 * CF
    with pytest.raises(ValueError, match="road friction"):
        tyre.set_mu(math.nan)


# -- the model in its linear range against §5 --------------------------------------------------------------

@settings(max_examples=15, deadline=None)
@given(kmh=st.floats(25.0, 130.0), df_deg=st.floats(-1.0, 1.0), ratio=st.floats(-1.0, 1.0))
def test_steady_state_is_the_closed_form(kmh: float, df_deg: float, ratio: float) -> None:
    """Small angles (a_y well below 0.5 μ g): the linear range, where the §5 closed forms hold exactly."""
    u = kmh / 3.6
    df, dr = math.radians(df_deg), math.radians(df_deg) * ratio
    beta, r = closed_form(u, df, dr)
    assume(abs(u * r) < 0.9 * LINEAR_FRACTION * GRAVITY)      # the linear range of the tyres (a = b: equal loads)
    model = LateralDynamics(ev_single_track(P))
    settle(model, u, df, dr)
    assert abs(model.lat_accel) < LINEAR_FRACTION * GRAVITY
    assert model.w / u == pytest.approx(beta, abs=1e-9 + 1e-6 * abs(beta))     # §5's β is w/u (linearised)
    assert model.omega == pytest.approx(r, abs=1e-7 + 1e-5 * abs(r))
    assert model.lat_accel == pytest.approx(u * r, abs=1e-5 + 1e-5 * abs(u * r))


def test_transient_agrees_with_plant_single_track() -> None:
    """A 1° front-wheel step at 80 km/h: Heun at 1 ms against the exact discretisation of plant/single_track.py
    (ISO signs there: every angle and rate flips)."""
    u = 80.0 / 3.6
    ours = LateralDynamics(ev_single_track(P))
    theirs = SingleTrack(ev_single_track(P), u)
    df = math.radians(1.0)
    worst_r = worst_b = 0.0
    for _ in range(1500):
        ours.step(DT, u, df, 0.0)
        theirs.step(DT, -df, 0.0)
        worst_r = max(worst_r, abs(ours.omega + theirs.yaw_rate))
        worst_b = max(worst_b, abs(ours.w / u + theirs.beta))
    r_ss = closed_form(u, df, 0.0)[1]
    assert worst_r < 1e-5 * r_ss and worst_b < 1e-5 * r_ss


def test_saturation_caps_lateral_acceleration_and_understeers() -> None:
    """On μ = 0.3 the lateral acceleration never exceeds μ g however far the wheels are steered, and the
    steady yaw rate falls below the linear model's (the front axle, with the larger slip angle, saturates)."""
    u = 80.0 / 3.6
    model = LateralDynamics(ev_single_track(P), mu=0.3)
    previous = 0.0
    for df_deg in (0.5, 1.0, 2.0, 4.0, 8.0):
        settle(model, u, math.radians(df_deg), 0.0, 3.0)
        assert model.lat_accel < 0.3 * GRAVITY
        assert model.lat_accel >= previous - 1e-9
        previous = model.lat_accel
    assert previous > 0.9 * 0.3 * GRAVITY
    assert model.omega < 0.5 * closed_form(u, math.radians(8.0), 0.0)[1]


# -- regimes ------------------------------------------------------------------------------------------------

def _straight(v: float, angle: float = 0.0) -> tuple[list[float], list[float]]:
    return [angle] * 4, [v * RPM_PER_MPS] * 4


def test_regime_switching_with_hysteresis() -> None:
    body = VehicleBody(P)
    body.advance(*_straight(4.0), DT)
    assert not body.dynamic                                             # [P0]'s U-turn speed: kinematic
    body.advance(*_straight(DYNAMIC_ON_SPEED), DT)
    assert body.dynamic
    for _ in range(200):                              # the body's speed follows at most μ g (PLANT-DYN-03)
        body.advance(*_straight(0.5 * (DYNAMIC_ON_SPEED + DYNAMIC_OFF_SPEED)), DT)
    assert body.dynamic                                                 # hysteresis
    for _ in range(200):
        body.advance(*_straight(DYNAMIC_OFF_SPEED - 0.01), DT)
    assert not body.dynamic
    body.advance(*_straight(10.0, 27.0), DT)                            # crab at 27°: not car-like
    assert not body.dynamic
    body.advance(*_straight(10.0, 20.0), DT)
    assert body.dynamic
    angles, speeds = _straight(10.0)
    speeds[3] = -1.0                                                    # a wheel rolling backwards
    body.advance(angles, speeds, DT)
    assert not body.dynamic


def test_leaving_the_dynamic_regime_has_no_acceleration_spike() -> None:
    body = VehicleBody(P)
    angles = [2.0, 2.0, 0.0, 0.0]
    for _ in range(2000):
        body.advance(angles, [6.0 * RPM_PER_MPS] * 4, DT)
    assert body.dynamic and body.sideslip_deg != 0.0
    lat = body.lat_accel
    for _ in range(1000):                             # the body slides down to the wheels at μ g (PLANT-DYN-03)
        body.advance(angles, [4.0 * RPM_PER_MPS] * 4, DT)
        if not body.dynamic:
            break
    assert not body.dynamic
    assert abs(body.lat_accel) < 2.0 * abs(lat) + 1.0                          # centripetal only, no jump / dt


def test_road_mu_is_taken_at_scenario_start() -> None:
    behaviours = assemble("EV4WIS", ())
    (plant,) = [b for b in behaviours if b.nodes == ("PLANT",)]
    assert isinstance(plant, EvBodyNode)
    io = MemoryIO(ranges.BY_SIGNAL)
    io.values["DRV_MotionRequest"] = {"DriveMode": 2, "PivotX": 0.0, "PivotY": 0.0, "TargetSpeed": 22.22}
    io.values["DRV_Steering"] = {"HandWheelAngle": 0.0, "HandWheelRate": 0.0, "DriverTorque": 0.0}
    io.values["BENCH_Control"] = {"ScenarioId": 3, "RoadMu": 0.3, "InitialSpeed": 22.22, "SensorNoise": 0.0,
                                  "Vehicle": 0}

    def run(seconds: float) -> None:
        for _ in range(round(seconds / DT)):
            io.t += DT
            for b in behaviours:
                b.step(io, io.t, DT)

    run(0.05)
    assert plant.body.dynamics.front.mu == 0.3 and plant.body.dynamic
    assert io.values["PLANT_Motion"]["Speed"] == pytest.approx(22.22, rel=1e-3)
    io.values["BENCH_Control"].update(ScenarioId=4, RoadMu=math.nan)
    run(DT)
    assert plant.body.dynamics.front.mu == 1.0
    io.values["BENCH_Control"].update(ScenarioId=5, RoadMu=0.0)
    run(DT)
    assert plant.body.dynamics.front.mu == MU_MIN


# -- [P3] §2 laws --------------------------------------------------------------------------------------

def k_of_u(u: float) -> float:
    """docs/spec/formulas.md §5: k(u) = (−b + m a u²/(C_r L)) / (a + m b u²/(C_f L))."""
    return (-B + M * A * u * u / (CR * WB)) / (A + M * B * u * u / (CF * WB))


def test_feedforward_ratio_and_feedback_gain() -> None:
    laws = SeedLaws(P)
    u0 = math.sqrt(B * CR * WB / (M * A))
    assert laws.ratio(u0) == pytest.approx(0.0, abs=1e-12)
    for u in (5.0, 11.11, 22.22, 27.78, 40.0):
        assert laws.ratio(u) == pytest.approx(k_of_u(u), rel=1e-12)
    assert laws.c1 == 1.0 and laws.c2 == pytest.approx(M * B / (CF * WB) + M * A / (CR * WB))
    assert laws.rear_angle(Strategy.OFF, 2.0, 20.0, 5.0) == 0.0
    assert laws.rear_angle(Strategy.FEEDBACK, 2.0, 20.0, 5.0) == pytest.approx(-2.0 + laws.c2 * 20.0 * 5.0)
    assert laws.rear_angle(Strategy.FEEDBACK, 2.0, 20.0, None) == pytest.approx(k_of_u(20.0) * 2.0)


@pytest.mark.parametrize("kmh", [30.0, 60.0, 100.0])
def test_feedback_law_zeroes_sideslip_and_gives_the_closed_loop_gain(kmh: float) -> None:
    """δ_r = −δ_f + C2 u r in closed loop with the model (no delay): steady β = 0 (a = b) and
    r/δ_f = (u/L)(1 + C1)/(1 + K u² + C2 u²/L) (docs/spec/formulas.md §5)."""
    u = kmh / 3.6
    laws = SeedLaws(P)
    model = LateralDynamics(ev_single_track(P))
    df = math.radians(0.5)
    for _ in range(5000):
        dr = -df + laws.c2 * u * model.omega
        model.step(DT, u, df, dr)
    c2 = M * B / (CF * WB) + M * A / (CR * WB)
    assert model.w / u == pytest.approx(0.0, abs=1e-7)
    assert model.omega / df == pytest.approx(u / WB * 2.0 / (1.0 + KS * u * u + c2 * u * u / WB), rel=1e-6)


# -- the VCU's coding --------------------------------------------------------------------------------------

def _vcu_rear(config: dict[str, float] | None, imu: dict[str, float] | None = None,
              speed: float = 22.22) -> tuple[VcuFault, float, float]:
    io = MemoryIO(ranges.BY_SIGNAL)
    io.values["DRV_MotionRequest"] = {"DriveMode": 2, "PivotX": 0.0, "PivotY": 0.0, "TargetSpeed": speed}
    io.values["DRV_Steering"] = {"HandWheelAngle": 30.0, "HandWheelRate": 0.0, "DriverTorque": 0.0}
    if config is not None:   # the VCU's coding (docs/contract/vcu.md VCU-DIAG-02)
        io.diagnostic_sides["VCU"] = CodedSide(config)
    if imu is not None:
        io.values["IMU_Motion"] = imu
    vcu = Vcu(P)
    fault, plan = vcu.decide(io)
    if plan is None:
        return fault, math.nan, math.nan
    return fault, 0.5 * (plan.angles[0] + plan.angles[1]), 0.5 * (plan.angles[2] + plan.angles[3])


def test_vcu_rear_law_from_bench_vcu_config() -> None:
    u = 22.22
    fault, front, rear = _vcu_rear({"RearSteerLaw": 0})
    assert fault == VcuFault.OK and rear == 0.0 and front == pytest.approx(2.0, abs=1e-3)
    fault, front, rear = _vcu_rear({"RearSteerLaw": 1})
    assert rear == pytest.approx(k_of_u(u) * 2.0, abs=1e-3)
    assert _vcu_rear(None)[2] == pytest.approx(rear)                        # absent: FEEDFORWARD
    c2 = M * B / (CF * WB) + M * A / (CR * WB)
    fault, front, rear = _vcu_rear({"RearSteerLaw": 2}, {"YawRate": 4.0, "LatAccel": 0.0, "LongAccel": 0.0})
    assert rear == pytest.approx(-2.0 + c2 * u * 4.0, abs=1e-3)
    assert _vcu_rear({"RearSteerLaw": 2})[2] == pytest.approx(k_of_u(u) * 2.0, abs=1e-3)   # no IMU: FF
    assert _vcu_rear({"RearSteerLaw": 3})[0] == VcuFault.REQUEST_INVALID
    assert _vcu_rear({"RearSteerLaw": 0}, speed=5.0)[2] == pytest.approx(-2.0, abs=0.01)  # < 20 km/h: -X
