"""Braking-capable planar vehicle (docs/spec/vehicles.md B, the A-class car of [P4]): longitudinal, lateral and yaw
motion of the body, four wheel-spin degrees of freedom, Magic Formula tyres with combined slip
(plant/tyre.py), static and dynamic load transfer, brake torques from plant/brakes.py, front-wheel drive.

Internal frame (the vehicle-dynamics textbook one, chosen because [P4]'s formulas are written in it):
x forward, y LEFT, yaw rate r positive counter-clockwise (left turn), road-wheel angle delta positive left,
origin at the centre of gravity. The bus convention (docs/spec/formulas.md §1: angles, yaw rate and lateral
acceleration positive to the RIGHT) is applied only by the properties named *_bus and by the PLANT node.

Wheels i = FL, FR, RL, RR at (a, B/2), (a, -B/2), (-b, B/2), (-b, -B/2). Both front wheels steer by the same
delta ([P4] §2 assumes delta1 = delta2; no Ackermann linkage is modelled).

    m (u' - v r) = sum Fx_i          m (v' + u r) = sum Fy_i          I_z r' = sum (x_i Fy_i - y_i Fx_i)
    J omega_i'   = T_drive_i - T_brake_i - R Fx_wheel_i

Slip of wheel i (contact-point velocity V_long, V_lat in the wheel frame):
kappa = (omega R - V_long) / max(|V_long|, v_floor), alpha = atan2(V_lat, max(|V_long|, v_floor)); the floor
(abs.toml, chosen) keeps both finite at standstill, where the tyre then acts as a stiff damper.

Normal loads: static (m g b/L, m g a/L per axle, half per wheel) plus longitudinal transfer
-m a_x h / L (to the front when braking) and lateral transfer m_axle a_y h / B per axle (to the outer wheels;
each axle transfers its own static share: no roll-stiffness distribution is modelled). a_x, a_y lag the
body's accelerations by load_transfer_lag (pitch and roll of the suspension, chosen), which also breaks
the algebraic loop between loads and forces.

Integration, per plant tick: body explicit Euler with the forces at the start of the tick; each wheel
semi-implicit (the stiff tyre term R^2 dFx/dkappa / V is taken implicitly, so the wheel is stable at any
speed and tick; past the force peak the slope is 0 and the lock-up is the explicit, physical one). The
brake is dry friction: it can stop a wheel but never turn it backwards. The car does not reverse: below
stop_speed with the brakes on, it is held at rest.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from plant.tyre import CombinedSlipTyre, Shape, lateral_b

G = 9.81               # m/s^2
KMH = 3.6              # km/h per m/s
MIN_MU = 0.05          # lowest road friction the model takes (BENCH_Control.RoadMu may say 0)


@dataclass(frozen=True)
class VehicleSpec:
    """What the model needs (built from plant/vehicles/aclass.toml and abs.toml by the assembly)."""

    mass: float
    yaw_inertia: float
    cog_to_front_axle: float
    cog_to_rear_axle: float
    track: float
    wheel_radius: float
    cog_height: float
    cornering_stiffness_front: float      # axle, N/rad
    cornering_stiffness_rear: float       # axle, N/rad
    wheel_inertia: float
    lateral_c: float
    lateral_e: float
    slip_speed_floor: float
    load_transfer_lag: float
    stop_speed: float

    def __post_init__(self) -> None:
        for name in ("mass", "yaw_inertia", "cog_to_front_axle", "cog_to_rear_axle", "track", "wheel_radius",
                     "cog_height", "cornering_stiffness_front", "cornering_stiffness_rear", "wheel_inertia",
                     "lateral_c", "slip_speed_floor", "load_transfer_lag", "stop_speed"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"vehicle spec: {name} must be a positive number, got {value!r}")
        if not (math.isfinite(self.lateral_e) and self.lateral_e <= 1.0):
            raise ValueError(f"vehicle spec: lateral_e must be a finite number <= 1, got {self.lateral_e!r}")

    @property
    def wheelbase(self) -> float:
        return self.cog_to_front_axle + self.cog_to_rear_axle

    def static_loads(self) -> tuple[float, float]:
        """(front wheel, rear wheel) static normal load, N."""
        w = self.mass * G / self.wheelbase
        return w * self.cog_to_rear_axle / 2.0, w * self.cog_to_front_axle / 2.0


#: Longitudinal Magic Formula shapes of docs/spec/vehicles.md B and their friction D.
DRY = (Shape(10.0, 1.9, 0.97), 1.0)
WET = (Shape(12.0, 2.3, 1.0), 0.82)


def road_shape(mu: float, dry: tuple[Shape, float] = DRY, wet: tuple[Shape, float] = WET) -> Shape:
    """The curve shape for a road friction mu (BENCH_Control.RoadMu): the dry set from the midpoint of the
    two sets' D upwards (0.91), the wet set below; D = mu in both cases (so 1.0 is docs/spec/vehicles.md's dry set
    and 0.82 its wet set exactly; other values scale the nearer set's peak)."""
    return dry[0] if mu >= 0.5 * (dry[1] + wet[1]) else wet[0]


