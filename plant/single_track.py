"""Linear 2-DOF single-track ("bicycle") model with front and rear steering (docs/spec/formulas.md §5, [P3]).

State: sideslip angle β at the centre of gravity and yaw rate r; inputs: front and rear road-wheel
angles δ_f, δ_r; the speed u is held constant (set it with `reset` or `set_speed`). Equations
(docs/spec/formulas.md §5, ISO 8855 left-positive, as in [P3]):

    m u (β̇ + r) = C_f (δ_f − β − a r/u) + C_r (δ_r − β + b r/u)
    I_z ṙ       = a C_f (δ_f − β − a r/u) − b C_r (δ_r − β + b r/u)
    a_y         = u (β̇ + r)

Everything in this module is ISO (angles, yaw rate and lateral acceleration positive to the LEFT);
the bus convention of docs/spec/formulas.md §1 (positive to the right) is the caller's business: flip every sign.

Why exact discretisation: with the input held over a step (zero-order hold), x⁺ = Φ x + Γ δ with
Φ = e^{A h}, Γ = ∫₀ʰ e^{A τ} dτ B is exact for any h, so the model is stable at low speed (where A is
stiff, |λ| ~ (C_f + C_r)/(m u)) and agrees with a reference integrator to rounding; Φ and Γ are
recomputed only when h or u changes. Below KINEMATIC_SPEED (where 1/u blows up) the tyres are
taken as rolling without slip: β and r follow the kinematic single-track model at once.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

#: m/s: below this speed the model is kinematic (no tyre slip); the dynamic model needs u > 0.
KINEMATIC_SPEED = 1.0


@dataclass(frozen=True)
class SingleTrackParams:
    """Parameters of docs/spec/formulas.md §5 (SI): mass m, yaw inertia I_z, CoG to front/rear axle a/b,
    axle cornering stiffnesses C_f/C_r (N/rad, > 0)."""

    mass: float
    yaw_inertia: float
    a: float
    b: float
    cf: float
    cr: float

    def __post_init__(self) -> None:
        for name in ("mass", "yaw_inertia", "a", "b", "cf", "cr"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0.0):
                raise ValueError(f"single-track parameter {name} must be a positive finite number, got {value!r}")

    @property
    def wheelbase(self) -> float:
        """L = a + b."""
        return self.a + self.b

    @property
    def stability_factor(self) -> float:
        """K_s = m/L² (b/C_f − a/C_r), s²/m² (docs/spec/formulas.md §5; > 0 understeer, 0 neutral)."""
        return self.mass / self.wheelbase ** 2 * (self.b / self.cf - self.a / self.cr)

    @property
    def characteristic_speed(self) -> float:
        """u_ch = 1/√K_s, m/s (the speed of maximum yaw gain of an understeering car); inf when K_s ≤ 0."""
        k = self.stability_factor
        return 1.0 / math.sqrt(k) if k > 0.0 else math.inf

    def yaw_rate_gain(self, u: float) -> float:
        """Steady-state r/δ_f of the 2WS car, 1/s: (u/L)/(1 + K_s u²) (docs/spec/formulas.md §5)."""
        return (u / self.wheelbase) / (1.0 + self.stability_factor * u * u)

    def steady_state(self, u: float, delta_f: float, delta_r: float = 0.0) -> tuple[float, float, float]:
        """(β, r, a_y) in steady state for constant inputs at speed u (ISO units, rad, rad/s, m/s²).

        Solves A x + B δ = 0 (the §5 equations with β̇ = ṙ = 0); for 2WS r equals
        yaw_rate_gain(u)·δ_f. Below KINEMATIC_SPEED: the kinematic (no-slip) values."""
        if u < KINEMATIC_SPEED:
            return self._kinematic(u, delta_f, delta_r)
        (a00, a01), (a10, a11) = self._a_matrix(u)
        (b00, b01), (b10, b11) = self._b_matrix(u)
        r0 = -(b00 * delta_f + b01 * delta_r)
        r1 = -(b10 * delta_f + b11 * delta_r)
        det = a00 * a11 - a01 * a10
        if det == 0.0:
            raise ValueError(f"no steady state at u = {u:g} m/s: the critical speed of an oversteering car")
        beta = (r0 * a11 - a01 * r1) / det
        r = (a00 * r1 - a10 * r0) / det
        return beta, r, u * r

    # -- matrices of ẋ = A x + B δ, x = (β, r), δ = (δ_f, δ_r) -------------------------------------------
    def _a_matrix(self, u: float) -> tuple[tuple[float, float], tuple[float, float]]:
        m, iz, a, b, cf, cr = self.mass, self.yaw_inertia, self.a, self.b, self.cf, self.cr
        return ((-(cf + cr) / (m * u), -1.0 + (b * cr - a * cf) / (m * u * u)),
                ((b * cr - a * cf) / iz, -(a * a * cf + b * b * cr) / (iz * u)))

    def _b_matrix(self, u: float) -> tuple[tuple[float, float], tuple[float, float]]:
        m, iz, a, b, cf, cr = self.mass, self.yaw_inertia, self.a, self.b, self.cf, self.cr
        return ((cf / (m * u), cr / (m * u)),
                (a * cf / iz, -b * cr / iz))

    def _kinematic(self, u: float, delta_f: float, delta_r: float) -> tuple[float, float, float]:
        """Rolling without slip (linearised): β = (b δ_f + a δ_r)/L, r = u (δ_f − δ_r)/L, a_y = u r."""
        big_l = self.wheelbase
        r = u * (delta_f - delta_r) / big_l
        return (self.b * delta_f + self.a * delta_r) / big_l, r, u * r


class SingleTrack:
    """The §5 model as a stepped simulation (ISO signs). Reused by other vehicles (4WS): keep it generic.

    Attributes after each `step`: beta (rad), yaw_rate (rad/s), lat_accel (m/s²), beta_rate (rad/s),
    yaw_angle (rad, integrated), delta_f/delta_r (the inputs of the last step, rad).
    """

    def __init__(self, params: SingleTrackParams, speed: float = 0.0) -> None:
        self.params = params
        self._key: tuple[float, float] | None = None
        self._phi: Matrix = ((1.0, 0.0), (0.0, 1.0))
        self._gamma: Matrix = ((0.0, 0.0), (0.0, 0.0))
        self._ab: tuple[Matrix, Matrix] = (((0.0, 0.0), (0.0, 0.0)), ((0.0, 0.0), (0.0, 0.0)))   # A, B at _key's u
        self.reset(speed)

    def reset(self, speed: float = 0.0, beta: float = 0.0, yaw_rate: float = 0.0) -> None:
        """Start over at `speed` (m/s, ≥ 0) with the given state, straight inputs."""
        self.set_speed(speed)
        self.beta, self.yaw_rate = float(beta), float(yaw_rate)
        self.beta_rate = 0.0
        self.lat_accel = self.speed * self.yaw_rate
        self.yaw_angle = 0.0
        self.delta_f = self.delta_r = 0.0

    def set_speed(self, speed: float) -> None:
        """The (constant) speed u, m/s; ValueError for a negative or non-finite speed."""
        if not (isinstance(speed, (int, float)) and math.isfinite(speed) and speed >= 0.0):
            raise ValueError(f"single-track speed must be a finite number >= 0 m/s, got {speed!r}")
        self.speed = float(speed)

    @property
    def kinematic(self) -> bool:
        """True below KINEMATIC_SPEED, where the no-slip model is used."""
        return self.speed < KINEMATIC_SPEED

    # -- tyre quantities (ISO) -------------------------------------------------------------------------
    @property
    def front_slip_angle(self) -> float:
        """α_f = δ_f − β − a r/u, rad (0 in the kinematic regime)."""
        if self.kinematic:
            return 0.0
        return self.delta_f - self.beta - self.params.a * self.yaw_rate / self.speed

    @property
    def rear_slip_angle(self) -> float:
        """α_r = δ_r − β + b r/u, rad (0 in the kinematic regime)."""
        if self.kinematic:
            return 0.0
        return self.delta_r - self.beta + self.params.b * self.yaw_rate / self.speed

    @property
    def front_lateral_force(self) -> float:
        """F_yf = C_f α_f, N (the axle; positive to the left). In the kinematic regime the force that
        keeps the no-slip motion, m a_y b/L."""
        if self.kinematic:
            return self.params.mass * self.lat_accel * self.params.b / self.params.wheelbase
        return self.params.cf * self.front_slip_angle

    @property
    def rear_lateral_force(self) -> float:
        """F_yr = C_r α_r, N (kinematic regime: m a_y a/L)."""
        if self.kinematic:
            return self.params.mass * self.lat_accel * self.params.a / self.params.wheelbase
        return self.params.cr * self.rear_slip_angle

    # -- dynamics --------------------------------------------------------------------------------------
    def derivatives(self, beta: float, yaw_rate: float, delta_f: float, delta_r: float = 0.0) -> tuple[float, float]:
        """(β̇, ṙ) of docs/spec/formulas.md §5 at the current speed (dynamic regime only)."""
        (a00, a01), (a10, a11) = self.params._a_matrix(self.speed)
        (b00, b01), (b10, b11) = self.params._b_matrix(self.speed)
        return (a00 * beta + a01 * yaw_rate + b00 * delta_f + b01 * delta_r,
                a10 * beta + a11 * yaw_rate + b10 * delta_f + b11 * delta_r)

    def step(self, dt: float, delta_f: float, delta_r: float = 0.0) -> None:
        """Advance by dt (s) with the road-wheel angles held over the step (rad, ISO)."""
        self.delta_f, self.delta_r = delta_f, delta_r
        u = self.speed
        if u < KINEMATIC_SPEED:
            beta, r, ay = self.params._kinematic(u, delta_f, delta_r)
            self.beta_rate = (beta - self.beta) / dt if dt > 0.0 else 0.0
            self.beta, self.yaw_rate, self.lat_accel = beta, r, ay
            self.yaw_angle += r * dt
            return
        if self._key != (dt, u):
            self._ab = (self.params._a_matrix(u), self.params._b_matrix(u))
            self._phi, self._gamma = _discretise(*self._ab, dt)
            self._key = (dt, u)
        (p00, p01), (p10, p11) = self._phi
        (g00, g01), (g10, g11) = self._gamma
        beta, r = self.beta, self.yaw_rate
        new_beta = p00 * beta + p01 * r + g00 * delta_f + g01 * delta_r
        new_r = p10 * beta + p11 * r + g10 * delta_f + g11 * delta_r
        self.yaw_angle += 0.5 * (r + new_r) * dt   # trapezoid: exact enough for the heading of ground truth
        self.beta, self.yaw_rate = new_beta, new_r
        (a00, a01), _ = self._ab[0]        # derivatives() at this u, with the matrices of the key (not rebuilt)
        (b00, b01), _ = self._ab[1]
        beta_rate = a00 * new_beta + a01 * new_r + b00 * delta_f + b01 * delta_r
        self.beta_rate = beta_rate
        self.lat_accel = u * (beta_rate + new_r)

    def steady_state(self, delta_f: float, delta_r: float = 0.0) -> tuple[float, float, float]:
        """(β, r, a_y) this model settles to at its speed for constant inputs (ISO)."""
        return self.params.steady_state(self.speed, delta_f, delta_r)


# -- exact zero-order-hold discretisation ---------------------------------------------------------------

Matrix = tuple[tuple[float, ...], ...]


def _discretise(a: Matrix, b: Matrix, h: float) -> tuple[Matrix, Matrix]:
    """(Φ, Γ) = (e^{A h}, ∫₀ʰ e^{A τ} dτ B) from the exponential of the block matrix [[A, B], [0, 0]] h."""
    n, k = len(a), len(b[0])
    size = n + k
    big = [[0.0] * size for _ in range(size)]
    for i in range(n):
        for j in range(n):
            big[i][j] = a[i][j] * h
        for j in range(k):
            big[i][n + j] = b[i][j] * h
    e = _expm(big)
    phi = tuple(tuple(e[i][j] for j in range(n)) for i in range(n))
    gamma = tuple(tuple(e[i][n + j] for j in range(k)) for i in range(n))
    return phi, gamma


def _expm(m: list[list[float]]) -> list[list[float]]:
    """Matrix exponential by scaling and squaring with an 18-term Taylor series (small dense matrices;
    relative error near machine precision for the norms met here)."""
    size = len(m)
    norm = max(sum(abs(x) for x in row) for row in m)
    squarings = max(0, math.ceil(math.log2(norm / 0.5))) if norm > 0.5 else 0
    scale = 2.0 ** -squarings
    x = [[v * scale for v in row] for row in m]
    result = [[1.0 if i == j else 0.0 for j in range(size)] for i in range(size)]
    term = [row[:] for row in result]
    for k in range(1, 19):
        term = _matmul(term, x)
        term = [[v / k for v in row] for row in term]
        result = [[r + t for r, t in zip(rr, tr)] for rr, tr in zip(result, term)]
    for _ in range(squarings):
        result = _matmul(result, result)
    return result


def _matmul(p: list[list[float]], q: list[list[float]]) -> list[list[float]]:
    cols = list(zip(*q))
    return [[sum(x * y for x, y in zip(row, col)) for col in cols] for row in p]
