"""A closed-loop path-following driver for the manoeuvres of the 4WS cases: the test's stimulus, not part of the
vehicle. It runs as a test-node timer (`bench.every`, every DRV_Steering cycle), reads the ground truth
(PLANT_Position, PLANT_Motion, PLANT_Dynamics: what a driver sees of the car's motion) and sets
DRV_Steering.HandWheelAngle. Only the bench's public API and DBC names are used.

Course frame = the world frame of the ground truth (the start pose: x right, y forward, headings clockwise
from +y, docs/spec/formulas.md §1); a path is the lateral position x(y) of the vehicle's centre along the course.

Law: MacAdam's optimal preview control (C. C. MacAdam, "Application of an optimal preview control for
simulation of closed-loop automobile driving", IEEE SMC 11(6), 1981), in its single-input form. The driver
holds an internal model of the car (`CarModel`: the linear single-track model of docs/spec/formulas.md §5 with the
car's rear-steering law and the steering lag), predicts the lateral position at a few times over a preview
window for the current state and a hand-wheel angle θ held from now, and takes the θ that minimises the summed
squared distance of those predictions to the path. The predictions are linear in θ, so the choice is a closed
form; it is made again every tick from the measured state (receding horizon), which closes the loop. Why this
and not a proportional look-ahead: the three rear-steering laws respond very differently in the first few
tenths of a second (the feedback law first steers the rear against the front), and a driver who knows the car
anticipates that; with one law-independent look-ahead gain two of the three laws clipped the ISO 3888-1 gates.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import expm

from bench.case import Case

HAND_WHEEL_LIMIT = 900.0      # deg, DRV_Steering.HandWheelAngle range
HAND_WHEEL_STEP = 0.1         # deg, its resolution


@dataclass(frozen=True)
class Transition:
    """The path moves from the previous lateral position to x_to while y goes from y_start to y_end."""

    y_start: float
    y_end: float
    x_to: float


class Path:
    """x(y) made of straight pieces joined by half-cosine transitions (x = x0 + (x1 − x0)(1 − cos πτ)/2;
    chained transitions between ±A at the cones of a slalom make a sinusoid)."""

    def __init__(self, x_start: float, transitions: Sequence[Transition]) -> None:
        self.x_start = x_start
        self.pieces: list[tuple[float, float, float, float]] = []     # (y_start, y_end, x_from, x_to)
        x, last = x_start, -math.inf
        for tr in transitions:
            if not (tr.y_end > tr.y_start >= last):
                raise ValueError(f"path transitions must be ordered and non-empty: {tr}")
            self.pieces.append((tr.y_start, tr.y_end, x, tr.x_to))
            x, last = tr.x_to, tr.y_end

    def at(self, y: float) -> tuple[float, float, float]:
        """(x, dx/dy, d²x/dy²) at y."""
        x = self.x_start
        for y0, y1, x0, x1 in self.pieces:
            if y < y0:
                return x, 0.0, 0.0
            if y <= y1:
                k = math.pi / (y1 - y0)
                half = 0.5 * (x1 - x0)
                phase = k * (y - y0)
                return x0 + half * (1.0 - math.cos(phase)), half * k * math.sin(phase), half * k * k * math.cos(phase)
            x = x1
        return x, 0.0, 0.0

    def curvature(self, y: float) -> float:
        """Signed curvature (1/m, positive = bending right) at y."""
        _, d1, d2 = self.at(y)
        return d2 / (1.0 + d1 * d1) ** 1.5


class CarModel:
    """The driver's internal model of the car, bus signs. State s = (x, ψ, w, r, δ_f, δ_r): lateral position (m),
    heading (rad), lateral velocity (m/s), yaw rate (rad/s), front and rear axle angles (rad); input θ, the
    hand-wheel angle (rad); speed u constant:
        ẋ = u ψ + w,  ψ̇ = r,  m (ẇ + u r) = F_f + F_r,  I_z ṙ = a F_f − b F_r       (docs/spec/formulas.md §5)
        F_f = C_f (δ_f − (w + a r)/u),  F_r = C_r (δ_r − (w − b r)/u)
        τ δ̇_f = θ/i − δ_f,  τ δ̇_r = k_θ θ/i + k_r r − δ_r      (the law: 2WS (0, 0), FEEDFORWARD (k(u), 0),
                                                                  FEEDBACK (−C1, C2 u))
    τ lumps the steering servos and the network (chosen)."""

    def __init__(self, m: float, iz: float, a: float, b: float, cf: float, cr: float, ratio: float, u: float,
                 rear: tuple[float, float], lag: float) -> None:
        if not (u > 0.0 and lag > 0.0 and ratio > 0.0):
            raise ValueError("CarModel needs a positive speed, lag and steering ratio")
        self.u, self.ratio, self.lag = u, ratio, lag
        self.k_theta, self.k_r = rear
        am = np.zeros((6, 6))
        bm = np.zeros(6)
        am[0, 1], am[0, 2] = u, 1.0
        am[1, 3] = 1.0
        am[2, 2], am[2, 3] = -(cf + cr) / (m * u), -(a * cf - b * cr) / (m * u) - u
        am[2, 4], am[2, 5] = cf / m, cr / m
        am[3, 2], am[3, 3] = -(a * cf - b * cr) / (iz * u), -(a * a * cf + b * b * cr) / (iz * u)
        am[3, 4], am[3, 5] = a * cf / iz, -b * cr / iz
        am[4, 4], bm[4] = -1.0 / lag, 1.0 / (lag * ratio)
        am[5, 5], am[5, 3], bm[5] = -1.0 / lag, self.k_r / lag, self.k_theta / (lag * ratio)
        self.a, self.b = am, bm

    def preview(self, times: Sequence[float]) -> tuple[list[list[float]], list[float]]:
        """For each preview time t: the row c e^{A t} (free response of x) and g = c ∫₀ᵗ e^{Aτ} dτ b (response of
        x to a unit hand-wheel angle held from now); c selects x. From the exponential of [[A, b], [0, 0]] t."""
        n = len(self.b)
        rows, gains = [], []
        for t in times:
            big = np.zeros((n + 1, n + 1))
            big[:n, :n] = self.a * t
            big[:n, n] = self.b * t
            e = expm(big)
            rows.append(e[0, :n].tolist())
            gains.append(float(e[0, n]))
        return rows, gains


@dataclass
class DriverLog:
    t: list[float] = field(default_factory=list)
    offset: list[float] = field(default_factory=list)       # x − x_path, m
    hand_wheel: list[float] = field(default_factory=list)   # deg


class PreviewDriver:
    """The driver of the module docstring on one bench case.

    Measured (ground truth, bus signs): x = PLANT_Position.PosX, y = PosY, ψ = PLANT_Motion.Heading,
    w = u tan(PLANT_Dynamics.Sideslip), r = PLANT_Motion.YawRate, u = PLANT_Motion.Speed; the axle angles are
    the driver's own estimate (its commands through the model's lag and law): a driver does not see them."""

    def __init__(self, bench: Case, path: Path, model: CarModel, *, horizon: float = 0.5, points: int = 5,
                 period: float = 0.01) -> None:
        if not (horizon > 0.0 and points >= 1 and period > 0.0):
            raise ValueError("PreviewDriver needs a positive horizon and period and at least one preview point")
        self.bench = bench
        self.path = path
        self.model = model
        self.period = period
        self.times = [horizon * (i + 1) / points for i in range(points)]
        self.rows, self.gains = model.preview(self.times)
        self.norm = sum(g * g for g in self.gains)
        self.keep = math.exp(-period / model.lag)
        self.delta_f = self.delta_r = 0.0
        self.log = DriverLog()
        self._cancel: Callable[[], None] | None = None

    def engage(self) -> None:
        """Start steering (every `period` s of bench time until `release`; timers outlive a scenario)."""
        self.delta_f = self.delta_r = 0.0
        self._cancel = self.bench.every(self.period, self._tick)

    def release(self) -> None:
        if self._cancel is not None:
            self._cancel()
            self._cancel = None

    def _tick(self, now: float) -> None:
        b = self.bench
        x, y = b.value("PLANT_Position", "PosX"), b.value("PLANT_Position", "PosY")
        heading, speed = b.value("PLANT_Motion", "Heading"), b.value("PLANT_Motion", "Speed")
        yaw, slip = b.value("PLANT_Motion", "YawRate"), b.value("PLANT_Dynamics", "Sideslip")
        if not all(math.isfinite(v) for v in (x, y, heading, speed, yaw, slip)) or speed < 1.0:
            return                                              # nothing to steer by: hold the hand wheel
        r = math.radians(yaw)
        state = (x, math.radians(heading), speed * math.tan(math.radians(slip)), r, self.delta_f, self.delta_r)
        num = 0.0
        for t, row, g in zip(self.times, self.rows, self.gains):
            free = row[0] * state[0] + row[1] * state[1] + row[2] * state[2] + row[3] * state[3] \
                + row[4] * state[4] + row[5] * state[5]
            num += (self.path.at(y + speed * t)[0] - free) * g
        theta = max(-HAND_WHEEL_LIMIT, min(HAND_WHEEL_LIMIT, math.degrees(num / self.norm)))
        theta = round(theta / HAND_WHEEL_STEP) * HAND_WHEEL_STEP
        b.set("DRV_Steering", HandWheelAngle=theta)
        m = self.model
        front = math.radians(theta) / m.ratio
        rear = m.k_theta * front + m.k_r * r
        self.delta_f = front + (self.delta_f - front) * self.keep
        self.delta_r = rear + (self.delta_r - rear) * self.keep
        self.log.t.append(now)
        self.log.offset.append(x - self.path.at(y)[0])
        self.log.hand_wheel.append(theta)
