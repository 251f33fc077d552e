"""The SBW's bench I/O on the ACLASS plant with an external SBW (plant/sbw.py ActuatorEmulation,
plant/assemblies/aclass.py), on a fake NodeIO at dt = 1 ms, no bus: the emulated steering actuator against the
servo that docs/contract/plant.md PLANT-IO-SBW-03 documents, the road-feel motor's current loop (-04), the
timeout (-06), the sensor frames' sampling (-02) and the sensor faults on them (-05).

Expected values come from the documents: the servo's equation integrated here on its own (fine Euler steps, the
reference built from the frames by the documented rule), the current loop's first-order lag, the stated
sampling instants. The test plays the external SBW by writing IO_SbwActuators into the fake bus every 5 ms."""

from __future__ import annotations

import math
from collections.abc import Callable

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plant.driver import ANGLE
from plant.sbw import SensorFault
from plant.vehicles import load_parameters
from tests.plant.sbw_rig import DT, Rig

RAD = math.pi / 180.0
P = load_parameters("SBW")
# docs/contract/plant.md PLANT-IO-SBW-03 / -04 / -06, restated
WN, ZETA, TAU, CYCLE, TIMEOUT = 80.0, 1.0, 0.5e-3, 0.005, 0.015
KT_COLUMN = 0.8            # K_m r_m = 0.05 N·m/A × 16, N·m at the column per A (sbw.md)
# "within 0.05° plus 2 % of the motion" (PLANT-IO-SBW-03)
ABS_TOL, REL_TOL = 0.05, 0.02


class Sbw:
    """The external SBW as the test plays it: one IO_SbwActuators frame every 5 ms (AliveCounter +1 each)."""

    def __init__(self, rig: Rig) -> None:
        self.rig, self.counter = rig, 0
        self.applied: list[tuple[float, float]] = []     # (t_k, θ_k deg): the plant applies it in its next tick

    def send(self, angle: float, torque: float = 0.0) -> None:
        self.counter = (self.counter + 1) % 15
        self.rig.io.values["IO_SbwActuators"] = {"PinionAngleRequest": round(angle, 1),
                                                  "RoadFeelTorqueRequest": round(torque, 3),
                                                  "AliveCounter": self.counter}
        self.applied.append((self.rig.tick * DT, round(angle, 1)))


def drive(rig: Rig, sbw: Sbw | None, request: Callable[[float], float], seconds: float,
          torque: float = 0.0) -> list[float]:
    """Run `seconds`, the SBW sending `request(t)` at every multiple of 5 ms; the true pinion (deg) per tick."""
    out = []
    for _ in range(round(seconds / DT)):
        if sbw is not None and rig.tick % 5 == 0:
            sbw.send(request(rig.tick * DT), torque)
        rig.run(DT)
        out.append(rig.mech.theta_p / RAD)
    return out


def documented_servo(applied: list[tuple[float, float]], t0: float, t1: float, theta0: float = 0.0,
                     h: float = 1e-5) -> Callable[[float], float]:
    """θ_p(t) by PLANT-IO-SBW-03's equation θ̈ = ω_n²(r − θ) + 2ζω_n(ṙ − θ̇), from rest at θ0 at t0, with the
    reference of its frames: w_k = (θ_k − θ_{k−1}) / 5 ms (0 for the first), r = θ_k + w_k min(t − t_k, 5 ms)."""
    frames = [(t, a, (a - applied[i - 1][1]) / CYCLE if i else 0.0) for i, (t, a) in enumerate(applied)]
    times, values = [], []
    theta, omega, k, t = theta0, 0.0, -1, t0
    while t < t1:
        while k + 1 < len(frames) and frames[k + 1][0] <= t + 1e-12:
            k += 1
        if k < 0:
            r, rate = 0.0, 0.0
        else:
            tk, ak, wk = frames[k]
            r, rate = (ak + wk * (t - tk), wk) if t - tk < CYCLE else (ak + wk * CYCLE, 0.0)
        accel = WN * WN * (r - theta) + 2 * ZETA * WN * (rate - omega)
        omega += h * accel
        theta += h * omega
        t += h
        times.append(t)
        values.append(theta)

    def at(when: float) -> float:
        i = min(len(times) - 1, max(0, round((when - t0) / h) - 1))
        return values[i]
    return at


