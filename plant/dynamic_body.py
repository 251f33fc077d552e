"""Vehicle dynamics of the 4WIS EV at speed: the 2-DOF single-track model of docs/spec/formulas.md §5 with saturating
lateral tyres, and the EV's body that switches between it and the kinematic body of plant/body.py.

Why two models: [P0]'s manoeuvres (PIVOT, LATERAL, U-turns) are slow rotations about a point with wheel
angles up to ±90°, where the wheels roll without slip and the kinematic rigid-body fit of plant/body.py is
exact; [P3]'s manoeuvres (steps, lane changes, slalom at 40-100 km/h) need tyre slip, sideslip and a
finite yaw response, which the kinematic fit cannot produce. One vehicle, two regimes (`VehicleBody`):

- KINEMATIC (plant/body.py, unchanged): below DYNAMIC_ON_SPEED, or any wheel beyond DYNAMIC_ON_ANGLE, or any
  wheel rolling backwards.
- DYNAMIC (`LateralDynamics`): entered when the centre's forward speed reaches DYNAMIC_ON_SPEED = 5.0 m/s
  (18 km/h, just below ADAPTIVE's 20 km/h law switch of docs/spec/vehicles.md A, so [P3]'s laws always act on
  the dynamic body) with every wheel within ±DYNAMIC_ON_ANGLE = 25° and rolling forward; left below
  DYNAMIC_OFF_SPEED = 4.5 m/s (16.2 km/h) or beyond DYNAMIC_OFF_ANGLE = 30° (hysteresis: no chattering).
  [P0]'s cases run at most 4 m/s: always kinematic. All four thresholds "chosen".
  The switch carries the motion over: entering, the lateral velocity and yaw rate start from the kinematic
  motion; leaving, the kinematic fit restarts from the wheels without a finite-difference acceleration spike.

Dynamic regime, docs/spec/formulas.md §5 in the bus frame of §1 (x right, y forward, angles/rates positive clockwise;
the §5 equations keep their form when every angle, rate and force flips sign together):

    m (ẇ + u ω) = F_f + F_r                     w: lateral velocity of the CoG (right), ω: yaw rate
    I_z ω̇      = a F_f − b F_r                  u: forward velocity
    α_f = δ_f − (w + a ω)/u,  α_r = δ_r − (w − b ω)/u,   F = tyre(C α)
    a_y = (F_f + F_r)/m = ẇ + u ω  (lateral, right);  sideslip = atan(w/u)

- Axle angles δ_f, δ_r: the mean of the two wheels of the axle (the wheels' true angles, WHL_Status). For the
  VCU's rotation about a far centre (R ≥ 50 m at speed) the mean differs from the axle-centre heading by
  (K/R)² relative, below 1e-4.
- Lateral tyres (`SaturatingTyre`, per axle): linear, F = C α, up to LINEAR_FRACTION = 0.5 of the axle's
  friction limit μ F_z, then smoothly (same value and slope at the joint) towards μ F_z:
  F = s + (F_max − s) tanh((C α − s)/(F_max − s)), s = 0.5 F_max. Why not plant/tyre.py's Magic Formula:
  it bends from zero slip, so the closed forms of §5 (k(u), yaw gains) would hold only approximately at any
  lateral acceleration; with this tyre they hold exactly below 0.5 μ g and a severe manoeuvre still
  saturates (no force above μ F_z). Static axle loads F_z = m g b/L (front), m g a/L (rear); no load
  transfer, no combined slip (the hub motors only hold the speed), no relaxation length.
- μ = BENCH_Control.RoadMu at the scenario start (limited to [MU_MIN, 1.5]: RoadMu 0 would leave no force).
- Speed: the hub motors are speed-controlled and the tyres longitudinally stiff: u follows the forward velocity
  the wheels' rolling implies (the kinematic fit's forward velocity u_w, the mean of the four v_i cos δ_i), so
  BENCH_Control.InitialSpeed (the wheels' preset) and DRV_MotionRequest.TargetSpeed (through the VCU and the
  hub-motor lag) set it, but never faster than the tyres can push or brake the car: |u̇| ≤ μ g
  (`LongitudinalGrip`: four driven and braked wheels, Σ|F_x| ≤ μ Σ F_z = μ m g; load transfer moves load
  between the axles but not this sum). When u_w runs away faster (a speed step: the hub motors' 100 ms lag
  alone would ask for up to 20 g) the wheels slide: u changes at exactly μ g until it meets u_w again, and
  the wheels report their own (slipping) speed in WHL_Status while PLANT_Motion.Speed is the body's. The
  slip does not take lateral grip away (no combined slip: a limit of this model). LongAccel = u̇ − ω w.
  The kinematic regime below 16.2 km/h is not limited ([P0]'s slow manoeuvres; docs/contract/plant.md);
  the body's own speed (not the wheels') decides when it leaves the dynamic regime, and a sliding body stays
  dynamic down to SLIDE_MIN_SPEED (1 m/s), so a stop from speed hands over to the kinematic fit without a jump
  in speed once the wheels grip again (a jump of at most 1 m/s when they are still sliding there).
- Integration: Heun (2nd-order Runge-Kutta) at the plant tick with the angles and u held over the step. The
  step is well inside the stable region (|λ| h ≤ 0.04 at 4.5 m/s, 1 ms) and a steady state of the model is
  a fixed point of the scheme, so steady values equal the closed forms exactly. Position and heading as in
  plant/body.py (exact for constant body velocities over the step).

Ground truth (PLANT_*) and the IMU read the same attributes as for the kinematic body (x, y, heading, vx = w,
vy = u, omega, lat_accel, long_accel): `VehicleBody` is a `PlanarBody`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

from bench.sim.node import Behaviour
from plant import signal_ranges as ranges
from plant.body import BodyNode, PlanarBody, WheelSource
from plant.single_track import SingleTrackParams
from plant.vehicles import Ev4wisParams

_RAD = math.pi / 180.0
GRAVITY = 9.81                 # m/s²
LINEAR_FRACTION = 0.5          # share of μ F_z up to which the tyre is linear (chosen)
MU_MIN = 0.05                  # lowest road friction simulated (RoadMu 0 would leave no tyre force at all; chosen)
MU_MAX = 1.5                   # BENCH_Control.RoadMu range end
DYNAMIC_ON_SPEED = 5.0         # m/s (18 km/h): kinematic -> dynamic at or above (chosen)
DYNAMIC_OFF_SPEED = 4.5        # m/s (16.2 km/h): dynamic -> kinematic below (chosen)
DYNAMIC_ON_ANGLE = 25.0        # deg: every wheel within this to enter the dynamic regime (chosen)
DYNAMIC_OFF_ANGLE = 30.0       # deg: a wheel beyond this leaves it (chosen)
SLIDE_TOL = 0.05               # m/s: wheels and body differ by more than this = the wheels slide (chosen)
SLIDE_MIN_SPEED = 1.0          # m/s: a sliding body stays dynamic down to this speed (chosen; Heun stays stable)


def longitudinal_limit(mu: float) -> float:
    """Largest |u̇| the four tyres can give, m/s²: μ g (module docstring, `Speed`)."""
    return mu * GRAVITY


def follow_speed(u: float, u_wheels: float, limit: float, dt: float) -> float:
    """The body's forward speed after dt: the wheels' u_w when the tyres can give the change, else u moved
    towards u_w by limit·dt (the wheels slide)."""
    step = limit * dt
    change = u_wheels - u
    if change > step:
        return u + step
    if change < -step:
        return u - step
    return u_wheels


def ev_single_track(p: Ev4wisParams) -> SingleTrackParams:
    """docs/spec/vehicles.md A as the §5 model's parameters (a, b from the CoG at the geometric centre)."""
    return SingleTrackParams(p.mass, p.yaw_inertia, p.cog_to_front_axle, p.cog_to_rear_axle,
                             p.cornering_stiffness_front, p.cornering_stiffness_rear)


