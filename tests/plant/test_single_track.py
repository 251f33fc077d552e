"""plant/single_track.py: the linear 2-DOF model of docs/spec/formulas.md §5.

- Cross-check against commonroad-vehicle-models' single-track model ST (docs/spec/vehicles.md B, "Independent
  cross-checks"): BMW 320i (vehicle 2), 50 km/h, road-wheel step 0.040107 rad; with its cornering stiffnesses
  per unit load equal front and rear the car is neutral (K = 0) and the ST model is the same linear model:
  the yaw rates agree within 1e-4 relative over 2 s (they do to about 1e-8).
- Steady-state gains against the closed forms of §5 for K ≠ 0 (the A-class car of docs/spec/vehicles.md B), typed here
  independently of the plant, and the 4WS steady state (rear input) as another engineer will use it.
- Exactness and stability of the discretisation, the kinematic regime below 1 m/s, bad input.
"""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plant.single_track import KINEMATIC_SPEED, SingleTrack, SingleTrackParams

# docs/spec/vehicles.md B, written out (not read from plant/vehicles)
M, IZ, A, B, CF, CR = 1350.0, 2050.0, 1.06, 1.59, 85000.0, 120000.0
L = A + B
ACLASS = SingleTrackParams(M, IZ, A, B, CF, CR)
K_ACLASS = M / L ** 2 * (B / CF - A / CR)      # docs/spec/formulas.md §5


def _rk4_reference(params: SingleTrackParams, u: float, delta_f: float, delta_r: float, t_end: float,
                   h: float = 1e-5) -> tuple[float, float]:
    """(β, r) at t_end from rest, the §5 equations integrated with RK4 at a tiny step (independent of the
    model's exact discretisation)."""
    m, iz, a, b, cf, cr = params.mass, params.yaw_inertia, params.a, params.b, params.cf, params.cr

    def f(beta: float, r: float) -> tuple[float, float]:
        fyf = cf * (delta_f - beta - a * r / u)
        fyr = cr * (delta_r - beta + b * r / u)
        return (fyf + fyr) / (m * u) - r, (a * fyf - b * fyr) / iz

    beta = r = 0.0
    for _ in range(round(t_end / h)):
        k1 = f(beta, r)
        k2 = f(beta + 0.5 * h * k1[0], r + 0.5 * h * k1[1])
        k3 = f(beta + 0.5 * h * k2[0], r + 0.5 * h * k2[1])
        k4 = f(beta + h * k3[0], r + h * k3[1])
        beta += h / 6.0 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
        r += h / 6.0 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
    return beta, r


# -- commonroad cross-check ---------------------------------------------------------------------------------

