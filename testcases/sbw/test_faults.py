"""SBW faults at 50 km/h: a timed-out SBW_Pinion, the three angle-sensor faults and a timed-out ECU input, each
detected by the bench and by the SBW, with its documented safe reaction (docs/contract/sbw.md SBW-FLT-01..05;
SBW_Pinion.SbwFault value table of dbc/chassis.dbc; issues 4, 26).

- SBW_Pinion dropped for 100 ms (fault injection): the bench's monitor times it out 3 cycles after the last
  frame and sees it come back; steering is not affected (the SBW's own loops do not use the bus). Only the
  simulated SBW's frames can be dropped: reference only.
- The angle-sensor faults go in through the plant's sensor model (BENCH_SbwSensorFault), which feeds the
  simulated SBW's wires and an external SBW's bench I/O (IO_SbwHandWheel, IO_SbwPinion; docs/contract/plant.md
  PLANT-IO-SBW-05) alike, so they judge a real SBW too, on the bus (SbwFault, SBW_HandWheel, SBW_Pinion) and on
  the plant's ground truth (PLANT_SbwAngles, PLANT_SbwSensors):
  - hand-wheel sensor offset 1000° (beyond ±900°): HANDWHEEL_RANGE (SBW-FLT-01);
  - hand-wheel sensor stuck while the robot turns the hand wheel 15° on: HANDWHEEL_STUCK (SBW-FLT-02);
  - pinion sensor offset 30° (more than 20° from the actuator's rotor angle): PINION_RANGE (SBW-FLT-03).
  Each: SbwFault within 0.05 s of the condition, held while it lasts, the substitute on the bus within
  substitute_error_max of the truth (0.1007°, its coding chain), the pinion target = the hand wheel (no
  feedback; one LSB, counted in whole LSB), steering on (true |θ_h − θ_p| ≤ 0.5°), SbwFault 0 once the sensor
  is healthy. The cases code the SBW's YAW_RATE mode (SteeringMode, docs/contract/sbw.md SBW-DIAG-02) so that
  "feedback off" is a real check; an SBW without the feedback (optional, SBW-CTL-05) refuses that coding
  (NRC 0x31) and the case is skipped with that reason.
- IMU_Motion dropped for 300 ms in YAW_RATE mode: the bench times it out; the ECU flags INPUT_TIMEOUT, the
  pinion target returns to the hand-wheel angle (fixed ratio); the feedback resumes after. Coded YAW_RATE as
  above, so skipped on an SBW without the feedback.
Limits: testcases/sbw/limits.toml [sbw] (the same numbers as docs/contract/sbw.md).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from testcases.fault_memory import FaultMemory
from testcases.sbw.steps import SBW_FAULT, Limits, plot_steering, robot_angle, signal, start

SPEED_KMH = 50.0
HAND_WHEEL = 20.0      # deg held during the faults
CONTRACT_RANGE = 900.0  # deg, SBW_HandWheel.HandWheelAngle range (dbc/chassis.dbc)
STUCK_TURN = 15.0      # deg the robot turns the hand wheel on while its sensor is stuck (> stuck_motion)
PINION_OFFSET = 30.0   # deg added to the pinion sensor (> sensor_plausibility, within the ±600° range)
ANGLE_LSB = 0.1        # deg, resolution of SBW_HandWheel.HandWheelAngle and SBW_Pinion.PinionAngle(Target)


def _first_time(t: np.ndarray, mask: np.ndarray) -> float:
    """Time of the first sample where mask holds, NaN when none."""
    idx = np.flatnonzero(mask)
    return float(t[idx[0]]) if len(idx) else math.nan


def _bench_timeout(bench, lim: Limits, message: str, fault_start: float) -> float:
    """The bench's monitor flags `message` timed out within timeout_detection_max of its last frame; returns
    the time of that last frame (bench time)."""
    t_frames, _ = bench.history(message, "AliveCounter", fault_start - 0.05)
    last = float(t_frames[t_frames <= fault_start + 1e-9][-1])
    timeouts = [t for t, reason in bench.detections(message, since=fault_start) if reason == "timeout"]
    latency = timeouts[0] - last if timeouts else math.nan
    detections = bench.detections(message, since=fault_start)[:3]
    found = ", ".join(f"{reason} at {t - bench.start:.3f} s" for t, reason in detections)
    lim.at_most(f"bench: {message} timed out after its last frame", "timeout_detection_max", latency,
                detail=f"last frame at {last - bench.start:.3f} s; the monitor's detections: {found}")
    return last


@pytest.mark.dut("SBW")
@pytest.mark.req("SBW-FLT-05", "COM-RX-02")
@pytest.mark.reference_only("SBW", reason="drops SBW_Pinion frames, which only the simulated SBW's frames can be, "
                                          "and reads its true angles (PLANT_SbwAngles)")
def test_sbw_pinion_timeout(bench) -> None:
    lim = Limits(bench)
    start(bench, SPEED_KMH)
    robot_angle(bench, HAND_WHEEL)
    bench.run(0.6)
    fault = bench.inject("drop", "SBW_Pinion", duration=0.1)
    bench.note(f"SBW_Pinion dropped from {fault.start - bench.start:.3f} s to {fault.end - bench.start:.3f} s")
    bench.run(0.05)
    bench.expect_true("bench: SBW_Pinion timed out during the drop", bench.timed_out("SBW_Pinion"))
    bench.run(0.35)
    _bench_timeout(bench, lim, "SBW_Pinion", fault.start)
    bench.expect_true("bench: SBW_Pinion back after the drop", not bench.timed_out("SBW_Pinion"),
                      measured=bench.value("SBW_Pinion", "PinionAngle"))
    th, hw = signal(bench, "PLANT_SbwAngles", "HandWheelAngle", fault.start)
    _, pin = signal(bench, "PLANT_SbwAngles", "PinionAngle", fault.start)
    lim.at_most("steering unaffected: max |hand wheel − pinion| (truth) from the drop on", "fault_tracking_error_max",
                float(np.max(np.abs(hw - pin))))
    bench.expect("SbwFault after the drop", bench.value("SBW_Pinion", "SbwFault"), SBW_FAULT["OK"],
                 detail="the ECU's own loops never depended on the bus")
    lim.report()
    plot_steering(bench, "SBW_Pinion dropped")
    bench.plot("SBW_Pinion frames (AliveCounter) around the drop", [("SBW_Pinion", "AliveCounter"),
                                                                    ("SBW_HandWheel", "AliveCounter")], ylabel="-")


def _sensor_fault(bench, lim: Limits, *, fault: str, offset: float, code: str, condition: str,
                  condition_at, hold: float = 0.6, move_to: float | None = None) -> None:
    """Inject one angle-sensor fault at 50 km/h with the hand wheel at HAND_WHEEL (and, with `move_to`, turn it
    there 0.2 s into the fault), clear it after `hold` s, and judge the SBW's detection and reaction.
    `condition_at(t_inject)` gives the bench time the fault's condition holds from (from the ground truth);
    `code` the SbwFault expected; the reaction window starts 0.5 s after the last robot motion or 0.2 s after
    the detection, whichever is later."""
    start(bench, SPEED_KMH, "YAW_RATE", or_direct=True)
    memory = FaultMemory(bench, "SBW")
    robot_angle(bench, HAND_WHEEL)
    bench.run(1.5)
    t_inject = bench.now
    bench.set("BENCH_SbwSensorFault", SensorFault=fault, SensorOffset=offset)
    t_settled = t_inject
    if move_to is not None:
        bench.run(0.2)
        robot_angle(bench, move_to)
        t_settled = bench.now + 0.5
    bench.run(hold)
    memory.during(code, t_inject)
    t_clear = bench.now
    bench.set("BENCH_SbwSensorFault", SensorFault="NONE", SensorOffset=0.0)
    bench.run(0.5)
    bench.note(f"{fault} ({offset:+g}°) from {t_inject - bench.start:.3f} s to {t_clear - bench.start:.3f} s "
               f"(BENCH_SbwSensorFault){'' if move_to is None else f'; robot to {move_to:g}° 0.2 s into it'}")

    t_condition = condition_at(t_inject)
    bench.expect_true(f"bench: {condition}", math.isfinite(t_condition),
                      detail=f"from {t_condition:.3f} s" if math.isfinite(t_condition) else "never")
    tf, values = signal(bench, "SBW_Pinion", "SbwFault", t_inject)
    t_ecu = _first_time(tf, values == SBW_FAULT[code])
    lim.at_most(f"SBW: SbwFault = {code} after the condition", "fault_detection_max", t_ecu - t_condition,
                detail=f"condition {t_condition:.3f} s, SbwFault {t_ecu:.3f} s")
    t_from = max(t_ecu + 0.2, t_settled - bench.start)
    t_to = t_clear - bench.start
    during = (tf > t_from) & (tf <= t_to)
    bench.expect_true(f"SBW: {code} held while the sensor is faulty", bool(np.all(values[during] == SBW_FAULT[code])),
                      measured=", ".join(f"{v:g}" for v in sorted(set(values[during].tolist()))),
                      expected=f"{SBW_FAULT[code]} only")

    # safe reaction: the substitute on the bus is the truth, fixed ratio, steering continues
    th, hw_bus = signal(bench, "SBW_HandWheel", "HandWheelAngle", t_inject)
    tt, hw_true = signal(bench, "PLANT_SbwAngles", "HandWheelAngle", t_inject)
    _, pin_true = signal(bench, "PLANT_SbwAngles", "PinionAngle", t_inject)
    window = (th > t_from) & (th <= t_to)
    if code == "PINION_RANGE":
        tp, pin_bus = signal(bench, "SBW_Pinion", "PinionAngle", t_inject)
        in_fault = (tp > t_from) & (tp <= t_to)
        substitute = float(np.max(np.abs(pin_bus[in_fault] - np.interp(tp[in_fault], tt, pin_true))))
        what = "SBW_Pinion.PinionAngle = the actuator's rotor angle, the true pinion (max error)"
    else:
        substitute = float(np.max(np.abs(hw_bus[window] - np.interp(th[window], tt, hw_true))))
        what = "SBW_HandWheel.HandWheelAngle = column estimate of the true hand wheel (max error)"
    lim.at_most(f"reaction: {what}", "substitute_error_max", substitute,
                detail="the coding chain: output, I/O channel, torsion bar and truth, half an LSB each")
    tp, target = signal(bench, "SBW_Pinion", "PinionAngleTarget", t_inject)
    in_fault = (tp > t_from) & (tp <= t_to)
    # both on the SBW's 0.1° grid: the difference in whole LSB (20.1 − 20.0 is 0.10000000000000142 in floats)
    lsb_diff = np.round(np.abs(target[in_fault] - np.interp(tp[in_fault], th, hw_bus)) / ANGLE_LSB, 6)
    ratio_error = float(np.max(lsb_diff)) * ANGLE_LSB
    bench.expect("reaction: no feedback, pinion target = hand wheel (max difference)", ratio_error, 0.0,
                 abs_tol=ANGLE_LSB, unit="deg", detail="ratio 1 of the mechanical car; one LSB of the angles, "
                                                       "counted in whole LSB")
    window_true = (tt > t_from) & (tt <= t_to)
    lim.at_most("reaction: steering continues, max |hand wheel − pinion| (truth)", "fault_tracking_error_max",
                float(np.max(np.abs(hw_true[window_true] - pin_true[window_true]))))
    bench.expect("SbwFault after the sensor recovered", bench.value("SBW_Pinion", "SbwFault"), SBW_FAULT["OK"])
    bench.expect_clean_bus()
    memory.after(code, t_inject)
    memory.clear_and_reset()
    lim.report()
    plot_steering(bench, fault)
    sensor = "PinionSensor" if code == "PINION_RANGE" else "HandWheelSensor"
    bus = ("SBW_Pinion", "PinionAngle") if code == "PINION_RANGE" else ("SBW_HandWheel", "HandWheelAngle")
    truth = "PinionAngle" if code == "PINION_RANGE" else "HandWheelAngle"
    bench.plot("angle sensor reading vs what the SBW sends",
               [("PLANT_SbwSensors", sensor, f"sensor reading (PLANT_SbwSensors.{sensor})"),
                (*bus, ".".join(bus)), ("PLANT_SbwAngles", truth, "truth")], ylabel="angle [deg]")
    bench.plot(f"SbwFault ({SBW_FAULT[code]} = {code})", [("SBW_Pinion", "SbwFault")], ylabel="value")


@pytest.mark.dut("SBW")
@pytest.mark.req("SBW-FLT-01", "COM-E2E-01", "COM-E2E-02", "COM-VAL-01")
def test_sbw_handwheel_out_of_range(bench) -> None:
    """Hand-wheel sensor offset +1000°: the condition holds from the first PLANT_SbwSensors frame beyond ±900°."""
    lim = Limits(bench)

    def beyond_range(t_inject: float) -> float:
        ts, sensor = signal(bench, "PLANT_SbwSensors", "HandWheelSensor", t_inject)
        return _first_time(ts, np.abs(sensor) > CONTRACT_RANGE)

    _sensor_fault(bench, lim, fault="HANDWHEEL_OFFSET", offset=1000.0, code="HANDWHEEL_RANGE",
                  condition="hand-wheel sensor reading beyond the contract range ±900° (PLANT_SbwSensors)",
                  condition_at=beyond_range)


@pytest.mark.dut("SBW")
@pytest.mark.req("SBW-FLT-02", "COM-VAL-01")
def test_sbw_handwheel_stuck(bench) -> None:
    """Hand-wheel sensor stuck at 20°, then the robot turns the hand wheel to 35°: the condition holds from the
    first PLANT_SbwAngles frame whose true hand wheel (what the column estimate measures) is more than
    stuck_motion from the stuck reading."""
    lim = Limits(bench)
    stuck_motion = lim["stuck_motion"]

    def moved(t_inject: float) -> float:
        ts, sensor = signal(bench, "PLANT_SbwSensors", "HandWheelSensor", t_inject)
        tt, hw_true = signal(bench, "PLANT_SbwAngles", "HandWheelAngle", t_inject)
        stuck = float(sensor[0]) if len(sensor) else math.nan
        return _first_time(tt, np.abs(hw_true - stuck) > stuck_motion)

    _sensor_fault(bench, lim, fault="HANDWHEEL_STUCK", offset=0.0, code="HANDWHEEL_STUCK",
                  condition=f"true hand wheel moved more than {stuck_motion:g}° from the stuck reading",
                  condition_at=moved, hold=1.2, move_to=HAND_WHEEL + STUCK_TURN)


@pytest.mark.dut("SBW")
@pytest.mark.req("SBW-FLT-03", "COM-VAL-01")
def test_sbw_pinion_sensor_implausible(bench) -> None:
    """Pinion sensor offset +30°: the condition holds from the first PLANT_SbwSensors frame more than
    sensor_plausibility from the true pinion (what the actuator's rotor angle measures)."""
    lim = Limits(bench)
    plausibility = lim["sensor_plausibility"]

    def implausible(t_inject: float) -> float:
        ts, sensor = signal(bench, "PLANT_SbwSensors", "PinionSensor", t_inject)
        tt, pin_true = signal(bench, "PLANT_SbwAngles", "PinionAngle", t_inject)
        return _first_time(ts, np.abs(sensor - np.interp(ts, tt, pin_true)) > plausibility)

    _sensor_fault(bench, lim, fault="PINION_OFFSET", offset=PINION_OFFSET, code="PINION_RANGE",
                  condition=f"pinion sensor more than {plausibility:g}° from the true pinion (PLANT_SbwSensors)",
                  condition_at=implausible)


@pytest.mark.dut("SBW")
@pytest.mark.req("SBW-FLT-04", "SBW-CTL-05", "COM-RX-02")
@pytest.mark.reference_only("IMU", reason="drops IMU_Motion frames, which only an IMU simulated by this process sends")
def test_sbw_input_timeout(bench) -> None:
    lim = Limits(bench)
    start(bench, SPEED_KMH, "YAW_RATE")
    memory = FaultMemory(bench, "SBW")
    robot_angle(bench, HAND_WHEEL)
    bench.run(1.5)
    offset_before = bench.value("SBW_Pinion", "PinionAngleTarget") - bench.value("SBW_HandWheel", "HandWheelAngle")
    fault = bench.inject("drop", "IMU_Motion", duration=0.3)
    bench.run(0.2)
    memory.during("INPUT_TIMEOUT", fault.start)
    bench.run(fault.end - bench.now)
    target_end = bench.value("SBW_Pinion", "PinionAngleTarget") - bench.value("SBW_HandWheel", "HandWheelAngle")
    bench.run(1.5)
    bench.note(f"IMU_Motion dropped from {fault.start - bench.start:.3f} s to {fault.end - bench.start:.3f} s "
               f"in YAW_RATE mode; pinion target − hand wheel {offset_before:+.2f}° before the drop")

    last = _bench_timeout(bench, lim, "IMU_Motion", fault.start)
    t_timeout = last + 0.03 - bench.start
    tf, fault_values = signal(bench, "SBW_Pinion", "SbwFault", fault.start)
    t_ecu = _first_time(tf, fault_values == SBW_FAULT["INPUT_TIMEOUT"])
    lim.at_most("reference ECU: SbwFault = INPUT_TIMEOUT after the bench's timeout", "fault_detection_max",
                t_ecu - t_timeout, detail=f"bench {t_timeout:.3f} s, ECU {t_ecu:.3f} s")
    bench.expect_true("feedback active before the drop (pinion target ≠ hand wheel)", abs(offset_before) > 0.5,
                      measured=round(offset_before, 2), expected="> 0.5°")
    bench.expect("reaction: pinion target back to the hand wheel at the end of the drop", target_end, 0.0,
                 abs_tol=0.1, unit="deg", detail="feedback off: the fixed ratio of the mechanical car")
    bench.expect("SbwFault after the drop", bench.value("SBW_Pinion", "SbwFault"), SBW_FAULT["OK"])
    offset_after = bench.value("SBW_Pinion", "PinionAngleTarget") - bench.value("SBW_HandWheel", "HandWheelAngle")
    bench.expect("feedback resumed: pinion target − hand wheel as before the drop", offset_after, offset_before,
                 abs_tol=0.2, unit="deg")
    memory.after("INPUT_TIMEOUT", fault.start)
    memory.clear_and_reset()
    lim.report()
    plot_steering(bench, "IMU_Motion dropped")
    bench.plot("yaw-rate feedback around the drop", [("SBW_Pinion", "PinionAngleTarget", "pinion target"),
                                                     ("SBW_HandWheel", "HandWheelAngle", "hand wheel")],
               ylabel="angle [deg]")
    bench.plot("SbwFault (4 = INPUT_TIMEOUT)", [("SBW_Pinion", "SbwFault")], ylabel="value")