def test_a_small_step_request_follows_the_documented_servo() -> None:
    """A 1° step of the request from rest (a reference that runs 1° on during its cycle, PLANT-IO-SBW-03):
    the true pinion against the equation at every tick, and the figures the document gives (90 % after 10 ms,
    25 % overshoot)."""
    rig = Rig(50.0, external=("SBW",))
    sbw = Sbw(rig)
    pinion = drive(rig, sbw, lambda t: 0.0 if t < 0.2 else 1.0, 0.4)
    model = documented_servo(sbw.applied, 0.0, 0.4)
    for i in range(200, 400):
        assert pinion[i] == pytest.approx(model((i + 1) * DT), abs=ABS_TOL + REL_TOL * 1.0), i
    t90 = next(i for i in range(200, 400) if pinion[i] >= 0.9) + 1 - 200
    assert t90 * DT == pytest.approx(0.010, abs=0.0015)
    assert max(pinion) == pytest.approx(1.25, abs=0.01)
    assert pinion[-1] == pytest.approx(1.0, abs=0.005)


def test_a_sine_request_at_50_kmh_follows_the_documented_servo_under_the_tyre_load() -> None:
    """30° at 1 Hz at 50 km/h (the load: aligning torque, friction, compensated by the rig): the pinion against
    the equation, and no phase lag of its own beyond the 0.05° the document gives."""
    rig = Rig(50.0, external=("SBW",))
    sbw = Sbw(rig)
    pinion = drive(rig, sbw, lambda t: 30.0 * math.sin(2 * math.pi * t), 2.0)
    model = documented_servo(sbw.applied, 0.0, 2.0)
    worst = max(abs(pinion[i] - model((i + 1) * DT)) for i in range(1000, 2000))
    assert worst <= ABS_TOL + REL_TOL * 30.0
    assert rig.v("PLANT_SbwTorques", "AligningTorque") != 0.0


def test_a_ramp_request_is_followed_without_steady_error_and_a_held_request_exactly() -> None:
    rig = Rig(50.0, external=("SBW",))
    sbw = Sbw(rig)
    pinion = drive(rig, sbw, lambda t: min(100.0 * t, 60.0), 1.2)                 # 100 °/s up to 60°
    # on the ramp (after the start transient, 0.1-0.5 s): the pinion within the request's 0.05° rounding
    for i in range(100, 500, 7):
        assert pinion[i] == pytest.approx(100.0 * (i + 1) * DT, abs=ABS_TOL + 0.05), i
    assert pinion[-1] == pytest.approx(60.0, abs=0.01)
    # the steady current holds the aligning torque, give or take the dry friction: i_M = (−T_a ± T_f) / (K_M r_M)
    assert rig.v("PLANT_SbwTorques", "AligningTorque") < -1.0
    # (+ 0.01 A: the 0.5 ms current loop behind the aligning torque, which still settles with the car's yaw)
    assert abs(rig.mech.i_M - (-rig.mech.aligning_torque / 0.8)) <= 0.4 / 0.8 + 0.01


def test_bunched_and_late_frames_take_their_rate_from_the_counter_not_the_receive_times() -> None:
    """One frame per 5 ms sample (AliveCounter +1 each, PLANT-IO-SBW-03), but sent irregularly: every other
    frame 4 ms late, so pairs arrive 1 ms apart with 9 ms between them (bunched), and every 8th 12 ms late
    (the reference holds after 5 ms of extrapolation, within the 15 ms timeout; the frames behind it follow
    1 ms apart). The rig's rate is
    Δθ / (n · 5 ms) by the counter, whatever the spacing: the pinion follows the documented servo fed with
    that rule's reference, and the rule by receive times (Δθ / spacing: 5 times the rate for a bunched frame)
    would be far off."""
    rig = Rig(50.0, external=("SBW",))
    sbw = Sbw(rig)
    # send tick of sample k (in order, at most one per 1 ms tick): its own 5k ms plus a delay, after the last one
    send, last = {}, -1
    for k in range(200):
        last = send[k] = max(5 * k + (12 if k % 8 == 0 else 4 if k % 2 == 0 else 0), last + 1)
    due_at = {tick: k for k, tick in send.items()}
    pinion = []
    for _ in range(1000):
        k = due_at.get(rig.tick)
        if k is not None:
            sbw.send(30.0 * math.sin(2 * math.pi * 5 * k * DT))
        rig.run(DT)
        pinion.append(rig.mech.theta_p / RAD)
    spacings = {round(b[0] - a[0], 3) for a, b in zip(sbw.applied, sbw.applied[1:], strict=False)}
    assert {0.001, 0.009} <= spacings and max(spacings) >= 0.012                # bunched and late, as meant
    model = documented_servo(sbw.applied, 0.0, 1.0)
    worst = max(abs(pinion[i] - model((i + 1) * DT)) for i in range(500, 1000))
    assert worst <= ABS_TOL + REL_TOL * 30.0
    # the same frames with the rate by receive times: a different pinion, beyond the servo's tolerance
    by_time = [(t, a) for t, a in sbw.applied]
    frames = [(t, a, (a - by_time[i - 1][1]) / (t - by_time[i - 1][0]) if i else 0.0)
              for i, (t, a) in enumerate(by_time)]
    k, theta, omega, t, h, off = -1, model(0.5), 0.0, 0.5, 1e-5, 0.0
    while t < 1.0:
        while k + 1 < len(frames) and frames[k + 1][0] <= t + 1e-12:
            k += 1
        tk, ak, wk = frames[k]
        r, rate = (ak + wk * (t - tk), wk) if t - tk < CYCLE else (ak + wk * CYCLE, 0.0)
        omega += h * (WN * WN * (r - theta) + 2 * ZETA * WN * (rate - omega))
        theta += h * omega
        t += h
        off = max(off, abs(theta - model(t)))
    assert off > 2 * (ABS_TOL + REL_TOL * 30.0)


