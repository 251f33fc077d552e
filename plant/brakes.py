"""Brake hydraulics of the A-class car (docs/spec/vehicles.md B): master cylinder, four wheel circuits with an ABS
inlet and outlet valve each, finite pressure rates, brake torque.

Why orifice flow: the pressure rate of a valve is set by the flow through its orifice, which grows with the
square root of the pressure difference; so a wheel far below the master pressure fills fast and slows as it
approaches it, and a high pressure dumps faster than a low one, as a real hydraulic unit does.

Per wheel circuit, pressure p (bar), master pressure p_m:

    INCREASE (inlet open, outlet closed):  dp/dt = duty * k_in * sign(p_m - p) sqrt(|p_m - p|)
    HOLD     (both closed):                dp/dt = 0
    DECREASE (inlet closed, outlet open):  dp/dt = -k_out * sqrt(p)     (to the low-pressure accumulator)

`duty` in (0, 1] is the inlet valve's averaged opening (the ABS ECU's slow "stepped" increase is a PWM of
the inlet valve, averaged here). The step never overshoots the target of the flow. Unpowered valves are
INCREASE at full duty: without an ABS (or with the bypass of BENCH_AbsStimulus) the wheels follow the master
cylinder at the inlet's rate. Brake torque = gain * p (front and rear gains, plant/vehicles/abs.toml).

Master pressure from DRV_Pedals (dbc/chassis.dbc): BrakePressure (bar) when it is non-zero, else
BrakePedal (%) * pedal_to_pressure; a driver never builds pressure instantly, so p_m follows that demand
at master_rate at most (bar/s, chosen).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from enum import IntEnum


class Valve(IntEnum):
    """ABS valve state of one wheel circuit; the numbers are ABS_SteerState.PressureStateXX's value table."""

    HOLD = 0
    INCREASE = 1
    DECREASE = 2


_INCREASE, _DECREASE = Valve.INCREASE, Valve.DECREASE    # an enum class attribute costs a lookup per tick


class BrakeHydraulics:
    """Master cylinder and four wheel circuits (FL, FR, RL, RR)."""

    __slots__ = ("k_in", "k_out", "gains", "master_rate", "pedal_to_pressure", "max_pressure",
                 "pressures", "master", "valves", "duties", "bypass")

    def __init__(self, *, inlet_flow: float, outlet_flow: float, gain_front: float, gain_rear: float,
                 master_rate: float, pedal_to_pressure: float, max_pressure: float) -> None:
        for name, value in (("inlet_flow", inlet_flow), ("outlet_flow", outlet_flow), ("gain_front", gain_front),
                            ("gain_rear", gain_rear), ("master_rate", master_rate),
                            ("pedal_to_pressure", pedal_to_pressure), ("max_pressure", max_pressure)):
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"brake hydraulics: {name} must be a positive number, got {value!r}")
        self.k_in = inlet_flow
        self.k_out = outlet_flow
        self.gains = (gain_front, gain_front, gain_rear, gain_rear)
        self.master_rate = master_rate
        self.pedal_to_pressure = pedal_to_pressure
        self.max_pressure = max_pressure
        self.reset()

    def reset(self) -> None:
        self.pressures = [0.0, 0.0, 0.0, 0.0]
        self.master = 0.0
        self.valves = [Valve.INCREASE] * 4
        self.duties = [1.0, 1.0, 1.0, 1.0]
        self.bypass = False

    def demand(self, brake_pressure: float, brake_pedal: float) -> float:
        """The master pressure the driver asks for, bar (module doc); bad values count as no braking."""
        if math.isfinite(brake_pressure) and brake_pressure > 0.0:
            return min(brake_pressure, self.max_pressure)
        if math.isfinite(brake_pedal) and brake_pedal > 0.0:
            return min(brake_pedal * self.pedal_to_pressure, self.max_pressure)
        return 0.0

    def command(self, valves: Sequence[Valve | int], duties: Sequence[float]) -> None:
        """The ABS ECU's valve commands (held until the next command). A duty of 0 closes the inlet (INCREASE at
        duty 0 holds, as IO_AbsValves.InletDutyXX says); one outside [0, 1] (or NaN) opens it fully."""
        for i in range(4):
            self.valves[i] = Valve(valves[i])
            d = duties[i]
            self.duties[i] = d if 0.0 <= d <= 1.0 else 1.0

    def release(self) -> None:
        """Valves unpowered (the ABS is passive): every circuit follows the master cylinder."""
        self.valves = [Valve.INCREASE] * 4
        self.duties = [1.0, 1.0, 1.0, 1.0]

    def step(self, demand: float, dt: float) -> None:
        """Advance the master and wheel pressures by dt towards the driver's demand (bar)."""
        m = self.master
        dm = self.master_rate * dt
        m = min(demand, m + dm) if demand > m else max(demand, m - dm)
        self.master = m
        sqrt = math.sqrt
        k_in, k_out = self.k_in * dt, self.k_out * dt
        bypass = self.bypass
        pressures, valves, duties = self.pressures, self.valves, self.duties
        for i in range(4):
            p = pressures[i]
            valve = _INCREASE if bypass else valves[i]
            if valve == _INCREASE:
                diff = m - p
                step = (1.0 if bypass else duties[i]) * k_in * sqrt(abs(diff))
                p = min(m, p + step) if diff > 0.0 else max(m, p - step)
            elif valve == _DECREASE:
                p = max(0.0, p - k_out * sqrt(p))
            pressures[i] = p

    def torques(self) -> tuple[float, float, float, float]:
        """Brake torque of each wheel, N*m (>= 0; it opposes the wheel's rotation)."""
        p, g = self.pressures, self.gains
        return (g[0] * p[0], g[1] * p[1], g[2] * p[2], g[3] * p[3])
