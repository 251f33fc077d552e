"""Wheel-speed sensors of the ABS ([P4] §3: "wheel speeds are disturbed by road roughness, braking and
driving"): true circumferential speed + road-roughness disturbance + white sensor noise, quantised.

- noise: white, standard deviation BENCH_Control.SensorNoise (km/h) per sample, independent per wheel;
- road roughness: per wheel a first-order (Ornstein-Uhlenbeck) process of standard deviation
  roughness_ratio * SensorNoise and correlation time roughness_time (chosen, plant/vehicles/abs.toml),
  the slow wobble of a wheel over an uneven surface; SensorNoise = 0 means ideal sensors (DBC comment);
- quantisation: to `quantum` km/h (the 0.05 km/h of ABS_WheelSpeeds and IO_AbsSensors), limited to the
  sensor's measuring range [0, 200] km/h, so the ECU computes on exactly what it publishes;
- faults (BENCH_AbsSensorFault, docs/contract/plant.md PLANT-IO-ABS-03), one wheel at a time: OPEN_LINE reads 0,
  SHORT reads full scale (204.75 km/h, beyond the measuring range), STUCK holds the first reading taken with the
  fault active. The random draws are the same with or without a fault, so the other wheels read as before.

The same model feeds the simulated ABS (its wires, plant/ecus/abs.py) and an external one (IO_AbsSensors,
plant/braking_plant.py).

Deterministic: the generator is `random.Random(seed)`, re-seeded by `reset`, so a scenario replays the same
noise whatever ran before it.
"""

from __future__ import annotations

import math
import random
from collections.abc import Sequence
from enum import IntEnum

MEASURING_RANGE_KMH = (0.0, 200.0)   # what a healthy sensor reads (docs/contract/plant.md PLANT-IO-ABS-01)
FULL_SCALE_KMH = 204.75              # a shorted line: raw 4095 of IO_AbsSensors.WheelSensorXX


class SensorFault(IntEnum):
    """BENCH_AbsSensorFault.SensorFault's value table (dbc/bench.dbc)."""

    NONE = 0
    OPEN_LINE = 1
    SHORT = 2
    STUCK = 3


class WheelSpeedSensors:
    """Four sensors FL, FR, RL, RR sampled by the ECU."""

    __slots__ = ("quantum", "roughness_ratio", "roughness_time", "seed", "noise", "_rng", "_rough", "fault_wheel",
                 "fault", "_held")

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
        self.fault_wheel = 0
        self.fault = SensorFault.NONE
        self._held: float | None = None          # a STUCK sensor's reading

    def set_fault(self, wheel: float, fault: float) -> None:
        """The fault of BENCH_AbsSensorFault from the next sample on: `wheel` 0-3 (FL, FR, RL, RR), `fault` a
        SensorFault value; anything else means NONE. A change of wheel or fault ends a STUCK's held reading."""
        try:
            kind = SensorFault(int(fault)) if 0 <= wheel <= 3 else SensorFault.NONE
        except (ValueError, OverflowError):
            kind = SensorFault.NONE
        iwheel = int(wheel) if kind != SensorFault.NONE else 0
        if kind != self.fault or iwheel != self.fault_wheel:
            self._held = None
        self.fault, self.fault_wheel = kind, iwheel

    def sample(self, true_kmh: Sequence[float], dt: float) -> list[float]:
        """One reading per wheel, km/h, quantised; dt = time since the previous sample (roughness)."""
        sigma = self.noise
        q = self.quantum
        lo, hi = MEASURING_RANGE_KMH
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
        if self.fault:
            self._apply_fault(out)
        return out

    def _apply_fault(self, out: list[float]) -> None:
        i, fault = self.fault_wheel, self.fault
        if fault == SensorFault.OPEN_LINE:
            out[i] = 0.0
        elif fault == SensorFault.SHORT:
            out[i] = FULL_SCALE_KMH
        else:   # STUCK
            if self._held is None:
                self._held = out[i]
            out[i] = self._held
