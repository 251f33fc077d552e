"""Planar rigid-body motion of the 4WIS EV from its four wheels, and the PLANT node (ground truth).

Kinematic, no tyre slip: [P0]'s manoeuvres are low-speed rotations about a point, where each
wheel rolls along its heading (docs/spec/formulas.md §2). The body's velocity is the least-squares rigid motion
(v_x, v_y, omega) of the geometric centre that best matches the four wheel contact velocities
(speed * r along the wheel heading); when the wheels agree (a §2 command) the fit is exact, when they
disagree (mid-transient) it is the compromise the tyres would scrub towards. Dynamics at speed is
another model's job (single_track).

World frame: X right and Y forward of the start pose, heading 0 along +Y, positive clockwise
(docs/spec/formulas.md §1); body frame as docs/spec/formulas.md §1 (x right, y forward, origin at the geometric centre).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Protocol

from bench.sim.node import Behaviour, NodeIO
from plant import signal_ranges as ranges
from plant.kinematics import CORNERS, Geometry
from plant.scenario import ScenarioTracker

_DEG = 180.0 / math.pi
_RAD = math.pi / 180.0
_SNAP_DEG = 1e-6   # rounding noise must not flip the sign of a sideways Speed
_POS, _HEADING, _SPEED = ranges.PLANT_POS, ranges.PLANT_HEADING, ranges.PLANT_SPEED
_YAW_RATE, _SIDESLIP, _ACCEL = ranges.PLANT_YAW_RATE, ranges.PLANT_SIDESLIP, ranges.PLANT_ACCEL



class VelocityFit:
    """Least-squares rigid velocity of the geometric centre from wheel angles and speeds.

    Rigid motion: contact velocity u_i = (v_x + omega * y_i, v_y - omega * x_i), omega clockwise.
    The normal matrix depends only on the wheel layout, so its inverse is computed once.
    """

    __slots__ = ("_pos", "_inv", "_mps_per_rpm")

    def __init__(self, g: Geometry) -> None:
        self._pos = g.wheel_positions
        self._mps_per_rpm = 1.0 / g.rpm_per_mps
        n = float(len(self._pos))
        sx = sum(p[0] for p in self._pos)
        sy = sum(p[1] for p in self._pos)
        s2 = sum(p[0] ** 2 + p[1] ** 2 for p in self._pos)
        self._inv = _inverse3(((n, 0.0, sy), (0.0, n, -sx), (sy, -sx, s2)))

    def __call__(self, angles_deg: Sequence[float], speeds_rpm: Sequence[float]) -> tuple[float, float, float]:
        """(v_x m/s, v_y m/s, omega rad/s clockwise) of the geometric centre, body frame."""
        bx = by = bw = 0.0
        k = self._mps_per_rpm
        sin, cos, rad = math.sin, math.cos, _RAD
        for (px, py), a, n in zip(self._pos, angles_deg, speeds_rpm):
            v = n * k
            b = a * rad
            ux, uy = v * sin(b), v * cos(b)
            bx += ux
            by += uy
            bw += py * ux - px * uy
        (a00, a01, a02), (a10, a11, a12), (a20, a21, a22) = self._inv
        return (a00 * bx + a01 * by + a02 * bw,
                a10 * bx + a11 * by + a12 * bw,
                a20 * bx + a21 * by + a22 * bw)


def _inverse3(m: tuple[tuple[float, ...], ...]) -> tuple[tuple[float, ...], ...]:
    (a, b, c), (d, e, f), (g, h, i) = m
    co = ((e * i - f * h, c * h - b * i, b * f - c * e),
          (f * g - d * i, a * i - c * g, c * d - a * f),
          (d * h - e * g, b * g - a * h, a * e - b * d))
    det = a * co[0][0] + b * co[1][0] + c * co[2][0]
    return tuple(tuple(x / det for x in row) for row in co)


class PlanarBody:
    """Pose and motion of the geometric centre, integrated from the wheels' true states."""

    def __init__(self, g: Geometry) -> None:
        self.geometry = g
        self.fit = VelocityFit(g)
        self.reset()

    def reset(self) -> None:
        """At rest at the origin, heading 0."""
        self.x = self.y = 0.0            # world position, m
        self.heading = 0.0               # rad, clockwise from +Y, continuous (not wrapped)
        self.vx = self.vy = 0.0          # body-frame velocity, m/s (right, forward)
        self.omega = 0.0                 # rad/s, clockwise
        self.lat_accel = self.long_accel = 0.0   # body-frame acceleration, m/s^2 (right, forward)
        self._fresh = True

    def advance(self, angles_deg: Sequence[float], speeds_rpm: Sequence[float], dt: float) -> None:
        """Move by dt with the wheels' states at the end of the step (trapezoid of old and new velocity)."""
        self._advance_fitted(*self.fit(angles_deg, speeds_rpm), dt)

    def _advance_fitted(self, vx: float, vy: float, om: float, dt: float) -> None:
        """`advance` with the wheels' rigid fit already made (a subclass that fitted them need not fit twice)."""
        if self._fresh:
            self.vx, self.vy, self.omega, self._fresh = vx, vy, om, False
        if dt <= 0.0:
            return
        self._move(vx, vy, om, dt)
        # a = dv/dt + omega x v in the rotating body frame (omega clockwise = -z).
        self.lat_accel = (vx - self.vx) / dt + om * vy
        self.long_accel = (vy - self.vy) / dt - om * vx
        self.vx, self.vy, self.omega = vx, vy, om

    def _move(self, vx: float, vy: float, om: float, dt: float) -> None:
        """Position and heading over the step from the trapezoid of the old and the new body velocities (vx, vy,
        om: the new ones). Exact for constant body velocities: the mean of the rotating frame over the step is
        R(heading + h) * sin(h)/h with h = omega dt / 2."""
        mvx, mvy, mom = 0.5 * (vx + self.vx), 0.5 * (vy + self.vy), 0.5 * (om + self.omega)
        h = 0.5 * mom * dt
        s = 1.0 - h * h / 6.0 if abs(h) < 1e-4 else math.sin(h) / h
        mid = self.heading + h
        c, sn = math.cos(mid), math.sin(mid)
        self.x += (mvx * c + mvy * sn) * s * dt
        self.y += (-mvx * sn + mvy * c) * s * dt
        self.heading += mom * dt

    # -- ground truth in bus units -----------------------------------------------------------------
    @property
    def heading_deg(self) -> float:
        """Heading wrapped into [-180, 180) deg, positive clockwise."""
        return (self.heading * _DEG + 180.0) % 360.0 - 180.0

    @property
    def yaw_rate_dps(self) -> float:
        return self.omega * _DEG

    @property
    def sideslip_deg(self) -> float:
        """Direction of the centre's velocity from the body's +y axis, folded into (-90, 90] like a wheel
        angle (reversing straight is 0, LATERAL is 90); 0 below 1 mm/s where it is undefined."""
        if math.hypot(self.vx, self.vy) < 1e-3:
            return 0.0
        a = math.atan2(self.vx, self.vy) * _DEG      # (-180, 180]
        if a > 90.0 + _SNAP_DEG:
            a -= 180.0
        elif a <= -90.0 + _SNAP_DEG:
            a += 180.0
        return 90.0 if a > 90.0 else a + 0.0         # within _SNAP_DEG of sideways is exactly sideways

    @property
    def speed(self) -> float:
        """Signed speed of the geometric centre: its velocity projected on the folded sideslip direction
        (positive forward, and positive to the right when moving exactly sideways)."""
        return self.speed_and_sideslip()[0]

    def speed_and_sideslip(self) -> tuple[float, float]:
        """(speed m/s, sideslip deg) computed together (the plant tick is hot)."""
        slip = self.sideslip_deg
        b = slip * _RAD
        return self.vx * math.sin(b) + self.vy * math.cos(b), slip

    def to_world(self, bx: float, by: float) -> tuple[float, float]:
        """World position of a body-frame point."""
        c, s = math.cos(self.heading), math.sin(self.heading)
        return self.x + bx * c + by * s, self.y - bx * s + by * c

    def wheel_positions(self) -> dict[str, tuple[float, float]]:
        """World positions of the four contact points (for the U-turn top view of [P0] §3)."""
        return {c: self.to_world(px, py) for c, (px, py) in zip(CORNERS, self.geometry.wheel_positions)}


