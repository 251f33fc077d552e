"""Test oracle of the steer-by-wire cases: the linear 2-DOF model of docs/spec/formulas.md §5 and the ISO 7401 metrics,
written here independently of `plant/` (own numbers, own integrator, numpy only).

Vehicle: docs/spec/vehicles.md B (the A-class car). Signs: docs/spec/formulas.md §5 is written ISO left-positive; a
linear model is odd, so the same formulas hold in the bus convention (positive to the right) for every angle,
yaw rate and lateral acceleration together, which is how the cases use them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

# -- docs/spec/vehicles.md B ------------------------------------------------------------------------------------
MASS = 1350.0              # m, kg
YAW_INERTIA = 2050.0       # I_z, kg·m²
A = 1.06                   # CoG to front axle, m
B = 1.59                   # CoG to rear axle, m
WHEELBASE = A + B          # L = 2.65 m
C_F = 85000.0              # front axle cornering stiffness, N/rad
C_R = 120000.0             # rear axle cornering stiffness, N/rad
STEERING_RATIO = 15.0      # hand-wheel (and pinion) angle per road-wheel angle

_DEG = 180.0 / math.pi


def stability_factor() -> float:
    """K_s = m/L² (b/C_f − a/C_r), s²/m² (docs/spec/formulas.md §5); docs/spec/vehicles.md B quotes 1.90e-3."""
    return MASS / WHEELBASE ** 2 * (B / C_F - A / C_R)


def yaw_gain(u: float) -> float:
    """Steady r/δ_f = (u/L)/(1 + K_s u²), 1/s (docs/spec/formulas.md §5)."""
    return (u / WHEELBASE) / (1.0 + stability_factor() * u * u)


def plain_yaw_per_hand_wheel(u: float) -> float:
    """Steady r/θ_h of the plain car at the fixed ratio 15 (mechanical steering), 1/s."""
    return yaw_gain(u) / STEERING_RATIO


def hand_wheel_for_lat_accel(u: float, lat_accel: float) -> float:
    """Hand-wheel angle (deg) of the plain 15:1 car for a steady lateral acceleration: a_y = u r,
    r = yaw_gain(u) δ_f, θ_h = 15 δ_f (docs/spec/vehicles.md B: about 48° for 3 m/s² at 50 km/h)."""
    return STEERING_RATIO * lat_accel / (u * yaw_gain(u)) * _DEG


def state_matrices(u: float) -> tuple[np.ndarray, np.ndarray]:
    """A (2×2) and b (2) of ẋ = A x + b δ_f, x = (β, r), from the §5 equations divided out."""
    a = np.array([[-(C_F + C_R) / (MASS * u), -1.0 + (B * C_R - A * C_F) / (MASS * u * u)],
                  [(B * C_R - A * C_F) / YAW_INERTIA, -(A * A * C_F + B * B * C_R) / (YAW_INERTIA * u)]])
    b = np.array([C_F / (MASS * u), A * C_F / YAW_INERTIA])
    return a, b


def simulate(u: float, t: np.ndarray, delta_f: np.ndarray, h: float = 1e-3) -> tuple[np.ndarray, np.ndarray]:
    """Yaw rate r(t) and lateral acceleration a_y(t) = u (β̇ + r) of the §5 model (rad, rad/s, m/s²) driven
    by the road-wheel angle δ_f(t) (linear interpolation between the samples, held before the first), from
    rest, integrated with classical RK4 at step h (|λ| h ≈ 0.02 at 50 km/h: local error ~1e-11) and
    sampled at `t`. Plain floats: this runs in every case."""
    (a00, a01), (a10, a11) = state_matrices(u)[0].tolist()
    b0, b1 = state_matrices(u)[1].tolist()
    t = np.asarray(t, dtype=float)
    grid = np.arange(t[0], t[-1] + h, h)
    d = np.interp(grid, t, np.asarray(delta_f, dtype=float)).tolist()
    beta = r = 0.0
    n = len(d)
    rs, ays = [0.0] * n, [0.0] * n
    half = 0.5 * h
    for k in range(n):
        dk = d[k]
        k1b = a00 * beta + a01 * r + b0 * dk
        k1r = a10 * beta + a11 * r + b1 * dk
        rs[k], ays[k] = r, u * (k1b + r)
        if k + 1 == n:
            break
        dn = d[k + 1]
        dm = 0.5 * (dk + dn)
        bb, rr = beta + half * k1b, r + half * k1r
        k2b = a00 * bb + a01 * rr + b0 * dm
        k2r = a10 * bb + a11 * rr + b1 * dm
        bb, rr = beta + half * k2b, r + half * k2r
        k3b = a00 * bb + a01 * rr + b0 * dm
        k3r = a10 * bb + a11 * rr + b1 * dm
        bb, rr = beta + h * k3b, r + h * k3r
        k4b = a00 * bb + a01 * rr + b0 * dn
        k4r = a10 * bb + a11 * rr + b1 * dn
        beta += h / 6.0 * (k1b + 2.0 * k2b + 2.0 * k3b + k4b)
        r += h / 6.0 * (k1r + 2.0 * k2r + 2.0 * k3r + k4r)
    return np.interp(t, grid, rs), np.interp(t, grid, ays)


# -- ISO 7401 (lateral transient response, step steer) ------------------------------------------------------

@dataclass(frozen=True)
class StepMetrics:
    """ISO 7401 step-steer figures of one response: times from the instant the hand wheel reaches 50 % of
    its final angle; response time to 90 % of the steady value, peak response time to the first maximum,
    overshoot (peak − steady)/steady."""

    steady: float
    response_time: float
    peak_time: float
    overshoot: float


def crossing_time(t: np.ndarray, y: np.ndarray, level: float, after: float = -math.inf) -> float:
    """First time after `after` at which y reaches `level` (rising for a positive level, falling for a
    negative one), interpolated linearly between samples; NaN when it never does."""
    t, y = np.asarray(t, dtype=float), np.asarray(y, dtype=float)
    sign = 1.0 if level >= 0.0 else -1.0
    ys, lv = y * sign, level * sign
    for i in range(len(t)):
        if t[i] < after or ys[i] < lv:
            continue
        if i == 0 or ys[i - 1] >= lv or t[i - 1] < after:
            return float(t[i])
        return float(t[i - 1] + (lv - ys[i - 1]) / (ys[i] - ys[i - 1]) * (t[i] - t[i - 1]))
    return math.nan


def step_metrics(t_in: np.ndarray, hand_wheel: np.ndarray, t_out: np.ndarray, response: np.ndarray,
                 steady_window: float = 0.5) -> StepMetrics:
    """ISO 7401 metrics of `response` to a hand-wheel step; the final hand-wheel angle and the steady
    response are the means over the last `steady_window` s."""
    t_in, hand_wheel = np.asarray(t_in, float), np.asarray(hand_wheel, float)
    t_out, response = np.asarray(t_out, float), np.asarray(response, float)
    final = float(np.mean(hand_wheel[t_in >= t_in[-1] - steady_window]))
    t0 = crossing_time(t_in, hand_wheel, 0.5 * final)
    return _metrics(t0, t_out, response, steady_window)


def _metrics(t0: float, t: np.ndarray, response: np.ndarray, steady_window: float) -> StepMetrics:
    steady = float(np.mean(response[t >= t[-1] - steady_window]))
    t90 = crossing_time(t, response, 0.9 * steady)
    after = t >= t0
    sign = 1.0 if steady >= 0.0 else -1.0
    idx = int(np.argmax(response[after] * sign))
    peak = float(response[after][idx])
    return StepMetrics(steady, t90 - t0, float(t[after][idx]) - t0, (peak - steady) / steady)


def ideal_step_metrics(u: float, duration: float = 3.0, h: float = 2.5e-4) -> StepMetrics:
    """ISO 7401 metrics of the §5 yaw-rate response to an instantaneous road-wheel step at t = 0 (the
    transfer function itself, without steering dynamics)."""
    t = np.arange(0.0, duration, h)
    r, _ = simulate(u, t, np.ones_like(t), h)
    return _metrics(0.0, t, r, 0.5)


# -- periodic signals -----------------------------------------------------------------------------------------

def sine_fit(t: np.ndarray, y: np.ndarray, frequency: float) -> tuple[float, float]:
    """(amplitude, phase rad) of the least-squares fit y ≈ A sin(2π f t + φ) + c."""
    w = 2.0 * math.pi * frequency
    t = np.asarray(t, float)
    design = np.column_stack([np.sin(w * t), np.cos(w * t), np.ones_like(t)])
    (s, c, _), *_ = np.linalg.lstsq(design, np.asarray(y, float), rcond=None)
    return math.hypot(s, c), math.atan2(c, s)


def phase_lag_deg(t_ref: np.ndarray, ref: np.ndarray, t_out: np.ndarray, out: np.ndarray, frequency: float) -> float:
    """How far `out` lags `ref` at `frequency`, deg (positive = behind), wrapped to (−180, 180]."""
    _, p_ref = sine_fit(t_ref, ref, frequency)
    _, p_out = sine_fit(t_out, out, frequency)
    lag = math.degrees(p_ref - p_out)
    return (lag + 180.0) % 360.0 - 180.0 if lag != 180.0 else 180.0


def is_monotonic_increasing(x: np.ndarray, y: np.ndarray, bin_width: float,
                            slack: float) -> tuple[bool, list[tuple[float, float]]]:
    """Means of y in consecutive bins of x; True when each bin's mean exceeds the previous one by more than
    −slack (slack: the resolution of y on the bus). Returns the (bin centre, mean) pairs too."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    edges = np.arange(math.floor(x.min() / bin_width) * bin_width, x.max() + bin_width, bin_width)
    means = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        sel = (x >= lo) & (x < hi)
        if sel.sum() >= 3:
            means.append((0.5 * (lo + hi), float(np.mean(y[sel]))))
    ok = len(means) >= 2 and all(b[1] > a[1] - slack for a, b in zip(means, means[1:]))
    return ok, means