def test_commonroad_st_model_bmw320i_step_at_50kmh() -> None:
    pytest.importorskip("vehiclemodels", reason="pip install commonroad-vehicle-models (the 'test' extra)")
    from vehiclemodels.parameters_vehicle2 import parameters_vehicle2
    from vehiclemodels.vehicle_dynamics_st import vehicle_dynamics_st

    p = parameters_vehicle2()
    g = 9.81                                          # as vehicle_dynamics_st
    mu = p.tire.p_dy1                                 # its friction coefficient ...
    c_s = -p.tire.p_ky1 / p.tire.p_dy1                # ... and cornering stiffness per unit load, front = rear
    wheelbase = p.a + p.b
    cf = mu * c_s * p.m * g * p.b / wheelbase         # axle cornering stiffness = μ C_S × static axle load
    cr = mu * c_s * p.m * g * p.a / wheelbase
    params = SingleTrackParams(p.m, p.I_z, p.a, p.b, cf, cr)
    assert params.stability_factor == pytest.approx(0.0, abs=1e-12)       # neutral steer (docs/spec/vehicles.md)

    u, delta, duration, dt = 50.0 / 3.6, 0.040107, 2.0, 1e-3
    # the ST model's own right-hand side, integrated with RK4 at 0.1 ms (|λ| h ≈ 1e-3: error ~1e-13)
    x = [0.0, 0.0, delta, u, 0.0, 0.0, 0.0]           # x, y, δ, v, ψ, ψ̇, β: the step is already in
    h, sub = 1e-4, 10

    def rhs(state: list[float]) -> list[float]:
        return vehicle_dynamics_st(state, [0.0, 0.0], p)

    reference = []
    for _ in range(round(duration / dt)):
        for _ in range(sub):
            k1 = rhs(x)
            k2 = rhs([xi + 0.5 * h * ki for xi, ki in zip(x, k1)])
            k3 = rhs([xi + 0.5 * h * ki for xi, ki in zip(x, k2)])
            k4 = rhs([xi + h * ki for xi, ki in zip(x, k3)])
            x = [xi + h / 6.0 * (a1 + 2 * a2 + 2 * a3 + a4) for xi, a1, a2, a3, a4 in zip(x, k1, k2, k3, k4)]
        reference.append(x[5])
    model = SingleTrack(params, u)
    worst = 0.0
    for r_ref in reference:
        model.step(dt, delta)
        worst = max(worst, abs(model.yaw_rate - r_ref) / abs(reference[-1]))
    assert worst < 1e-4, worst
    # docs/spec/vehicles.md B's figures for this set: steady 0.21600 rad/s, a_y 3.000 m/s², 90 % at 0.148 s
    assert model.yaw_rate == pytest.approx(0.21600, abs=5e-5)
    assert model.lat_accel == pytest.approx(3.000, abs=2e-3)
    probe = SingleTrack(params, u)
    t = 0.0
    while probe.yaw_rate < 0.9 * model.yaw_rate:
        probe.step(1e-4, delta)
        t += 1e-4
    assert t == pytest.approx(0.148, abs=1.5e-3)


# -- steady state against the closed forms (K ≠ 0) ---------------------------------------------------------

def test_aclass_stability_factor_and_vehicles_md_figures() -> None:
    assert ACLASS.stability_factor == pytest.approx(K_ACLASS)
    assert ACLASS.stability_factor == pytest.approx(1.90e-3, rel=5e-3)               # docs/spec/vehicles.md B
    assert ACLASS.characteristic_speed * 3.6 == pytest.approx(82.6, abs=0.1)         # docs/spec/vehicles.md B
    assert ACLASS.yaw_rate_gain(50 / 3.6) == pytest.approx(3.84, abs=0.005)          # docs/spec/vehicles.md B


@settings(max_examples=40, deadline=None)
@given(u=st.floats(2.0, 60.0), delta=st.floats(-0.1, 0.1).filter(lambda d: abs(d) > 1e-4))
def test_steady_state_matches_closed_forms(u: float, delta: float) -> None:
    """r/δ_f = (u/L)/(1 + K u²), β/δ_f = (b/L − m a u²/(C_r L²))/(1 + K u²), a_y = u r (docs/spec/formulas.md §5)."""
    beta, r, ay = ACLASS.steady_state(u, delta)
    denominator = 1.0 + K_ACLASS * u * u
    assert r == pytest.approx(delta * (u / L) / denominator, rel=1e-9)
    assert beta == pytest.approx(delta * (B / L - M * A * u * u / (CR * L * L)) / denominator, rel=1e-9, abs=1e-15)
    assert ay == pytest.approx(u * r, rel=1e-12)


@pytest.mark.parametrize("kmh", [20.0, 50.0, 100.0, 150.0])
def test_stepping_settles_to_the_closed_form(kmh: float) -> None:
    u, delta = kmh / 3.6, math.radians(2.0)
    model = SingleTrack(ACLASS, u)
    for _ in range(5000):
        model.step(1e-3, delta)
    gain = (u / L) / (1.0 + K_ACLASS * u * u)
    assert model.yaw_rate / delta == pytest.approx(gain, rel=1e-6)
    assert model.lat_accel == pytest.approx(u * model.yaw_rate, rel=1e-6)
    assert model.front_lateral_force * A == pytest.approx(model.rear_lateral_force * B, rel=1e-6)   # ṙ = 0


