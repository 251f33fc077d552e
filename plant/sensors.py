"""Wheel-speed sensors of the ABS ([P4] §3: "wheel speeds are disturbed by road roughness, braking and
driving"): true circumferential speed + road-roughness disturbance + white sensor noise, quantised.

- noise: white, standard deviation BENCH_Control.SensorNoise (km/h) per sample, independent per wheel;
- road roughness: per wheel a first-order (Ornstein-Uhlenbeck) process of standard deviation
  roughness_ratio * SensorNoise and correlation time roughness_time (chosen, plant/vehicles/abs.toml),
  the slow wobble of a wheel over an uneven surface; SensorNoise = 0 means ideal sensors (DBC comment);
- quantisation: to `quantum` km/h (the 0.05 km/h of ABS_WheelSpeeds, dbc/chassis.dbc), clamped to the
  signal's range [0, 204.75] km/h, so the ECU computes on exactly what it publishes.

Deterministic: the generator is `random.Random(seed)`, re-seeded by `reset`, so a scenario replays the same
noise whatever ran before it.
"""

from __future__ import annotations

import math
import random
from collections.abc import Sequence

SPEED_RANGE_KMH = (0.0, 204.75)   # ABS_WheelSpeeds.WheelSpeedXX range, dbc/chassis.dbc


class WheelSpeedSensors:
    """Four sensors FL, FR, RL, RR sampled by the ECU."""

    __slots__ = ("quantum", "roughness_ratio", "roughness_time", "seed", "noise", "_rng", "_rough")

    def __init__(self, *, quantum: float, roughness_ratio: float, roughness_time: float, seed: int) -> None:
        if not (quantum > 0.0 and roughness_ratio >= 0.0 and roughness_time > 0.0):
            raise ValueError("wheel-speed sensors need quantum > 0, roughness_ratio >= 0, roughness_time > 0")
        self.quantum = quantum
        self.roughness_ratio = roughness_ratio
        self.roughness_time = roughness_time
        self.seed = int(seed)
        self.noise = 0.0
        self.reset()

    def reset(self, noise: float | None = None) -> None:
        """Re-seed; `noise` = the new standard deviation in km/h (None keeps it; bad values mean 0)."""
        if noise is not None:
            self.noise = noise if math.isfinite(noise) and noise > 0.0 else 0.0
        self._rng = random.Random(self.seed)
        self._rough = [0.0, 0.0, 0.0, 0.0]

    def sample(self, true_kmh: Sequence[float], dt: float) -> list[float]:
        """One reading per wheel, km/h, quantised; dt = time since the previous sample (roughness)."""
        sigma = self.noise
        q = self.quantum
        lo, hi = SPEED_RANGE_KMH
        out = []
        if sigma > 0.0:
            gauss = self._rng.gauss
            # exact discretisation of the OU process: x' = a x + sqrt(1 - a^2) sigma_r w
            a = math.exp(-dt / self.roughness_time)
            sr = self.roughness_ratio * sigma * math.sqrt(max(0.0, 1.0 - a * a))
            rough = self._rough
            for i in range(4):
                rough[i] = a * rough[i] + sr * gauss(0.0, 1.0)
                v = true_kmh[i] + rough[i] + sigma * gauss(0.0, 1.0)
                v = round(v / q) * q
                out.append(lo if v < lo else hi if v > hi else v)
        else:
            for i in range(4):
                v = round(true_kmh[i] / q) * q
                out.append(lo if v < lo else hi if v > hi else v)
        return out
