"""Reference IMU (node IMU): IMU_Motion from the body's true motion.

Signs per docs/spec/formulas.md §1: YawRate positive clockwise, LatAccel positive to the right, LongAccel positive
forward; mounted at the geometric centre. The source is the in-process body (plant.body.PlanarBody) or,
when the PLANT node runs elsewhere, its ground truth on the bus (PLANT_Motion.YawRate,
PLANT_Dynamics.LatAccel/LongAccel; held when silent). Optional white noise, off by default and
seeded, so runs stay reproducible. Values are clamped to the DBC ranges (IMU_Motion has no fault signal).
"""

from __future__ import annotations

import random
from typing import Protocol

from bench.sim.node import NodeIO
from plant import signal_ranges as ranges

_YAW_RATE, _ACCEL = ranges.IMU_YAW_RATE, ranges.IMU_ACCEL


class MotionSource(Protocol):
    """The in-process body the IMU reads: plant.body.PlanarBody, or a vehicle's own plant (the A-class)."""

    @property
    def yaw_rate_dps(self) -> float: ...

    @property
    def lat_accel(self) -> float: ...

    @property
    def long_accel(self) -> float: ...


class Imu:
    """The IMU behaviour."""

    nodes: tuple[str, ...] = ("IMU",)

    def __init__(self, body: MotionSource | None = None, *,
                 noise_std: tuple[float, float, float] = (0.0, 0.0, 0.0), seed: int = 0) -> None:
        """noise_std: (yaw rate deg/s, lateral m/s^2, longitudinal m/s^2) standard deviations."""
        self.body = body
        self.noise_std = noise_std
        self.seed = seed
        self.reset()

    def reset(self) -> None:
        self._rng = random.Random(self.seed)
        self._last = (0.0, 0.0, 0.0)

    def _truth(self, io: NodeIO) -> tuple[float, float, float]:
        if self.body is not None:
            b = self.body
            return b.yaw_rate_dps, b.lat_accel, b.long_accel
        motion, dynamics = io.latest("PLANT_Motion"), io.latest("PLANT_Dynamics")
        if motion is not None and dynamics is not None:
            values = (motion.get("YawRate", 0.0), dynamics.get("LatAccel", 0.0), dynamics.get("LongAccel", 0.0))
            if ranges.finite(*values):
                self._last = values
        return self._last

    def step(self, io: NodeIO, t: float, dt: float) -> None:
        yaw, lat, lon = self._truth(io)
        sy, sl, sg = self.noise_std
        if sy or sl or sg:
            gauss = self._rng.gauss
            yaw, lat, lon = yaw + gauss(0.0, sy), lat + gauss(0.0, sl), lon + gauss(0.0, sg)
        # ranges.clamp written out (every tick); a NaN, never expected, is sent as 0
        lo, hi = _YAW_RATE
        yaw = 0.0 if yaw != yaw else lo if yaw < lo else hi if yaw > hi else yaw
        lo, hi = _ACCEL
        lat = 0.0 if lat != lat else lo if lat < lo else hi if lat > hi else lat
        lon = 0.0 if lon != lon else lo if lon < lo else hi if lon > hi else lon
        io.send_values("IMU_Motion", YawRate=yaw, LatAccel=lat, LongAccel=lon)