def test_without_frames_the_actuator_holds_the_centre_and_the_road_feel_torque_is_zero() -> None:
    rig = Rig(50.0, external=("SBW",))
    rig.robot(ANGLE, 40.0)
    drive(rig, None, lambda t: 0.0, 1.0)
    assert abs(rig.mech.theta_p) / RAD < 0.01
    assert rig.mech.i_m == pytest.approx(0.0, abs=1e-9)
    assert rig.mech.theta_h / RAD == pytest.approx(40.0, abs=0.01)


def test_a_timeout_holds_the_last_request_and_drops_the_road_feel_torque() -> None:
    """Frames of a ramp, then none: 15 ms after the last frame the reference is that frame's request (not its
    extrapolation), and the road-feel torque is 0."""
    rig = Rig(50.0, external=("SBW",))
    rig.robot(ANGLE, 0.0)
    sbw = Sbw(rig)
    drive(rig, sbw, lambda t: 100.0 * t, 0.3, torque=2.0)
    last = sbw.applied[-1][1]
    assert rig.mech.i_m == pytest.approx(2.0 / KT_COLUMN, rel=0.01)
    rig.io.silenced.add("IO_SbwActuators")
    drive(rig, None, lambda t: 0.0, 0.5)
    assert rig.mech.theta_p / RAD == pytest.approx(last, abs=0.01)
    assert rig.mech.i_m == pytest.approx(0.0, abs=1e-6)


def test_the_road_feel_current_follows_its_request_with_the_documented_lag() -> None:
    """RoadFeelTorqueRequest 4 N·m with the hand wheel held: i_m → 4 / 0.8 = 5 A as 1 − e^{−t/0.5 ms}."""
    rig = Rig(0.0, external=("SBW",))
    sbw = Sbw(rig)
    drive(rig, sbw, lambda t: 0.0, 0.1)
    start = rig.tick
    sbw.send(0.0, 4.0)
    currents = []
    for _ in range(4):
        rig.run(DT)
        currents.append(rig.mech.i_m)
    for n, current in enumerate(currents, 1):
        assert current == pytest.approx(5.0 * (1.0 - math.exp(-n * DT / TAU)), rel=1e-6), (start, n)
    assert rig.v("PLANT_SbwTorques", "RoadFeelTorque") == pytest.approx(KT_COLUMN * currents[-1])


def test_sensor_frames_are_sampled_at_multiples_of_5_ms() -> None:
    """IO_SbwHandWheel, IO_SbwPinion, IO_SbwCurrents change only at ticks that are multiples of 5 ms, and then
    carry that tick's state (the hand wheel moving under the robot)."""
    rig = Rig(50.0, external=("SBW",))
    rig.robot(ANGLE, 90.0)
    sbw = Sbw(rig)
    for _ in range(100):
        if rig.tick % 5 == 0:
            sbw.send(rig.mech.theta_h / RAD)
        before = dict(rig.io.sent.get("IO_SbwHandWheel", {}))
        rig.run(DT)
        after = rig.io.sent["IO_SbwHandWheel"] if rig.tick % 5 == 0 else rig.io.sent.get("IO_SbwHandWheel", {})
        if rig.tick % 5:
            assert after == before, rig.tick
        else:
            assert after["HandWheelSensor"] == pytest.approx(rig.mech.theta_h / RAD, abs=1e-9)
            assert after["ColumnAngle"] == pytest.approx(rig.mech.theta_c / RAD, abs=1e-9)
            assert after["TorsionBarTorque"] == pytest.approx(rig.mech.torsion_torque, abs=1e-9)
            assert rig.io.sent["IO_SbwPinion"]["ActuatorAngle"] == pytest.approx(rig.mech.theta_p / RAD, abs=1e-9)
            assert rig.io.sent["IO_SbwCurrents"]["SteerMotorCurrent"] == pytest.approx(rig.mech.i_M, abs=1e-9)