class SaturatingTyre:
    """Lateral force of one axle: linear (C α) up to LINEAR_FRACTION of μ F_z, then a tanh towards μ F_z.

    Odd in α, continuous with a continuous slope, |F| < μ F_z. Signs: the force has the sign of α in any
    frame in which α and F are measured the same way round (ISO or the bus convention)."""

    __slots__ = ("stiffness", "load", "fraction", "mu", "f_max", "knee", "span")

    def __init__(self, stiffness: float, load: float, mu: float = 1.0,
                 linear_fraction: float = LINEAR_FRACTION) -> None:
        if not (stiffness > 0.0 and load > 0.0 and 0.0 < linear_fraction < 1.0):
            raise ValueError("SaturatingTyre needs a positive stiffness and load and 0 < linear_fraction < 1, got "
                             f"{stiffness!r}, {load!r}, {linear_fraction!r}")
        self.stiffness = float(stiffness)
        self.load = float(load)
        self.fraction = float(linear_fraction)
        self.set_mu(mu)

    def set_mu(self, mu: float) -> None:
        """Road friction μ (MU_MIN..MU_MAX; ValueError when not a finite positive number)."""
        if not (isinstance(mu, (int, float)) and math.isfinite(mu) and mu > 0.0):
            raise ValueError(f"road friction must be a finite positive number, got {mu!r}")
        self.mu = min(max(float(mu), MU_MIN), MU_MAX)
        self.f_max = self.mu * self.load
        self.knee = self.fraction * self.f_max
        self.span = self.f_max - self.knee

    def force(self, alpha: float) -> float:
        """Lateral force (N) at slip angle alpha (rad)."""
        f = self.stiffness * alpha
        if -self.knee <= f <= self.knee:
            return f
        s, span = self.knee, self.span
        if f > 0.0:
            return s + span * math.tanh((f - s) / span)
        return -s - span * math.tanh((-f - s) / span)

    def slope(self, alpha: float) -> float:
        """dF/dα, N/rad (C in the linear range, falling to 0 at saturation)."""
        f = abs(self.stiffness * alpha)
        if f <= self.knee:
            return self.stiffness
        t = math.tanh((f - self.knee) / self.span)
        return self.stiffness * (1.0 - t * t)


