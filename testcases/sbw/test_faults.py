"""SBW faults at 50 km/h: a timed-out SBW_Pinion, an out-of-range hand-wheel angle and a timed-out ECU input,
each detected by the bench and (where the reference ECU is a receiver) by the reference SBW ECU, with its
documented safe reaction (plant/ecus/sbw.py; SBW_Pinion.SbwFault value table of dbc/chassis.dbc; issue 4).

- SBW_Pinion dropped for 100 ms (fault injection): the bench's monitor times it out 3 cycles after the last
  frame and sees it come back; steering is not affected (the SBW's own loops do not use the bus). SBW_Pinion
  has no receiver among ACLASS's simulated ECUs (its contract receiver, the VCU, is not part of this car), so
  the reference ECU's side of a timed-out input is shown with IMU_Motion below.
- Hand-wheel angle sensor reading beyond the contract range ±900° (BENCH_SbwSensorFault: offset 1000°): the
  bench sees the reading beyond the range (PLANT_SbwSensors); the ECU flags HANDWHEEL_RANGE, replaces the
  sensor by the column estimate (so SBW_HandWheel stays in range and true), drops the yaw-rate feedback and
  keeps steering at ratio 1; the fault clears with the sensor.
- IMU_Motion dropped for 300 ms in YAW_RATE mode: the bench times it out; the ECU flags INPUT_TIMEOUT, the
  pinion target returns to the hand-wheel angle (fixed ratio); the feedback resumes after.
Limits: testcases/sbw/limits.toml [sbw].
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from testcases.sbw.steps import SBW_FAULT, Limits, expect_clean_bus, plot_steering, robot_angle, signal, start

SPEED_KMH = 50.0
HAND_WHEEL = 20.0      # deg held during the faults
CONTRACT_RANGE = 900.0  # deg, SBW_HandWheel.HandWheelAngle range (dbc/chassis.dbc)


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


@pytest.mark.dut("SBW")
@pytest.mark.req("SBW-FLT-01", "COM-E2E-01", "COM-E2E-02", "COM-VAL-01")
@pytest.mark.reference_only("SBW", reason="injects the sensor fault into the simulated SBW's sensors "
                                          "(BENCH_SbwSensorFault) and reads its true angles (PLANT_SbwAngles)")
def test_sbw_handwheel_out_of_range(bench) -> None:
    lim = Limits(bench)
    start(bench, SPEED_KMH, "YAW_RATE")
    robot_angle(bench, HAND_WHEEL)
    bench.run(1.5)
    t_inject = bench.now
    bench.set("BENCH_SbwSensorFault", SensorFault="HANDWHEEL_OFFSET", SensorOffset=1000.0)
    bench.run(0.6)
    t_clear = bench.now
    bench.set("BENCH_SbwSensorFault", SensorFault="NONE", SensorOffset=0.0)
    bench.run(0.5)
    bench.note(f"hand-wheel angle sensor offset +1000° from {t_inject - bench.start:.3f} s to "
               f"{t_clear - bench.start:.3f} s (BENCH_SbwSensorFault)")

    ts, sensor = signal(bench, "PLANT_SbwSensors", "HandWheelSensor", t_inject)
    t_bench = _first_time(ts, np.abs(sensor) > CONTRACT_RANGE)
    bench.expect_true("bench: hand-wheel sensor reading beyond the contract range ±900° (PLANT_SbwSensors)",
                      math.isfinite(t_bench), measured=f"{np.max(np.abs(sensor)):.1f}°",
                      expected="> 900°", detail=f"first frame at {t_bench:.3f} s")
    tf, fault = signal(bench, "SBW_Pinion", "SbwFault", t_inject)
    t_ecu = _first_time(tf, fault == SBW_FAULT["HANDWHEEL_RANGE"])
    lim.at_most("reference ECU: SbwFault = HANDWHEEL_RANGE after the bench saw the reading", "fault_detection_max",
                t_ecu - t_bench, detail=f"bench {t_bench:.3f} s, ECU {t_ecu:.3f} s")
    during = (tf > t_ecu + 0.2) & (tf <= t_clear - bench.start)
    bench.expect_true("reference ECU: HANDWHEEL_RANGE held while the sensor is out of range",
                      bool(np.all(fault[during] == SBW_FAULT["HANDWHEEL_RANGE"])),
                      measured=", ".join(f"{v:g}" for v in sorted(set(fault[during].tolist()))),
                      expected=f"{SBW_FAULT['HANDWHEEL_RANGE']} only")

    # safe reaction: plausible hand-wheel angle on the bus, fixed ratio, steering continues
    th, hw_bus = signal(bench, "SBW_HandWheel", "HandWheelAngle", t_inject)
    tt, hw_true = signal(bench, "PLANT_SbwAngles", "HandWheelAngle", t_inject)
    _, pin_true = signal(bench, "PLANT_SbwAngles", "PinionAngle", t_inject)
    window = (th > t_ecu + 0.2) & (th <= t_clear - bench.start)
    substitute_error = float(np.max(np.abs(hw_bus[window] - np.interp(th[window], tt, hw_true))))
    bench.expect("reaction: SBW_HandWheel.HandWheelAngle = column estimate of the true hand wheel (max error)",
                 substitute_error, 0.0, abs_tol=0.1, unit="deg", detail="one LSB of HandWheelAngle (0.1°)")
    tp, target = signal(bench, "SBW_Pinion", "PinionAngleTarget", t_inject)
    in_fault = (tp > t_ecu + 0.2) & (tp <= t_clear - bench.start)
    ratio_error = float(np.max(np.abs(target[in_fault] - np.interp(tp[in_fault], th, hw_bus))))
    bench.expect("reaction: yaw-rate feedback off, pinion target = hand wheel (max difference)", ratio_error, 0.0,
                 abs_tol=0.1, unit="deg", detail="ratio 1 of the mechanical car; one LSB of the angles")
    window_true = (tt > t_ecu + 0.2) & (tt <= t_clear - bench.start)
    lim.at_most("reaction: steering continues, max |hand wheel − pinion| (truth)", "fault_tracking_error_max",
                float(np.max(np.abs(hw_true[window_true] - pin_true[window_true]))))
    bench.expect("SbwFault after the sensor recovered", bench.value("SBW_Pinion", "SbwFault"), SBW_FAULT["OK"])
    expect_clean_bus(bench)
    lim.report()
    plot_steering(bench, "hand-wheel sensor out of range")
    bench.plot("hand-wheel angle sensor reading vs what the ECU sends",
               [("PLANT_SbwSensors", "HandWheelSensor", "sensor reading (PLANT_SbwSensors)"),
                ("SBW_HandWheel", "HandWheelAngle", "SBW_HandWheel.HandWheelAngle"),
                ("PLANT_SbwAngles", "HandWheelAngle", "hand wheel, truth")], ylabel="angle [deg]")
    bench.plot("SbwFault (1 = HANDWHEEL_RANGE)", [("SBW_Pinion", "SbwFault")], ylabel="value")


@pytest.mark.dut("SBW")
@pytest.mark.req("SBW-FLT-04", "SBW-CTL-05", "COM-RX-02")
@pytest.mark.reference_only("SBW", reason="selects the reference SBW's yaw-rate feedback through "
                                          "BENCH_SbwConfig, which a real SBW ignores")
def test_sbw_input_timeout(bench) -> None:
    lim = Limits(bench)
    start(bench, SPEED_KMH, "YAW_RATE")
    robot_angle(bench, HAND_WHEEL)
    bench.run(1.5)
    offset_before = bench.value("SBW_Pinion", "PinionAngleTarget") - bench.value("SBW_HandWheel", "HandWheelAngle")
    fault = bench.inject("drop", "IMU_Motion", duration=0.3)
    bench.run(0.3)
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
    lim.report()
    plot_steering(bench, "IMU_Motion dropped")
    bench.plot("yaw-rate feedback around the drop", [("SBW_Pinion", "PinionAngleTarget", "pinion target"),
                                                     ("SBW_HandWheel", "HandWheelAngle", "hand wheel")],
               ylabel="angle [deg]")
    bench.plot("SbwFault (4 = INPUT_TIMEOUT)", [("SBW_Pinion", "SbwFault")], ylabel="value")
