"""Pressure-modulation logic of the reference ABS: Bosch-style phases on wheel deceleration and slip, one
phase machine per wheel (each wheel's own control state, which [P4] §3.2's side pattern "Dec1, Dec3, Inc2,
Inc4" reads; plant/ecus/abs.py combines the rear two select-low into one rear-axle command).

The cycle (after the Bosch Automotive Handbook's ABS control cycle on high friction, simplified):

  OFF           valves unpowered (INCREASE): the wheel follows the driver. Control starts when the wheel
                decelerates beyond -a (decel_threshold) with a slip beyond lambda_1 / 2 (a pressure step alone
                decelerates a wheel beyond -a for a few ms), or decelerates at a slip beyond lambda_1 (a slow
                lock-up that never reaches -a) -> HOLD_ENTRY; slip beyond slip_max -> DECREASE.
  HOLD_ENTRY    phase 2: hold; slip beyond lambda_1 (slip_threshold) -> DECREASE; the deceleration recovers
                above -a first (the tyre carried the pressure) -> REAPPLY.
  DECREASE      phases 3 and 8: outlet open until the wheel re-accelerates (acceleration above decrease_end,
                0 m/s^2) and the slip is below slip_max.
  HOLD_REACCEL  phases 4-6: hold while the wheel re-accelerates; when its acceleration, having exceeded +a
                (accel_threshold), falls back below +a, or the slip is back under lambda_1 / 2 -> REAPPLY.
                A wheel that stays above lambda_1 for hold_timeout without re-accelerating gets another
                DECREASE (low friction); deceleration beyond -a or slip beyond slip_max -> DECREASE.
  REAPPLY       phases 5 and 7: full-rate increase for fast_reapply_time, then the stepped increase as an
                inlet duty of step_duty (PWM, averaged by plant/brakes.py). A decelerating wheel with the slip
                beyond lambda_1 -> DECREASE (phase 8); deceleration beyond -a alone -> STEP_HOLD. After
                reapply_timeout without a new cycle the pressure is back at the driver's: -> OFF.
  STEP_HOLD     a pause of the stepped increase (phase 7): as HOLD_ENTRY, back to the stepped increase when the
                deceleration recovers.
  RELEASED      outlet open, pressure dumped and kept at zero, until `resume` (the ECU's rear axle in an
                identified braked turn, plant/ecus/abs.py).

Any phase -> OFF when the brake switch opens or the reference speed is below abs_min_speed. The end of
HOLD_REACCEL (into REAPPLY) is the "hold -> increase switching point" of [P4] §3.2-3.3; `cycle_state`
reports the phase so that it shows on the bus as DECREASE -> INCREASE.

Thresholds (plant/vehicles/abs.toml, chosen): -a = 20 m/s^2 (a braked wheel on dry asphalt decelerates at
about 10 m/s^2 with the car; beyond twice that it is running away), +a = 3 m/s^2, lambda_1 = 0.16 (the dry
curve is within 2 % of its peak from 0.12 to 0.3; the wet one peaks at 0.088 and is past it), slip_max 0.35.

Slip of a wheel = (v_ref_i - v_i) / v_ref_i with v_ref_i the reference speed moved to that wheel (the
estimator's four-wheel model, so that an inner wheel of a turn is not taken for a slipping one);
wheel acceleration = difference of the sensor speeds over 20 ms (plant/ecus/abs.py ACCEL_WINDOW), m/s^2.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

from plant.brakes import Valve

KMH = 3.6


class Phase(IntEnum):
    OFF = 0
    HOLD_ENTRY = 1
    DECREASE = 2
    HOLD_REACCEL = 3
    REAPPLY = 4
    STEP_HOLD = 5
    RELEASED = 6


@dataclass(frozen=True)
class ControlConfig:
    decel_threshold: float        # -a, as a positive number, m/s^2
    accel_threshold: float        # +a, m/s^2
    slip_threshold: float         # lambda_1
    slip_max: float
    fast_reapply_time: float      # s
    step_duty: float              # inlet duty of the stepped increase, (0, 1]
    abs_min_speed: float          # km/h
    decrease_end: float = 0.0     # m/s^2: the decrease lasts until the wheel re-accelerates
    period: float = 0.005         # s
    hold_timeout: float = 0.04    # s (chosen)
    reapply_timeout: float = 0.6  # s (chosen)


#: enum members as module constants: an enum class attribute is a slow lookup in 3.11, and the phase machine
#: compares a dozen of them per wheel and control period
_P_OFF = Phase.OFF
_P_HOLD_ENTRY = Phase.HOLD_ENTRY
_P_DECREASE = Phase.DECREASE
_P_HOLD_REACCEL = Phase.HOLD_REACCEL
_P_REAPPLY = Phase.REAPPLY
_P_STEP_HOLD = Phase.STEP_HOLD
_P_RELEASED = Phase.RELEASED
_V_INCREASE, _V_HOLD, _V_DECREASE = Valve.INCREASE, Valve.HOLD, Valve.DECREASE


class WheelController:
    """One wheel's phase machine (module doc)."""

    __slots__ = ("c", "phase", "time_in_phase", "seen_plus")

    def __init__(self, config: ControlConfig) -> None:
        self.c = config
        self.reset()

    def reset(self) -> None:
        self.phase = _P_OFF
        self.time_in_phase = 0.0
        self.seen_plus = False

    def _go(self, phase: Phase) -> None:
        self.phase = phase
        self.time_in_phase = 0.0
        self.seen_plus = False

    def step(self, ref_kmh: float, wheel_kmh: float, accel: float, braking: bool,
             slip_threshold: float | None = None) -> tuple[Valve, float]:
        """Advance one control period; returns the valve command and the inlet duty. `slip_threshold`
        replaces lambda_1 (the ECU lowers it on the front axle in an identified turn)."""
        c = self.c
        lam = c.slip_threshold if slip_threshold is None else slip_threshold
        self.time_in_phase += c.period
        if not braking or ref_kmh < c.abs_min_speed:
            if self.phase != _P_OFF:
                self._go(_P_OFF)
            return _V_INCREASE, 1.0
        slip = (ref_kmh - wheel_kmh) / ref_kmh
        minus_a = -c.decel_threshold
        phase = self.phase
        if phase == _P_OFF:
            if slip > c.slip_max:
                self._go(_P_DECREASE)
            elif (accel < minus_a and slip > 0.5 * lam) or (accel < 0.0 and slip > lam):
                self._go(_P_HOLD_ENTRY)
        elif phase in (_P_HOLD_ENTRY, _P_STEP_HOLD):
            if slip > lam:
                self._go(_P_DECREASE)
            elif accel > minus_a:
                self._go(_P_REAPPLY)
                self.time_in_phase = c.fast_reapply_time    # straight into the stepped increase
        elif phase == _P_DECREASE:
            if accel > c.decrease_end and slip < c.slip_max:
                self._go(_P_HOLD_REACCEL)
        elif phase == _P_HOLD_REACCEL:
            if accel > c.accel_threshold:
                self.seen_plus = True
            if accel < minus_a or slip > c.slip_max:
                self._go(_P_DECREASE)
            elif (self.seen_plus and accel < c.accel_threshold) or (
                    slip < 0.5 * lam and accel < c.accel_threshold):
                self._go(_P_REAPPLY)
            elif not self.seen_plus and slip > lam and self.time_in_phase >= c.hold_timeout:
                self._go(_P_DECREASE)
        elif phase == _P_RELEASED:
            pass
        elif phase == _P_REAPPLY:
            if slip > c.slip_max or (accel < 0.0 and slip > lam):
                self._go(_P_DECREASE)
            elif accel < minus_a:
                self._go(_P_STEP_HOLD)
            elif self.time_in_phase >= c.reapply_timeout:
                self._go(_P_OFF)
        return self.command()

    def command(self) -> tuple[Valve, float]:
        phase = self.phase
        if phase == _P_OFF:
            return _V_INCREASE, 1.0
        if phase in (_P_HOLD_ENTRY, _P_HOLD_REACCEL, _P_STEP_HOLD):
            return _V_HOLD, 1.0
        if phase in (_P_DECREASE, _P_RELEASED):
            return _V_DECREASE, 1.0
        return _V_INCREASE, (1.0 if self.time_in_phase < self.c.fast_reapply_time else self.c.step_duty)

    def release(self) -> None:
        """Dump the pressure and keep the outlet open (the ECU's rear axle in an identified braked turn)."""
        if self.phase != _P_RELEASED:
            self._go(_P_RELEASED)

    def resume(self) -> None:
        """Back from RELEASED: re-apply (fast, then stepped) as after a cycle."""
        if self.phase == _P_RELEASED:
            self._go(_P_REAPPLY)

    @property
    def cycle_state(self) -> Valve:
        """The phase of the pressure cycle as ABS_SteerState.PressureStateXX reports it: DECREASE from the start
        of a reduction until the wheel has re-accelerated (phases 3-4: outlet open, then the hold that lets the
        wheel recover), INCREASE while the pressure is rebuilt or follows the driver (phases 5-7 and OFF),
        HOLD for the hold before the first reduction (phase 2); a pause of the stepped increase (phase 7) is
        INCREASE. The end of the re-acceleration hold, DECREASE ->
        INCREASE on the bus, is the hold->increase switching point of [P4] §3.2-3.3."""
        phase = self.phase
        if phase in (_P_DECREASE, _P_HOLD_REACCEL, _P_RELEASED):
            return _V_DECREASE
        if phase == _P_HOLD_ENTRY:
            return _V_HOLD
        return _V_INCREASE

    @property
    def active(self) -> bool:
        return self.phase != _P_OFF
