"""Reference ABS ECU (node ABS, [P4]): wheel-speed sensing, Bosch-style pressure modulation
(plant/ecus/abs_control.py), turning-state identification and reference speed (plant/ecus/abs_estimator.py);
publishes ABS_WheelSpeeds and ABS_SteerState (dbc/chassis.dbc).

Timing (bench time, so it is the same in every run): the control loop runs every control_period (5 ms) at
multiples of it; the estimator and the outputs every 10 ms (the messages' cycle) at multiples of 10 ms, after
that tick's control step. The estimator is fed exactly what is published in the same 10 ms window: the
quantised sensor speeds (ABS_WheelSpeeds), the cycle phases (PressureStateXX), AbsActive, and the brake
switch (DRV_Pedals, which the ABS receives per the contract), so a log replays to the same flags.

Control strategy (chosen, documented):
  - individual control of the front wheels, select-low on the rear axle (both rear circuits get the command
    of the rear wheel nearer to locking: the classic rear-axle stability choice); PressureStateXX reports each
    wheel's own cycle phase (WheelController.cycle_state), the control states [P4] §3.2 reads;
  - slip thresholds against the reference speed moved to each wheel by the four-wheel model (eq. 4, 14) with
    the estimator's yaw rate, so that the inner wheels of a turn are not taken for slipping ones;
  - in an identified braked turn (AbsActive and TurnDirection != 0) the rear axle is released (pressure dumped,
    the rear wheels roll freely: full rear side force, and the rear axle becomes the kinematic reference of
    [P4] eq. 5, 7, 9, 12 for the estimator's step 3) and the front wheels use the lower slip threshold
    turn_front_slip_threshold (side force); the rear axle re-applies when the turn ends.

Hardware it needs from the plant (direct references, no bus latency, like a real ECU's wires): the four
wheel-speed sensors and the hydraulic unit's valves (`AbsHardware`). Without them (PLANT external) it
still publishes, from sensors it cannot read, nothing but its start values; the assembly does not build it then.

Inputs from the bus: DRV_Pedals (brake switch: the driver's demand of plant/brakes.py at or above
brake_switch_pressure).

AbsFault (value table): 0 OK; 1 WHEEL_SPEED_INVALID: a sensor reads non-finite or outside its measuring range
0-200 km/h (a shorted line reads 204.75, plant/sensors.py), or reads
below 1 km/h for 0.5 s while the other three read above 20 km/h without braking (an open sensor line);
2 INPUT_TIMEOUT: DRV_Pedals never received or timed out. In a fault the ABS is passive (valves unpowered:
the brakes work without ABS), TurnDirection is 0 and the estimate is restarted when the fault clears.
Published values are clamped to their DBC ranges (never a NaN on the bus).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping, Sequence
from enum import IntEnum
from typing import Protocol

from bench.sim.node import DiagnosticSide, NodeIO
from plant import signal_ranges as ranges
from plant.brakes import Valve
from plant.ecus.abs_control import ControlConfig, WheelController
from plant.ecus.abs_estimator import STRAIGHT, Estimate, EstimatorConfig, TurnStateEstimator
from plant.ecus.diagnostics import EcuDiagnostics
from plant.sensors import MEASURING_RANGE_KMH
from plant.vehicles import AbsParams, AclassParams

KMH = 3.6
OUTPUT_PERIOD_MS = 10            # ABS_WheelSpeeds / ABS_SteerState cycle (dbc/chassis.dbc)
ACCEL_WINDOW = 4                 # control periods over which the wheel acceleration is differenced (20 ms)
SENSOR_LOST_KMH, SENSOR_OTHERS_KMH, SENSOR_LOST_S = 1.0, 20.0, 0.5
_SENSOR_LO, _SENSOR_HI = MEASURING_RANGE_KMH    # a reading outside is a sensor fault (a shorted line: 204.75)
#: select-low on the rear axle: DECREASE wins over HOLD, HOLD over INCREASE
_SELECT_LOW_RANK = {Valve.INCREASE: 0, Valve.HOLD: 1, Valve.DECREASE: 2}


class AbsFault(IntEnum):
    OK = 0
    WHEEL_SPEED_INVALID = 1
    INPUT_TIMEOUT = 2


_FAULT_OK = AbsFault.OK      # (an enum class attribute is a slow lookup; the control step compares it often)


class AbsHardware(Protocol):
    """What the ECU is wired to in the plant."""

    def read_sensors(self, dt: float) -> list[float]:
        """The four wheel-speed sensor readings now (km/h, FL, FR, RL, RR); dt since the last reading."""

    def command_valves(self, valves: Sequence[Valve], duties: Sequence[float]) -> None:
        """Set the inlet/outlet valves of the four wheel circuits."""

    def release_valves(self) -> None:
        """Valves unpowered (the brakes work without ABS)."""


def brake_demand(pedals: Mapping[str, float], pedal_to_pressure: float) -> float:
    """The driver's brake demand from DRV_Pedals, bar: BrakePressure when non-zero, else BrakePedal (%) times
    pedal_to_pressure (plant/brakes.py reads the pedals the same way)."""
    pressure = pedals.get("BrakePressure", 0.0)
    if math.isfinite(pressure) and pressure > 0.0:
        return pressure
    pedal = pedals.get("BrakePedal", 0.0)
    return pedal * pedal_to_pressure if math.isfinite(pedal) and pedal > 0.0 else 0.0


def estimator_config(params: AbsParams, car: AclassParams) -> EstimatorConfig:
    """The estimator of the reference ECU: geometry of docs/spec/vehicles.md B, calibration and thresholds of
    abs.toml."""
    return EstimatorConfig(track=car.track, wheelbase=car.wheelbase, cog_to_front_axle=car.cog_to_front_axle,
                           stability_factor=params.stability_factor, v_l0=params.v_l0, v_l1=params.v_l1,
                           v_l2=params.v_l2, t0=params.t0, t1=params.t1, period=OUTPUT_PERIOD_MS / 1000.0,
                           speed_filter_time=params.speed_filter_time, min_turn_speed=params.min_turn_speed,
                           min_delta_speed=params.min_delta_speed, rear_release_time=params.rear_release_time,
                           delta_average_points=int(params.delta_average_points))


def _clamp(value: float, bounds: tuple[float, float]) -> float:
    lo, hi = bounds
    if value != value:
        return 0.0
    return lo if value < lo else hi if value > hi else value


class AbsEcu:
    """The ABS node."""

    nodes: tuple[str, ...] = ("ABS",)

    def __init__(self, params: AbsParams, car: AclassParams, hardware: AbsHardware) -> None:
        self.params = params
        self.hardware = hardware
        self.config = estimator_config(params, car)
        self.control = ControlConfig(
            decel_threshold=params.decel_threshold, accel_threshold=params.accel_threshold,
            slip_threshold=params.slip_threshold, slip_max=params.slip_max,
            fast_reapply_time=params.fast_reapply_time, step_duty=params.step_duty,
            abs_min_speed=params.abs_min_speed, period=params.control_period)
        self._control_ms = round(params.control_period * 1000.0)
        if self._control_ms < 1 or OUTPUT_PERIOD_MS % self._control_ms:
            raise ValueError(f"ABS control_period must be a whole number of ms dividing {OUTPUT_PERIOD_MS} ms, "
                             f"got {params.control_period!r} s")
        self._turn_front_slip = params.turn_front_slip_threshold
        self._half_track = car.track / 2.0
        self._a = car.cog_to_front_axle
        self.estimator = TurnStateEstimator(self.config)
        self.wheels = [WheelController(self.control) for _ in range(4)]
        self.diagnostics = EcuDiagnostics("ABS", AbsFault, self._diagnostic_setup)
        self.reset()

    def reset(self) -> None:
        self.estimator.reset()
        for w in self.wheels:
            w.reset()
        self.speeds = [0.0, 0.0, 0.0, 0.0]          # latest sensor readings, km/h
        self._history: deque[list[float]] = deque(maxlen=ACCEL_WINDOW + 1)
        self.valves: list[Valve] = [Valve.INCREASE] * 4
        self.braking = False
        self.fault = AbsFault.OK
        self.estimate: Estimate | None = None
        self._est_t = 0.0
        self._last_ms: int | None = None
        self._lost_time = 0.0

    # -- per tick ----------------------------------------------------------------------------------------
    def step(self, io: NodeIO, t: float, dt: float) -> None:
        ms = round(t * 1000.0)
        if ms == self._last_ms or ms % self._control_ms:
            return
        self._last_ms = ms
        self._control_step(io, t)
        self.diagnostics.report(io, t, int(self.fault))
        if ms % OUTPUT_PERIOD_MS == 0:
            self._output_step(io, t)

    def _diagnostic_setup(self, side: DiagnosticSide, io: NodeIO) -> None:
        """What an ECUReset does, and the DID only the reference ABS knows (docs/contract/abs.md ABS-DIAG-*)."""
        side.on_reset(self.reset)

        def demand() -> float:
            pedals = io.latest("DRV_Pedals")
            return math.nan if pedals is None else brake_demand(pedals, self.params.pedal_to_pressure)

        side.provide("BrakeDemand", demand)

    def _control_step(self, io: NodeIO, t: float) -> None:
        p = self.params
        period = self.control.period
        pedals = io.latest("DRV_Pedals")
        speeds = self.hardware.read_sensors(period)
        fault = _FAULT_OK
        if not all(math.isfinite(v) and _SENSOR_LO <= v <= _SENSOR_HI for v in speeds):
            fault = AbsFault.WHEEL_SPEED_INVALID
            speeds = [_clamp(v, ranges.ABS_WHEEL_SPEED) for v in speeds]
        self.speeds = speeds
        self._history.append(speeds)
        braking = pedals is not None and brake_demand(pedals, p.pedal_to_pressure) >= p.brake_switch_pressure
        self.braking = braking
        lost = not braking and any(speeds[i] < SENSOR_LOST_KMH and all(speeds[j] > SENSOR_OTHERS_KMH
                                                                       for j in range(4) if j != i)
                                   for i in range(4))
        self._lost_time = self._lost_time + period if lost else 0.0
        if self._lost_time >= SENSOR_LOST_S:
            fault = AbsFault.WHEEL_SPEED_INVALID
        if fault == _FAULT_OK and pedals is None:
            fault = AbsFault.INPUT_TIMEOUT
        if fault != self.fault:
            if fault != _FAULT_OK:
                for w in self.wheels:
                    w.reset()
            else:
                self.estimator.reset()
            self.fault = fault
        if fault != _FAULT_OK:
            self.valves = [Valve.INCREASE] * 4
            self.hardware.release_valves()
            return
        refs = self._wheel_references(t)
        turn_mode = self.active and self.estimate is not None and self.estimate.turn != STRAIGHT
        h = self._history
        span = (len(h) - 1) * period
        duties = []
        for i, wheel in enumerate(self.wheels):
            accel = (h[-1][i] - h[0][i]) / KMH / span if span > 0.0 else 0.0
            if i >= 2:
                if turn_mode:
                    wheel.release()
                else:
                    wheel.resume()
            lam = self._turn_front_slip if turn_mode and i < 2 else None
            valve, duty = wheel.step(refs[i], speeds[i], accel, braking, lam)
            self.valves[i] = valve
            duties.append(duty)
        # rear axle select-low: both rear circuits get the command of the wheel nearer to locking
        rear = max(self.valves[2], self.valves[3], key=_SELECT_LOW_RANK.__getitem__)
        self.valves[2] = self.valves[3] = rear
        duties[2] = duties[3] = min(duties[2], duties[3])
        self.hardware.command_valves(self.valves, duties)

    def _wheel_references(self, t: float) -> list[float]:
        """The reference speed moved to each wheel (eq. 4 / 14 inverted), extrapolated to now during ABS."""
        est = self.estimate
        if est is None:
            return list(self.speeds)
        v = est.ref_speed + (est.slope * (t - self._est_t) if self.active else 0.0)
        if est.turn == STRAIGHT:
            return [v, v, v, v]
        r = est.yaw_rate * KMH
        half, ad = self._half_track, self._a * math.radians(est.delta_deg)
        return [v + (ad - half) * r, v + (ad + half) * r, v - half * r, v + half * r]

    @property
    def active(self) -> bool:
        return any(w.active for w in self.wheels)

    def _output_step(self, io: NodeIO, t: float) -> None:
        speeds = self.speeds
        states = [int(w.cycle_state) for w in self.wheels]
        active = self.active and self.fault == _FAULT_OK
        if self.fault == _FAULT_OK:
            est = self.estimator.update(speeds, states, active, self.braking)
            self.estimate, self._est_t = est, t
            turn, ref, angle = est.turn, est.ref_speed, -est.delta_deg   # bus: angle positive right
        else:
            self.estimate = None
            turn, ref, angle = 0, sorted(speeds)[1], 0.0
        io.send_values("ABS_WheelSpeeds", WheelSpeedFL=speeds[0], WheelSpeedFR=speeds[1],
                       WheelSpeedRL=speeds[2], WheelSpeedRR=speeds[3])
        io.send_values("ABS_SteerState", RefVehicleSpeed=_clamp(ref, ranges.ABS_REF_SPEED),
                       FrontWheelAngleEst=_clamp(angle, ranges.ABS_ANGLE), TurnDirection=turn,
                       AbsActive=1 if active else 0, PressureStateFL=states[0], PressureStateFR=states[1],
                       PressureStateRL=states[2], PressureStateRR=states[3], AbsFault=int(self.fault))