def test_the_reference_sbw_keeps_its_wires_no_io() -> None:
    rig = Rig(50.0)
    rig.run(0.1)
    assert not {"IO_SbwHandWheel", "IO_SbwPinion", "IO_SbwCurrents"} & set(rig.io.sent)
    assert "PLANT_SbwAngles" in rig.io.sent


@pytest.mark.parametrize("fault, offset", [(SensorFault.HANDWHEEL_OFFSET, 1000.0),
                                           (SensorFault.HANDWHEEL_STUCK, 0.0),
                                           (SensorFault.PINION_OFFSET, 30.0)])
def test_sensor_faults_appear_on_the_io(fault: int, offset: float) -> None:
    """PLANT-IO-SBW-05: the faulty sensor reads as the fault says; the independent channels stay true."""
    rig = Rig(50.0, external=("SBW",))
    sbw = Sbw(rig)
    rig.robot(ANGLE, 20.0)
    drive(rig, sbw, lambda t: rig.mech.theta_h / RAD, 0.5)
    at_start = rig.mech.theta_h / RAD
    rig.fault(fault, offset)
    rig.robot(ANGLE, 35.0)
    drive(rig, sbw, lambda t: rig.mech.theta_h / RAD, 0.5)
    hand, pinion = rig.io.sent["IO_SbwHandWheel"], rig.io.sent["IO_SbwPinion"]
    theta_h, theta_p = rig.mech.theta_h / RAD, rig.mech.theta_p / RAD
    expected_hand = {SensorFault.HANDWHEEL_OFFSET: theta_h + offset,
                     SensorFault.HANDWHEEL_STUCK: at_start}.get(fault, theta_h)
    expected_pinion = theta_p + offset if fault == SensorFault.PINION_OFFSET else theta_p
    assert theta_h == pytest.approx(35.0, abs=0.05)
    assert hand["HandWheelSensor"] == pytest.approx(expected_hand, abs=1e-6)
    assert pinion["PinionSensor"] == pytest.approx(expected_pinion, abs=1e-6)
    assert hand["ColumnAngle"] == pytest.approx(rig.mech.theta_c / RAD, abs=1e-9)
    assert pinion["ActuatorAngle"] == pytest.approx(theta_p, abs=1e-9)
    assert rig.v("PLANT_SbwSensors", "HandWheelSensor") == pytest.approx(expected_hand, abs=1e-6)
    rig.fault(SensorFault.NONE)
    drive(rig, sbw, lambda t: rig.mech.theta_h / RAD, 0.1)
    assert rig.io.sent["IO_SbwHandWheel"]["HandWheelSensor"] == pytest.approx(rig.mech.theta_h / RAD, abs=1e-6)


@settings(max_examples=20, deadline=None)
@given(request=st.floats(-900.0, 900.0), torque=st.floats(-20.0, 20.0), fault=st.sampled_from([0, 1, 2, 3, 9]),
       offset=st.floats(-2000.0, 2000.0), robot=st.floats(-1000.0, 1000.0), kmh=st.sampled_from([0.0, 50.0, 200.0]),
       silent_after=st.sampled_from([None, 0.05]))
def test_anything_from_the_external_sbw_never_puts_nan_or_out_of_range_on_the_io(
        request: float, torque: float, fault: int, offset: float, robot: float, kmh: float,
        silent_after: float | None) -> None:
    """Any request within the DBC ranges, any robot angle and sensor fault: every I/O and ground-truth value the
    plant sends is finite and within its signal's range (MemoryIO with the DBC bounds raises otherwise)."""
    rig = Rig(kmh, external=("SBW",))
    rig.robot(ANGLE, robot)
    rig.fault(fault, offset)
    sbw = Sbw(rig)
    drive(rig, sbw, lambda t: request, 0.1, torque=torque)
    if silent_after is not None:
        rig.io.silenced.add("IO_SbwActuators")
    drive(rig, None, lambda t: 0.0, 0.1)
    for message in ("IO_SbwHandWheel", "IO_SbwPinion", "IO_SbwCurrents", "PLANT_SbwAngles", "PLANT_SbwSensors"):
        assert all(math.isfinite(v) for v in rig.io.sent[message].values())