class LateralDynamics:
    """The §5 single-track model with saturating axle tyres, bus signs (module docstring).

    State: w (lateral velocity, m/s, right), omega (yaw rate, rad/s, clockwise). Inputs per step: forward
    speed u (m/s, > 0) and the axle angles (rad, positive right). After `step`: lat_accel (m/s², right) and
    the axle forces (N) at the new state."""

    def __init__(self, params: SingleTrackParams, mu: float = 1.0) -> None:
        self.params = params
        m, a, b = params.mass, params.a, params.b
        big_l = a + b
        self.front = SaturatingTyre(params.cf, m * GRAVITY * b / big_l, mu)
        self.rear = SaturatingTyre(params.cr, m * GRAVITY * a / big_l, mu)
        self._inv_m = 1.0 / m
        self._inv_iz = 1.0 / params.yaw_inertia
        self.reset()

    def reset(self, w: float = 0.0, omega: float = 0.0) -> None:
        self.w, self.omega = float(w), float(omega)
        self.force_front = self.force_rear = 0.0
        self.lat_accel = 0.0

    def set_mu(self, mu: float) -> None:
        self.front.set_mu(mu)
        self.rear.set_mu(mu)

    def forces(self, u: float, w: float, omega: float, delta_f: float, delta_r: float) -> tuple[float, float]:
        """(F_f, F_r), N, right-positive: α_f = δ_f − (w + a ω)/u, α_r = δ_r − (w − b ω)/u."""
        p = self.params
        return (self.front.force(delta_f - (w + p.a * omega) / u),
                self.rear.force(delta_r - (w - p.b * omega) / u))

    def derivatives(self, u: float, w: float, omega: float, delta_f: float,
                    delta_r: float) -> tuple[float, float, float, float]:
        """(ẇ, ω̇, F_f, F_r) of the equations in the module docstring."""
        ff, fr = self.forces(u, w, omega, delta_f, delta_r)
        return ((ff + fr) * self._inv_m - u * omega, (self.params.a * ff - self.params.b * fr) * self._inv_iz, ff, fr)

    def step(self, dt: float, u: float, delta_f: float, delta_r: float) -> None:
        """Advance by dt (s) with u and the angles held (Heun). u must be positive."""
        # `derivatives` written out three times (hot: every tick at speed; the same operations in the same order)
        a, b = self.params.a, self.params.b
        inv_m, inv_iz = self._inv_m, self._inv_iz
        front, rear = self.front.force, self.rear.force
        w, om = self.w, self.omega
        ff, fr = front(delta_f - (w + a * om) / u), rear(delta_r - (w - b * om) / u)
        dw1, dom1 = (ff + fr) * inv_m - u * om, (a * ff - b * fr) * inv_iz
        w2, om2 = w + dt * dw1, om + dt * dom1
        ff, fr = front(delta_f - (w2 + a * om2) / u), rear(delta_r - (w2 - b * om2) / u)
        dw2, dom2 = (ff + fr) * inv_m - u * om2, (a * ff - b * fr) * inv_iz
        w = w + 0.5 * dt * (dw1 + dw2)
        om = om + 0.5 * dt * (dom1 + dom2)
        self.w, self.omega = w, om
        ff, fr = front(delta_f - (w + a * om) / u), rear(delta_r - (w - b * om) / u)
        self.force_front, self.force_rear = ff, fr
        self.lat_accel = (ff + fr) * inv_m