@settings(max_examples=25, deadline=None)
@given(u=st.floats(3.0, 50.0), delta_f=st.floats(-0.08, 0.08), ratio=st.floats(-1.0, 1.0))
def test_four_wheel_steering_steady_state(u: float, delta_f: float, ratio: float) -> None:
    """With a rear input the steady yaw rate depends on δ_f − δ_r only: r = u (δ_f − δ_r)/(L (1 + K u²))
    (derived from §5), and the zero-sideslip ratio k(u) of docs/spec/formulas.md §5 gives β = 0."""
    delta_r = ratio * delta_f
    beta, r, _ = ACLASS.steady_state(u, delta_f, delta_r)
    assert r == pytest.approx(u * (delta_f - delta_r) / (L * (1.0 + K_ACLASS * u * u)), rel=1e-9, abs=1e-15)
    k = (-B + M * A * u * u / (CR * L)) / (A + M * B * u * u / (CF * L))
    beta0, _, _ = ACLASS.steady_state(u, delta_f, k * delta_f)
    assert beta0 == pytest.approx(0.0, abs=1e-12)


def test_zero_sideslip_ratio_changes_sign_at_vehicles_md_speed() -> None:
    """docs/spec/vehicles.md B: k = −0.46 at 40 km/h, +0.22 at 100 km/h, sign change at 67.7 km/h; checked on the
    model."""
    def k_from_model(kmh: float) -> float:
        u = kmh / 3.6
        b_f, _, _ = ACLASS.steady_state(u, 1.0, 0.0)
        b_r, _, _ = ACLASS.steady_state(u, 0.0, 1.0)
        return -b_f / b_r                          # the δ_r/δ_f that cancels β (linear superposition)
    assert k_from_model(40.0) == pytest.approx(-0.46, abs=0.01)
    assert k_from_model(100.0) == pytest.approx(0.22, abs=0.01)
    assert k_from_model(67.6) < 0.0 < k_from_model(67.8)


# -- discretisation, regimes, inputs -------------------------------------------------------------------------

@pytest.mark.parametrize("u, dt", [(1.5, 1e-3), (1.5, 0.05), (13.89, 1e-3), (40.0, 0.02)])
def test_exact_discretisation_against_fine_rk4(u: float, dt: float) -> None:
    """Exact for inputs held over a step, whatever the step (even 50 ms at 1.5 m/s where |λ| dt ≈ 7)."""
    model = SingleTrack(ACLASS, u)
    t_end = 0.4
    for _ in range(round(t_end / dt)):
        model.step(dt, 0.03, -0.01)
    beta, r = _rk4_reference(ACLASS, u, 0.03, -0.01, t_end)
    assert model.beta == pytest.approx(beta, rel=1e-7, abs=1e-12)
    assert model.yaw_rate == pytest.approx(r, rel=1e-7, abs=1e-12)


def test_kinematic_regime_below_one_metre_per_second() -> None:
    model = SingleTrack(ACLASS, 0.5)
    assert model.kinematic and KINEMATIC_SPEED == 1.0
    model.step(1e-3, 0.2)
    assert model.yaw_rate == pytest.approx(0.5 * 0.2 / L)
    assert model.beta == pytest.approx(B * 0.2 / L)
    assert model.lat_accel == pytest.approx(0.5 * model.yaw_rate)
    standstill = SingleTrack(ACLASS, 0.0)
    standstill.step(1e-3, 0.3)
    assert (standstill.yaw_rate, standstill.lat_accel, standstill.front_slip_angle) == (0.0, 0.0, 0.0)


def test_yaw_angle_integrates_the_yaw_rate() -> None:
    model = SingleTrack(ACLASS, 20.0)
    for _ in range(3000):
        model.step(1e-3, 0.02)
    assert model.yaw_angle == pytest.approx(model.yaw_rate * 3.0, rel=0.1)     # settles within ~0.5 s


def test_bad_input_is_refused_with_a_clear_error() -> None:
    with pytest.raises(ValueError, match="speed"):
        SingleTrack(ACLASS, -1.0)
    with pytest.raises(ValueError, match="speed"):
        SingleTrack(ACLASS, math.nan)
    with pytest.raises(ValueError, match="cf"):
        SingleTrackParams(M, IZ, A, B, 0.0, CR)
    with pytest.raises(ValueError, match="mass"):
        SingleTrackParams(math.inf, IZ, A, B, CF, CR)