class WheelSource(Protocol):
    """Where the body gets a wheel's true state: the in-process wheel ECU, or the bus."""

    def wheel_state(self, io: NodeIO) -> tuple[float, float]:
        """(steering angle deg, wheel speed rpm) now."""


class BusWheel:
    """An external wheel ECU: its state is what it reports in WHL_Status_xx (held angle, speed 0 when silent)."""

    def __init__(self, corner: str) -> None:
        self.message = f"WHL_Status_{corner}"
        self._angle = 0.0

    def wheel_state(self, io: NodeIO) -> tuple[float, float]:
        status = io.latest(self.message)
        if status is None:
            return self._angle, 0.0
        angle, speed = status.get("SteerAngle", math.nan), status.get("WheelSpeed", math.nan)
        if not ranges.finite(angle, speed):
            return self._angle, 0.0
        self._angle = angle
        return angle, speed


class BodyNode:
    """The PLANT node: integrates the body and publishes ground truth (dbc/bench.dbc, PLANT_*).

    The scenario protocol (plant/scenario.py): whenever BENCH_Control.ScenarioId changes, the body and every
    linked behaviour (the in-process VCU, wheels and IMU) reset; the in-process wheels then start
    rolling straight ahead at BENCH_Control.InitialSpeed (0: at rest), and PLANT_Status.ScenarioIdAck
    echoes the id. RoadMu and SensorNoise do not affect this kinematic model (no tyre forces, no
    wheel-speed sensor model). PLANT_Status.PlantTime is the time since that reset (or the first tick).
    Ground truth is clamped to the bench.dbc ranges (Sideslip carries ±180°: a 4WIS vehicle reaches 90°
    in LATERAL).
    """

    nodes: tuple[str, ...] = ("PLANT",)

    def __init__(self, g: Geometry, wheels: Mapping[str, WheelSource], *, vehicle_code: int,
                 linked: Sequence[Behaviour] = ()) -> None:
        self.body = PlanarBody(g)
        self.wheels = tuple(wheels[c] for c in CORNERS)
        self.linked = tuple(linked)
        self.scenario = ScenarioTracker(vehicle_code)
        self._rpm_per_mps = g.rpm_per_mps
        self.reset()

    def reset(self) -> None:
        self.body.reset()
        self.scenario.reset()

    def wheel_positions(self) -> dict[str, tuple[float, float]]:
        return self.body.wheel_positions()

    def _restart(self, control: Mapping[str, float], t: float, dt: float) -> None:
        self.body.reset()
        for behaviour in self.linked:
            behaviour.reset()
        v0 = control.get("InitialSpeed", 0.0)
        if ranges.finite(v0) and v0 != 0.0:
            for wheel in self.wheels:
                preset = getattr(wheel, "preset", None)
                if preset is not None:
                    preset(0.0, v0 * self._rpm_per_mps)

    def step(self, io: NodeIO, t: float, dt: float) -> None:
        scenario = self.scenario
        if scenario.poll(io, t, dt) and scenario.control is not None:
            self._restart(scenario.control, t, dt)
        states = [wheel.wheel_state(io) for wheel in self.wheels]
        body = self.body
        body.advance([a for a, _ in states], [n for _, n in states], dt)
        speed, sideslip = body.speed_and_sideslip()
        # ranges.clamp written out (hot: every tick); a NaN, never expected, is sent as 0
        lo, hi = _POS
        x, y = body.x, body.y
        x = 0.0 if x != x else lo if x < lo else hi if x > hi else x
        y = 0.0 if y != y else lo if y < lo else hi if y > hi else y
        io.send_values("PLANT_Position", PosX=x, PosY=y)
        heading, yaw = body.heading_deg, body.yaw_rate_dps
        lo, hi = _HEADING
        heading = 0.0 if heading != heading else lo if heading < lo else hi if heading > hi else heading
        lo, hi = _SPEED
        speed = 0.0 if speed != speed else lo if speed < lo else hi if speed > hi else speed
        lo, hi = _YAW_RATE
        yaw = 0.0 if yaw != yaw else lo if yaw < lo else hi if yaw > hi else yaw
        io.send_values("PLANT_Motion", Heading=heading, Speed=speed, YawRate=yaw)
        lo, hi = _SIDESLIP
        sideslip = 0.0 if sideslip != sideslip else lo if sideslip < lo else hi if sideslip > hi else sideslip
        lo, hi = _ACCEL
        lat, lon = body.lat_accel, body.long_accel
        lat = 0.0 if lat != lat else lo if lat < lo else hi if lat > hi else lat
        lon = 0.0 if lon != lon else lo if lon < lo else hi if lon > hi else lon
        io.send_values("PLANT_Dynamics", Sideslip=sideslip, LatAccel=lat, LongAccel=lon)
        scenario.acknowledge(io, t)