class VehicleBody(PlanarBody):
    """The EV's body: kinematic at low speed or large angles, the dynamic single-track model at speed
    (module docstring). Same interface as PlanarBody (the PLANT node and the IMU read it)."""

    def __init__(self, params: Ev4wisParams, mu: float = 1.0) -> None:
        self.dynamics = LateralDynamics(ev_single_track(params), mu)
        self._half = 0.5 * _RAD
        self.dynamic = False
        super().__init__(params.geometry)

    def reset(self) -> None:
        super().reset()
        self.dynamic = False
        self.dynamics.reset()

    def set_mu(self, mu: float) -> None:
        self.dynamics.set_mu(mu)

    @property
    def long_limit(self) -> float:
        """|u̇| the tyres can give at the road's μ (the front axle's μ: both axles share it), m/s²."""
        return longitudinal_limit(self.dynamics.front.mu)

    def sliding(self, u_wheels: float) -> bool:
        """The wheels' rolling speed differs from the body's by more than SLIDE_TOL (dynamic regime only)."""
        return abs(u_wheels - self.vy) > SLIDE_TOL

    # -- regime ----------------------------------------------------------------------------------------
    @staticmethod
    def wants_dynamic(angles_deg: Sequence[float], speeds_rpm: Sequence[float], forward_speed: float,
                      dynamic_now: bool) -> bool:
        """The regime rule of the module docstring (hysteresis on speed and angle)."""
        speed_limit, angle_limit = ((DYNAMIC_OFF_SPEED, DYNAMIC_OFF_ANGLE) if dynamic_now
                                    else (DYNAMIC_ON_SPEED, DYNAMIC_ON_ANGLE))
        if not forward_speed >= speed_limit:
            return False
        for a, n in zip(angles_deg, speeds_rpm):
            if not (-angle_limit <= a <= angle_limit and n > 0.0):
                return False
        return True

    def advance(self, angles_deg: Sequence[float], speeds_rpm: Sequence[float], dt: float) -> None:
        """Move by dt with the wheels' states at the end of the step, in the regime they call for."""
        vx, vy, om = self.fit(angles_deg, speeds_rpm)
        want = self.wants_dynamic(angles_deg, speeds_rpm, self.vy if self.dynamic else vy, self.dynamic)
        if not want and self.dynamic and self.sliding(vy):
            want = self.wants_dynamic(angles_deg, speeds_rpm, DYNAMIC_OFF_SPEED, True) and self.vy >= SLIDE_MIN_SPEED
        if want != self.dynamic:
            if want:                        # carry the motion over (the first tick: the wheels' motion)
                if self._fresh:
                    self.vx, self.vy, self.omega, self._fresh = vx, vy, om, False
                self.dynamics.reset(self.vx, self.omega)
            else:
                self._fresh = True          # the kinematic fit restarts from the wheels, no acceleration spike
            self.dynamic = want
        if not want:
            self._advance_fitted(vx, vy, om, dt)
            return
        if dt <= 0.0:
            return
        h = self._half
        delta_f = (angles_deg[0] + angles_deg[1]) * h
        delta_r = (angles_deg[2] + angles_deg[3]) * h
        d = self.dynamics
        u = follow_speed(self.vy, vy, self.long_limit, dt)
        d.step(dt, u, delta_f, delta_r)
        self._move(d.w, u, d.omega, dt)
        self.lat_accel = d.lat_accel
        self.long_accel = (u - self.vy) / dt - d.omega * d.w
        self.vx, self.vy, self.omega = d.w, u, d.omega


class EvBodyNode(BodyNode):
    """The EV's PLANT node on the switching body: plant/body.py's BodyNode (scenario reset, ground truth)
    with `VehicleBody`, and BENCH_Control.RoadMu taken at every scenario start (at least MU_MIN; 1.0 when
    missing or not finite)."""

    def __init__(self, params: Ev4wisParams, wheels: Mapping[str, WheelSource], *, vehicle_code: int,
                 linked: Sequence[Behaviour] = ()) -> None:
        super().__init__(params.geometry, wheels, vehicle_code=vehicle_code, linked=linked)
        self.vehicle_body = VehicleBody(params)   # the attribute `body` keeps BodyNode's declared type
        self.body = self.vehicle_body
        self.reset()

    def _restart(self, control: Mapping[str, float], t: float, dt: float) -> None:
        mu = control.get("RoadMu", 1.0)
        self.vehicle_body.set_mu(max(mu, MU_MIN) if ranges.finite(mu) else 1.0)
        super()._restart(control, t, dt)