class BrakingVehicle:
    """The physics; no bus. Inputs set before `step`: delta (rad, left +), brake and drive torques."""

    def __init__(self, spec: VehicleSpec) -> None:
        self.spec = spec
        a, b, half = spec.cog_to_front_axle, spec.cog_to_rear_axle, spec.track / 2.0
        self.pos = ((a, half), (a, -half), (-b, half), (-b, -half))
        fz_f, fz_r = spec.static_loads()
        self.static = (fz_f, fz_f, fz_r, fz_r)
        self._lat_shapes = (Shape(lateral_b(spec.cornering_stiffness_front, fz_f, spec.lateral_c), spec.lateral_c,
                                  spec.lateral_e),
                            Shape(lateral_b(spec.cornering_stiffness_rear, fz_r, spec.lateral_c), spec.lateral_c,
                                  spec.lateral_e))
        self.set_road(1.0)
        self.reset()

    def set_road(self, mu: float) -> None:
        """Friction of the road (BENCH_Control.RoadMu): a non-finite value means dry (1.0, the DBC start value);
        at least MIN_MU (a road without any friction would never stop the car: the model needs some grip)."""
        if not math.isfinite(mu):
            mu = 1.0
        mu = max(mu, MIN_MU)
        self.mu = mu
        shape = road_shape(mu)
        front = CombinedSlipTyre(shape, self._lat_shapes[0])
        rear = CombinedSlipTyre(shape, self._lat_shapes[1])
        self.tyres = (front, front, rear, rear)

    def reset(self, speed: float = 0.0) -> None:
        """Straight ahead at `speed` m/s (wheels free rolling), at the origin, heading 0."""
        speed = speed if math.isfinite(speed) and speed > 0.0 else 0.0
        self.u = speed          # forward, m/s
        self.v = 0.0            # lateral (left), m/s
        self.r = 0.0            # yaw rate (left), rad/s
        self.x = self.y = 0.0   # world position of the CoG (x along the start heading, y to its left), m
        self.psi = 0.0          # heading, rad, counter-clockwise
        w0 = speed / self.spec.wheel_radius
        self.omega = [w0, w0, w0, w0]
        self.delta = 0.0
        self.brake_torque: Sequence[float] = (0.0, 0.0, 0.0, 0.0)
        self.drive_torque = 0.0   # front axle, split equally (open differential)
        self.long_accel = self.lat_accel = 0.0   # body accelerations (CoG, body frame, lateral left), m/s^2
        self._long_accel_lag = self._lat_accel_lag = 0.0
        self.fz = list(self.static)
        self.kappa = [0.0, 0.0, 0.0, 0.0]
        self.alpha = [0.0, 0.0, 0.0, 0.0]
        self.stopped = speed == 0.0

    # -- dynamics ----------------------------------------------------------------------------------------
    def step(self, dt: float) -> None:
        spec = self.spec
        m, R, J = spec.mass, spec.wheel_radius, spec.wheel_inertia
        brake_torque = self.brake_torque
        braking = brake_torque[0] > 0.0 or brake_torque[1] > 0.0 or brake_torque[2] > 0.0 or brake_torque[3] > 0.0
        if self.stopped:
            if self.drive_torque <= 0.0:
                self.long_accel = self.lat_accel = 0.0
                return
            self.stopped = False
        # normal loads with the lagged accelerations
        k = dt / (spec.load_transfer_lag + dt)
        self._long_accel_lag += (self.long_accel - self._long_accel_lag) * k
        self._lat_accel_lag += (self.lat_accel - self._lat_accel_lag) * k
        h, L, B = spec.cog_height, spec.wheelbase, spec.track
        d_long = -m * self._long_accel_lag * h / L / 2.0            # per front wheel (+), per rear wheel (-)
        m_front = m * spec.cog_to_rear_axle / L
        m_rear = m - m_front
        d_lat_f = m_front * self._lat_accel_lag * h / B            # a_y > 0 (left turn): load to the right wheels
        d_lat_r = m_rear * self._lat_accel_lag * h / B
        st = self.static
        fz = self.fz
        # max(0.0, x) written out: x if x > 0.0 else 0.0 (also for -0.0 and NaN, as max gives)
        f = st[0] + d_long - d_lat_f
        fz[0] = f if f > 0.0 else 0.0
        f = st[1] + d_long + d_lat_f
        fz[1] = f if f > 0.0 else 0.0
        f = st[2] - d_long - d_lat_r
        fz[2] = f if f > 0.0 else 0.0
        f = st[3] - d_long + d_lat_r
        fz[3] = f if f > 0.0 else 0.0

        u, v, r = self.u, self.v, self.r
        delta = self.delta
        cd, sd = math.cos(delta), math.sin(delta)
        floor = spec.slip_speed_floor
        mu = self.mu
        fx_sum = fy_sum = mz = 0.0
        half_drive = 0.5 * self.drive_torque
        omega = self.omega
        kappas, alphas, tyres, pos = self.kappa, self.alpha, self.tyres, self.pos
        atan2 = math.atan2
        for i in range(4):
            px, py = pos[i]
            vx = u - r * py
            vy = v + r * px
            if i < 2:
                v_long = vx * cd + vy * sd
                v_lat = -vx * sd + vy * cd
            else:
                v_long, v_lat = vx, vy
            den = abs(v_long)
            if den < floor:
                den = floor
            w = omega[i]
            kappa = (w * R - v_long) / den
            alpha = atan2(v_lat, den)
            tyre = tyres[i]
            fz_mu = mu * fz[i]
            f_long, f_lat, slope = tyre.forces_and_slope(kappa, alpha, fz_mu)
            f_lat = -f_lat
            kappas[i], alphas[i] = kappa, alpha
            # wheel spin, semi-implicit in the tyre's stiffness
            j_eff = J + dt * R * R * (slope if slope > 0.0 else 0.0) / den
            drive = half_drive if i < 2 else 0.0
            w_free = w + dt * (drive - R * f_long) / j_eff
            impulse = dt * brake_torque[i] / j_eff
            if w_free > impulse:
                w_new = w_free - impulse
            elif w_free < -impulse:
                w_new = w_free + impulse
            else:
                w_new = 0.0
            omega[i] = w_new
            # body forces
            if i < 2:
                fx_b = f_long * cd - f_lat * sd
                fy_b = f_long * sd + f_lat * cd
            else:
                fx_b, fy_b = f_long, f_lat
            fx_sum += fx_b
            fy_sum += fy_b
            mz += px * fy_b - py * fx_b

        long_accel, lat_accel = fx_sum / m, fy_sum / m
        self.long_accel, self.lat_accel = long_accel, lat_accel
        u_new = u + dt * (long_accel + v * r)
        v_new = v + dt * (lat_accel - u * r)
        r_new = r + dt * mz / spec.yaw_inertia
        # pose (trapezoid of the heading over the tick)
        psi_mid = self.psi + 0.5 * dt * (r + r_new)
        self.psi += dt * r_new
        c, s = math.cos(psi_mid), math.sin(psi_mid)
        um, vm = 0.5 * (u + u_new), 0.5 * (v + v_new)
        self.x += dt * (um * c - vm * s)
        self.y += dt * (um * s + vm * c)
        if u_new < spec.stop_speed and braking and self.drive_torque <= 0.0:
            self.u = self.v = self.r = 0.0
            self.omega = [0.0, 0.0, 0.0, 0.0]
            self.kappa = [0.0, 0.0, 0.0, 0.0]
            self.alpha = [0.0, 0.0, 0.0, 0.0]
            self.long_accel = self.lat_accel = 0.0
            self.stopped = True
            return
        self.u = u_new if u_new > 0.0 else 0.0
        self.v, self.r = v_new, r_new

    # -- observations --------------------------------------------------------------------------------------
    def wheel_speeds_kmh(self) -> list[float]:
        """True circumferential speeds omega R of FL, FR, RL, RR, km/h."""
        k = self.spec.wheel_radius * KMH
        return [w * k for w in self.omega]

    @property
    def speed(self) -> float:
        """Speed of the centre of gravity over the ground, m/s ([P4] §1: V)."""
        return math.hypot(self.u, self.v)

    @property
    def sideslip(self) -> float:
        """Sideslip at the CoG, rad, positive = velocity to the left of the heading (internal frame)."""
        return math.atan2(self.v, self.u) if self.u > 1e-3 else 0.0