# -- the steering robot (docs/contract/sbw.md, plant.md PLANT-IO-SBW-07), restated --------------------------------
ROBOT_RATE_LIMIT = 400.0       # deg/s, RobotAngle is rate limited to this first
ROBOT_NATURAL_FREQUENCY = 60.0  # rad/s, then a critically damped second-order filter
ROBOT_ANGLE_PERIOD = 0.01      # s, BENCH_SteeringRobot's cycle: RobotAngle is a staircase of this step
ROBOT_SUBSTEP = 0.25e-3        # s, the plant integrates the robot at its 4 kHz substep (PLANT-IO-SBW-07)


def robot_sine_amplitude(amplitude: float, frequency: float) -> float:
    """Amplitude (deg) of the hand wheel the robot imposes for a RobotAngle sine of `amplitude` deg at `frequency`
    Hz sent every ROBOT_ANGLE_PERIOD: the staircase's fundamental, A sin(ωT/2) / (ωT/2) (a zero-order hold of T),
    through the filter ω_n² / (s + ω_n)², |H(jω)| = 1 / (1 + (ω/ω_n)²), integrated at ROBOT_SUBSTEP h, which
    lowers it by ω² h / ω_n more (first order in h). The rate limit leaves the sine itself alone while its peak
    rate 2π f A stays below it (ValueError otherwise: the response is then no longer linear); it only ramps each
    step of the staircase (sbw.md SBW-CTL-03 bounds that in the tolerance)."""
    w = 2.0 * math.pi * frequency
    if w * amplitude >= ROBOT_RATE_LIMIT:
        raise ValueError(f"a {amplitude:g} deg sine at {frequency:g} Hz turns at {w * amplitude:.0f} deg/s, "
                         f"beyond the robot's rate limit {ROBOT_RATE_LIMIT:g} deg/s")
    half = w * ROBOT_ANGLE_PERIOD / 2.0
    integration = 1.0 - w * w * ROBOT_SUBSTEP / ROBOT_NATURAL_FREQUENCY
    return amplitude * (math.sin(half) / half) / (1.0 + (w / ROBOT_NATURAL_FREQUENCY) ** 2) * integration
