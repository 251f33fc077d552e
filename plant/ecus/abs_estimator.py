"""Turning-state identification and reference speed of the ABS ([P4] eq. 5-14, docs/spec/formulas.md §6), as a pure
class: no bus, no plant. The reference ABS ECU (plant/ecus/abs.py) runs it on exactly what it publishes
(ABS_WheelSpeeds, the PressureStateXX and AbsActive of ABS_SteerState, and its brake switch), so a replay of
a recorded log gives the same flags (tests/integration/test_abs_replay.py).

Signs are the paper's: wheels 1-4 = FL, FR, RL, RR; yaw rate r > 0 and road-wheel angle delta > 0 for a LEFT
turn; T = 1 left, -1 right, 0 straight (the exception of docs/spec/formulas.md §1, kept on the bus in TurnDirection).
The ECU negates delta for FrontWheelAngleEst (bus: positive right). Speeds in km/h, as on the bus.

Before ABS control ([P4] §3.1, "before braking" and "braking before ABS" merged as the paper does):
  - the wheel speeds are low-pass filtered (first order, speed_filter_time: the paper's "anti-interference
    measures"; eq. 13 on raw 10 ms samples would flag every noise burst);
  - dV1 = V2 - V1 (6), dV2 = V4 - V3 (7), ddV = |dV1 - dV2| (8) of the filtered speeds;
  - T from eq. 13 with erratum E3 corrected (ddV < V_l2 for BOTH signs); a new value is taken once it has
    held t1 (the same confirmation time as in ABS control); none below min_turn_speed;
  - delta from eq. 12 with x = the filtered rear mean (5) when T != 0, else 0;
  - reference speed, [P4] §3.3 wheel selection: not braking: rear mean (5, 10) in a turn, third-largest
    wheel when straight; braking: second-largest wheel.
During ABS control ([P4] §3.2 and §3.3):
  - a wheel's "hold->increase switching point" is, on the bus, its first sample in INCREASE after it was in
    DECREASE: the end of a pressure cycle, where the wheel has re-accelerated (the reference ECU reports the
    cycle's phase, plant/ecus/abs_control.py); a pause inside the stepped increase is not one;
  - step 1: one side's two wheels decreasing while the other side's are in INCREASE (left turn: Dec1, Dec3,
    Inc2, Inc4), held for t0, arms the identification for that side. A wheel counts as decreasing when it was
    in DECREASE in an update of the last pattern_window; the other side's must be in INCREASE in the update
    itself; both sides matching is no pattern. The inner front wheel (individual control) and the inner rear
    wheel (select-low) cycle on their own: their DECREASE stretches often alternate, and read from one
    update's states alone the pattern appeared only when the cycles' phases overlapped (docs/contract/abs.md
    ABS-TURN-01);
  - step 2: at the switching points of the armed side's (inner) wheels, while the outer wheel of the same axle
    is in INCREASE, the axle's speed difference is taken (dV1 at the front, dV2 at the rear); with both axles
    measured, eq. 13 (E3 corrected) gives a candidate T, kept only if it agrees with the armed side; a non-zero
    candidate that no later evaluation contradicts for t1 is confirmed;
  - step 3 ("then identify delta and V_f as before ABS control"): the reference ECU releases the rear axle in
    an identified turn (both rear PressureStates DECREASE), so after rear_release_time the rear wheels roll
    freely and the method before ABS applies to them: V_f = rear mean (eq. 5, 10) and delta from eq. 12 with
    the moving average ([P4] §4: delta-bar) of dV2 over delta_average_points samples, published once
    the window is full (0 until then: "not identified yet"); the yaw rate of eq. 9 from the same window is
    given to the ECU for its wheel references; the turn ends when the averaged dV2 stays below V_l0 for t1;
  - reference speed otherwise ([P4] §3.3 interpolation): each switching point gives a point, the wheel's
    speed times (1 + decel / (g k_s)) - at the end of its re-acceleration a wheel still carries its share of
    the braking, with a slip of about that (point_slip_stiffness k_s, chosen) - moved to the CoG by the
    four-wheel model (eq. 4, 14; r from eq. 11 with the identified delta; no correction when T = 0); the
    reference speed and its slope are the least-squares line through the points of the last point_window
    (the slope bounded to [-max_decel, 0]); between points it is extrapolated with that slope, and it is never
    below the second-largest corrected wheel speed ([P4]: the second-largest wheel during braking).
Below min_delta_speed the published delta is held (eq. 12's gain grows as 1/x: it would amplify the noise).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass

KMH = 3.6
G = 9.81

HOLD, INCREASE, DECREASE = 0, 1, 2          # ABS_SteerState.PressureStateXX value table (dbc/chassis.dbc)
LEFT, STRAIGHT, RIGHT = 1, 0, -1            # ABS_SteerState.TurnDirection value table


def turn_direction(dv1: float, dv2: float, ddv: float, v_l0: float, v_l1: float, v_l2: float) -> int:
    """[P4] eq. 13 with erratum E3 corrected (docs/spec/formulas.md §6): ddV < V_l2 for both signs.

    T = 1 if V_l0 < dV1, dV2 < V_l1 and ddV < V_l2; T = -1 if V_l0 < -dV1, -dV2 < V_l1 and ddV < V_l2; else 0."""
    if ddv >= v_l2:
        return STRAIGHT
    if v_l0 < dv1 < v_l1 and v_l0 < dv2 < v_l1:
        return LEFT
    if v_l0 < -dv1 < v_l1 and v_l0 < -dv2 < v_l1:
        return RIGHT
    return STRAIGHT


def front_wheel_angle(dv2_kmh: float, x_kmh: float, wheelbase: float, track: float, k: float) -> float:
    """[P4] eq. 12: delta = L (1 + K x^2) dV2 / (B x), rad (left positive); x and dV2 in km/h."""
    x = x_kmh / KMH
    return wheelbase * (1.0 + k * x * x) * (dv2_kmh / KMH) / (track * x)


def yaw_rate(delta: float, x_kmh: float, wheelbase: float, k: float) -> float:
    """[P4] eq. 11: r = delta (x / L) / (1 + K x^2), rad/s (left positive)."""
    x = x_kmh / KMH
    return delta * x / wheelbase / (1.0 + k * x * x)


def nth_largest(values: Sequence[float], n: int) -> float:
    """The n-th largest of the values (n = 1 is the largest)."""
    return sorted(values, reverse=True)[n - 1]


@dataclass(frozen=True)
class EstimatorConfig:
    """Vehicle geometry (docs/spec/vehicles.md B), the ECU's calibration and [P4]'s thresholds (abs.toml)."""

    track: float                 # B, m
    wheelbase: float             # L, m
    cog_to_front_axle: float     # a, m
    stability_factor: float      # K, s^2/m^2
    v_l0: float                  # km/h
    v_l1: float                  # km/h
    v_l2: float                  # km/h
    t0: float                    # s
    t1: float                    # s
    period: float = 0.01         # s between updates (ABS_SteerState cycle)
    speed_filter_time: float = 0.3
    min_turn_speed: float = 5.0  # km/h
    min_delta_speed: float = 20.0   # km/h: below it delta is held (eq. 12's gain grows as 1/x: noise)
    delta_average_points: int = 30
    max_decel: float = 1.3 * G   # m/s^2, bound of the reference-speed slope during ABS (chosen)
    point_slip_stiffness: float = 13.0   # 1/slip: braking force per load per unit slip at a point (chosen)
    rear_release_time: float = 0.1   # s the released rear axle needs to roll freely (chosen)
    point_window: float = 0.3    # s of interpolation points in the reference-speed fit (chosen)
    min_point_span: float = 0.08 # s the points must span before they give a slope (chosen)
    pattern_window: float = 0.1  # s a DECREASE counts for the side pattern of step 1 (chosen)

    def __post_init__(self) -> None:
        for name in ("track", "wheelbase", "cog_to_front_axle", "v_l0", "v_l1", "v_l2", "t0", "t1", "period",
                     "speed_filter_time", "min_turn_speed", "min_delta_speed", "max_decel", "point_window",
                     "min_point_span", "rear_release_time", "point_slip_stiffness", "pattern_window"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"estimator config: {name} must be a positive number, got {value!r}")
        if not (math.isfinite(self.stability_factor) and self.stability_factor >= 0.0):
            raise ValueError(f"estimator config: stability_factor must be >= 0, got {self.stability_factor!r}")
        if not self.v_l0 < self.v_l1:
            raise ValueError(f"estimator config: v_l0 ({self.v_l0}) must be below v_l1 ({self.v_l1})")
        if self.delta_average_points < 1:
            raise ValueError("estimator config: delta_average_points must be at least 1")


@dataclass(frozen=True, slots=True)
class Estimate:
    """One update's result: T (paper sign), reference speed (km/h), delta (deg, LEFT positive), yaw rate used
    for the corrections (rad/s, left positive) and the slope of the reference speed (km/h/s)."""

    turn: int
    ref_speed: float
    delta_deg: float
    yaw_rate: float
    slope: float


class TurnStateEstimator:
    """[P4]'s identification of P = {V, T, delta} (module doc). Call `update` every `config.period`."""

    def __init__(self, config: EstimatorConfig) -> None:
        self.c = config
        self._eps = 1e-9
        self.reset()

    def reset(self) -> None:
        self.t = 0.0
        self.turn = STRAIGHT
        self.ref_speed = 0.0
        self.delta = 0.0                    # rad, left positive
        self.slope = 0.0                    # km/h/s
        self._filtered: list[float] | None = None
        self._cand, self._cand_time = STRAIGHT, 0.0
        self._in_abs = False
        self._decreased = [False] * 4
        self._rear_free_time = self._end_time = 0.0
        self._rear_window: deque[tuple[float, float]] = deque(maxlen=int(self.c.delta_average_points))
        self._yaw: float | None = None      # rad/s from the released rear axle (eq. 9)
        self._pattern_side, self._pattern_time = STRAIGHT, 0.0
        self._last_decrease: list[float | None] = [None] * 4   # time of each wheel's latest DECREASE update
        self._armed = STRAIGHT
        self._dv1: float | None = None
        self._dv2: float | None = None
        self._abs_cand, self._abs_cand_t = STRAIGHT, 0.0
        self._points: deque[tuple[float, int, float]] = deque()   # (t, wheel, speed) interpolation points
        self._history: deque[tuple[float, float]] = deque(maxlen=6)   # (t, ref speed) before ABS, for a slope

    # -- one update --------------------------------------------------------------------------------------
    def update(self, speeds: Sequence[float], states: Sequence[int], abs_active: bool, braking: bool) -> Estimate:
        """speeds: V_w1..V_w4 (FL, FR, RL, RR) km/h; states: PressureState per wheel (0 HOLD, 1 INCREASE,
        2 DECREASE); abs_active: the ECU modulates pressure; braking: the brake switch."""
        c = self.c
        self.t += c.period
        if abs_active:
            if not self._in_abs:
                self._enter_abs(states)
            self._abs_update(speeds, states)
        else:
            if self._in_abs:
                self._in_abs = False
                self._filtered = None          # the ABS cycles left the filter far below the wheels
            self._free_update(speeds, braking)
        if self._yaw is not None and self.turn:
            r = self._yaw
        else:
            r = yaw_rate(self.delta, self.ref_speed, c.wheelbase, c.stability_factor) if self.turn else 0.0
        return Estimate(self.turn, self.ref_speed, math.degrees(self.delta), r, self.slope)

    # -- before ABS control ([P4] §3.1) ----------------------------------------------------------------
    def _free_update(self, speeds: Sequence[float], braking: bool) -> None:
        c = self.c
        f = self._filtered
        if f is None:
            f = self._filtered = list(speeds)
        else:
            k = c.period / (c.speed_filter_time + c.period)
            for i in range(4):
                f[i] += (speeds[i] - f[i]) * k
        if braking:
            ref = nth_largest(speeds, 2)
        elif self.turn != STRAIGHT:
            ref = 0.5 * (speeds[2] + speeds[3])
        else:
            ref = nth_largest(speeds, 3)
        self.ref_speed = ref
        self._history.append((self.t, ref))
        x = 0.5 * (f[2] + f[3])
        dv1, dv2 = f[1] - f[0], f[3] - f[2]
        raw = (turn_direction(dv1, dv2, abs(dv1 - dv2), c.v_l0, c.v_l1, c.v_l2)
               if x >= c.min_turn_speed else STRAIGHT)
        if raw == self.turn:
            self._cand, self._cand_time = raw, 0.0
        elif raw == self._cand:
            self._cand_time += c.period
        else:
            self._cand, self._cand_time = raw, c.period
        if raw != self.turn and self._cand_time >= c.t1 - self._eps:
            self.turn = raw
        if self.turn == STRAIGHT or x < c.min_turn_speed:
            self.delta = 0.0
        elif x >= c.min_delta_speed or not self.delta:
            self.delta = front_wheel_angle(dv2, x, c.wheelbase, c.track, c.stability_factor)

    # -- during ABS control ([P4] §3.2, §3.3) ----------------------------------------------------------
    def _enter_abs(self, states: Sequence[int]) -> None:
        self._in_abs = True
        self._decreased = [False] * 4
        self._rear_free_time = self._end_time = 0.0
        self._rear_window.clear()
        self._yaw = None
        self._pattern_side, self._pattern_time = STRAIGHT, 0.0
        self._last_decrease = [None] * 4
        self._armed = STRAIGHT
        self._dv1 = self._dv2 = None
        self._abs_cand, self._abs_cand_t = STRAIGHT, 0.0
        self._points.clear()
        # slope of the reference speed over the last samples before ABS (the braking deceleration so far)
        h = self._history
        if len(h) >= 2 and h[-1][0] > h[0][0]:
            s = (h[-1][1] - h[0][1]) / (h[-1][0] - h[0][0])
        else:
            s = 0.0
        self.slope = self._bounded_slope(s)

    def _offsets(self) -> tuple[float, float, float, float]:
        """Four-wheel model ([P4] eq. 4, 14): wheel speed - CoG speed per unit yaw rate, km/h per rad/s."""
        c = self.c
        half, ad = c.track / 2.0, c.cog_to_front_axle * self.delta
        return ((ad - half) * KMH, (ad + half) * KMH, -half * KMH, half * KMH)

    def _fit(self) -> tuple[float, float]:
        """Least-squares line through the interpolation points of the window: (CoG speed now, slope)."""
        offsets = self._offsets()
        r = yaw_rate(self.delta, self.ref_speed, self.c.wheelbase, self.c.stability_factor) if self.turn else 0.0
        rows = [(t - self.t, v - offsets[i] * r) for t, i, v in self._points]
        n = len(rows)
        mt = sum(x for x, _ in rows) / n
        mv = sum(y for _, y in rows) / n
        stt = sum((x - mt) ** 2 for x, _ in rows)
        slope = sum((x - mt) * (y - mv) for x, y in rows) / stt if stt > 0.0 else 0.0
        return mv - slope * mt, slope

    def _point_slip(self) -> float:
        """Slip a wheel still has when it carries its share of the braking: deceleration / (g k_s)."""
        return -self.slope / KMH / G / self.c.point_slip_stiffness

    def _bounded_slope(self, s: float) -> float:
        lo = -self.c.max_decel * KMH
        return lo if s < lo else 0.0 if s > 0.0 else s

    def _corrected(self, speeds: Sequence[float]) -> list[float]:
        """Wheel speeds moved to the CoG by the four-wheel model (eq. 4, 14), km/h; unchanged when T = 0."""
        if self.turn == STRAIGHT:
            return list(speeds)
        r = yaw_rate(self.delta, self.ref_speed, self.c.wheelbase, self.c.stability_factor)
        return [v - o * r for v, o in zip(speeds, self._offsets())]

    def _rear_free_update(self, speeds: Sequence[float], states: Sequence[int]) -> bool:
        """Step 3 on a released rear axle: True when it handled this update.

        In an identified turn the reference ECU releases the rear axle (both rear PressureStates DECREASE for
        as long as the turn lasts); once rear_release_time has let the pressure go, the rear wheels roll
        freely and [P4] §3.2 step 3 applies the method before ABS to them: reference speed = rear mean
        (eq. 5, 10); delta from eq. 12 with the moving average ([P4] §4: delta-bar) of dV2 (eq. 7) and of
        the rear mean over the last delta_average_points samples, published once that window is full; the
        turn ends (T = 0) when the averaged dV2 has not been a turn of the identified side (beyond V_l0)
        for t1."""
        c = self.c
        if self.turn == STRAIGHT or states[2] != DECREASE or states[3] != DECREASE:
            self._rear_free_time = 0.0
            self._rear_window.clear()
            self._yaw = None
            return False
        self._rear_free_time += c.period
        if self._rear_free_time < c.rear_release_time - self._eps:
            return False
        self._points.clear()
        self.ref_speed = 0.5 * (speeds[2] + speeds[3])
        window = self._rear_window
        window.append((speeds[3] - speeds[2], self.ref_speed))
        dv2 = sum(w[0] for w in window) / len(window)
        x = sum(w[1] for w in window) / len(window)
        self._yaw = dv2 / KMH / c.track                    # eq. 9, for the ECU's wheel references
        if len(window) < (window.maxlen or 0):
            return True
        if x >= c.min_turn_speed:
            if (dv2 if self.turn == LEFT else -dv2) > c.v_l0:
                self._end_time = 0.0
                if x >= c.min_delta_speed or not self.delta:
                    self.delta = front_wheel_angle(dv2, x, c.wheelbase, c.track, c.stability_factor)
            else:
                self._end_time += c.period
                if self._end_time >= c.t1 - self._eps:
                    self.turn, self.delta, self._end_time = STRAIGHT, 0.0, 0.0
        return True

    def _side_pattern(self, states: Sequence[int]) -> int:
        """Step 1's side pattern at this update: LEFT when FL and RL were each in DECREASE in an update of the
        last pattern_window (this one included) while FR and RR are in INCREASE in this update; RIGHT
        mirrored; STRAIGHT otherwise and when both sides match."""
        horizon = self.t - self.c.pattern_window + self._eps
        recent = [t is not None and t > horizon for t in self._last_decrease]
        left = recent[0] and recent[2] and states[1] == INCREASE and states[3] == INCREASE
        right = recent[1] and recent[3] and states[0] == INCREASE and states[2] == INCREASE
        if left == right:
            return STRAIGHT
        return LEFT if left else RIGHT

    def _abs_update(self, speeds: Sequence[float], states: Sequence[int]) -> None:
        c = self.c
        # a cycle's switching point: INCREASE again after a decrease (and usually a hold) of that wheel
        dec = self._decreased
        switched = [False] * 4
        for i in range(4):
            if states[i] == DECREASE:
                dec[i] = True
                self._last_decrease[i] = self.t
            elif states[i] == INCREASE:
                switched[i] = dec[i]
                dec[i] = False
        if self._rear_free_update(speeds, states):
            return
        # reference speed: extrapolate, then interpolation points, never below the second-largest wheel
        corrected = self._corrected(speeds)
        ref = self.ref_speed + self.slope * c.period
        if any(switched):
            pts = self._points
            k = 1.0 + self._point_slip()
            for i in range(4):
                if switched[i]:
                    pts.append((self.t, i, speeds[i] * k))
            while self.t - pts[0][0] > c.point_window + self._eps:
                pts.popleft()
            if pts[-1][0] - pts[0][0] >= c.min_point_span - self._eps:
                ref, slope = self._fit()
                self.slope = self._bounded_slope(slope)
            else:
                ref = max(corrected[i] for i in range(4) if switched[i]) * k
        second = nth_largest(corrected, 2)
        self.ref_speed = ref if ref > second else second
        # step 1: one side decreasing while the other increases, for t0
        side = self._side_pattern(states)
        if side != STRAIGHT and side == self._pattern_side:
            self._pattern_time += c.period
        else:
            self._pattern_side, self._pattern_time = side, (c.period if side else 0.0)
        if self._pattern_side != STRAIGHT and self._pattern_time >= c.t0 - self._eps:
            if self._armed != self._pattern_side:
                self._armed = self._pattern_side
                self._dv1 = self._dv2 = None
        # step 2: axle differences at the inner wheels' hold->increase points, outer wheel increasing
        new_front = new_rear = False
        if self._armed != STRAIGHT or self.turn != STRAIGHT:
            side = self._armed if self._armed != STRAIGHT else self.turn
            inner_f, outer_f, inner_r, outer_r = (0, 1, 2, 3) if side == LEFT else (1, 0, 3, 2)
            if switched[inner_f] and states[outer_f] == INCREASE:
                self._dv1 = speeds[1] - speeds[0]
                new_front = True
            if switched[inner_r] and states[outer_r] == INCREASE:
                self._dv2 = speeds[3] - speeds[2]
                new_rear = True
            if (self._armed != STRAIGHT and (new_front or new_rear)
                    and self._dv1 is not None and self._dv2 is not None):
                cand = turn_direction(self._dv1, self._dv2, abs(self._dv1 - self._dv2), c.v_l0, c.v_l1, c.v_l2)
                if cand != self._armed:
                    cand = STRAIGHT          # a candidate must agree with the side pattern that armed it
                if cand == STRAIGHT:
                    self._abs_cand = STRAIGHT
                elif cand != self._abs_cand:
                    self._abs_cand, self._abs_cand_t = cand, self.t
            if self._abs_cand != STRAIGHT and self.t - self._abs_cand_t >= c.t1 - self._eps:
                if self.turn != self._abs_cand:
                    self.turn, self.delta = self._abs_cand, 0.0
                self._armed, self._abs_cand = STRAIGHT, STRAIGHT
        # step 3 runs on the released rear axle (_rear_free_update): delta stays 0 ("not identified") until then

