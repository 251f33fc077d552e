"""ABS-FLT-01 judged on the bus, with the fault injected into a wheel-speed sensor (BENCH_AbsSensorFault, the
plant's sensor model: the simulated ABS's wires or an external ABS's IO_AbsSensors alike; docs/contract/plant.md
PLANT-IO-ABS-03).

Each case drives straight at 60 km/h (drive robot, no steering, no braking, noise on), with AbsFault = 0, then:
- SHORT (FR reads 204.75 km/h, beyond the 0-200 km/h measuring range): AbsFault = WHEEL_SPEED_INVALID within
  fault_report_max of the fault's command; braking with 150 bar the ABS stays passive, i.e. on the side of
  physics the valves are unpowered: every wheel's pressure follows the master cylinder (the brakes work without
  ABS) and AbsActive = 0; when the fault ends, AbsFault = 0 again within fault_report_max.
- OPEN_LINE (RL reads 0 km/h while the others read 60): AbsFault = WHEEL_SPEED_INVALID not before the
  contract's 0.5 s (open_line_confirm) and within fault_report_max after it; cleared likewise when it ends. Not
  judged while braking: there an open line cannot be told from a locked wheel, which is why ABS-FLT-01's
  condition reads "without braking".
- STUCK (FL holds its reading): at constant speed the held reading is a valid speed, so ABS-FLT-01 names no
  condition that applies and AbsFault must stay 0 (no false fault); the contract does not require a stuck sensor
  to be detected (abs.md ABS-FLT-01).
The latency counts from the moment the case sets BENCH_AbsSensorFault; fault_report_max covers that message's
cycle, a sensor sample, the ECU's control period and its next ABS_SteerState frame.
"""

from __future__ import annotations

import numpy as np
import pytest

from bench.case import Case
from testcases.abs import steps
from testcases.fault_memory import FaultMemory

SPEED = 60.0              # km/h
SETTLE = 1.0              # s before the fault
PRESSURE = 150.0          # bar
WHEEL = {"FL": 0, "FR": 1, "RL": 2, "RR": 3}
NONE, OPEN_LINE, SHORT, STUCK = 0, 1, 2, 3
WHEEL_SPEED_INVALID = 1


def _drive(bench: Case) -> None:
    steps.start(bench, SPEED)
    steps.hold_speed(bench, SPEED)
    bench.run(SETTLE)
    faults = steps.samples(bench, "ABS_SteerState", ["AbsFault"], since=bench.start + 0.5, required=True)
    bench.expect("before the fault: AbsFault (frames with a fault)", int(np.count_nonzero(faults["AbsFault"])), 0)


def _fault(bench: Case, wheel: str, fault: int) -> float:
    bench.set("BENCH_AbsSensorFault", FaultWheel=WHEEL[wheel], SensorFault=fault)
    return bench.now


def _first(bench: Case, since: float, value: int, *, equal: bool = True) -> float:
    """Seconds from `since` to the first ABS_SteerState frame whose AbsFault is (or, equal=False, is not) `value`;
    NaN when none came."""
    s = steps.samples(bench, "ABS_SteerState", ["AbsFault"], since=since, required=True)
    hit = np.flatnonzero((s["AbsFault"] == value) == equal)
    return float(s["t"][hit[0]]) + bench.start - since if hit.size else float("nan")


def _expect_cleared(bench: Case, kind: str, wheel: str) -> None:
    """The sensor reads true again: AbsFault 0 within fault_report_max (ABS-FLT-01's clearing); the case's plot."""
    t_clear = _fault(bench, wheel, NONE)
    bench.run(0.3)
    bench.expect_between(f"{kind} ended: AbsFault 0 after", _first(bench, t_clear, 0), 0.0,
                         steps.limit("fault_report_max"), unit="s", detail=steps.source("fault_report_max"))
    steps.plot_abs(bench, f"{kind} {wheel}")


@pytest.mark.dut("ABS")
@pytest.mark.req("ABS-FLT-01", "ABS-OUT-02")
def test_abs_sensor_short(bench: Case) -> None:
    report = steps.limit("fault_report_max")
    _drive(bench)
    memory = FaultMemory(bench, "ABS")
    t_fault = _fault(bench, "FR", SHORT)
    bench.run(0.3)
    memory.during("WHEEL_SPEED_INVALID", t_fault)
    bench.expect_between("SHORT FR: AbsFault WHEEL_SPEED_INVALID after", _first(bench, t_fault, WHEEL_SPEED_INVALID),
                         0.0, report, unit="s", detail=steps.source("fault_report_max"))
    t_brake = bench.now
    steps.brake(bench, PRESSURE)
    bench.run(1.0)
    state = steps.samples(bench, "ABS_SteerState", ["AbsFault", "AbsActive", "TurnDirection"], since=t_brake,
                          required=True)
    bench.expect("braking in the fault: frames with AbsFault != WHEEL_SPEED_INVALID",
                 int(np.count_nonzero(state["AbsFault"] != WHEEL_SPEED_INVALID)), 0)
    bench.expect("braking in the fault: frames with AbsActive = 1", int(np.count_nonzero(state["AbsActive"])), 0)
    bench.expect("braking in the fault: frames with TurnDirection != 0",
                 int(np.count_nonzero(state["TurnDirection"])), 0)
    # valves unpowered: each wheel circuit follows the master cylinder (PLANT-IO-ABS-02 RELEASED), judged on the
    # truth from 0.3 s after the brake application (the master reaches 150 bar at 1000 bar/s in 0.15 s)
    tol = steps.limit("passive_pressure_tol")
    _, master = bench.history("PLANT_AbsVehicle", "MasterPressure", since=t_brake + 0.3)
    for w in steps.WHEELS:
        _, p = bench.history(f"PLANT_AbsWheel_{w}", "BrakePressure", since=t_brake + 0.3)
        n = min(p.size, master.size)
        gap = float(np.max(np.abs(p[:n] - master[:n]))) if n else float("nan")
        bench.expect(f"braking in the fault: {w} pressure - master pressure, largest", gap, 0.0, abs_tol=tol,
                     unit="bar", detail=steps.source("passive_pressure_tol"))
    _expect_cleared(bench, "SHORT", "FR")
    memory.after("WHEEL_SPEED_INVALID", t_fault)
    memory.clear_and_reset()


@pytest.mark.dut("ABS")
@pytest.mark.req("ABS-FLT-01")
def test_abs_sensor_open_line(bench: Case) -> None:
    report, confirm = steps.limit("fault_report_max"), steps.limit("open_line_confirm")
    _drive(bench)
    memory = FaultMemory(bench, "ABS")
    t_fault = _fault(bench, "RL", OPEN_LINE)
    bench.run(confirm + 0.3)
    memory.during("WHEEL_SPEED_INVALID", t_fault)
    bench.expect_between("OPEN_LINE RL: AbsFault WHEEL_SPEED_INVALID after", _first(bench, t_fault,
                         WHEEL_SPEED_INVALID), confirm, confirm + report, unit="s",
                         detail=f"{steps.source('open_line_confirm')}; {steps.source('fault_report_max')}")
    _expect_cleared(bench, "OPEN_LINE", "RL")
    memory.after("WHEEL_SPEED_INVALID", t_fault)
    memory.clear_and_reset()


@pytest.mark.dut("ABS")
@pytest.mark.req("ABS-FLT-01")
def test_abs_sensor_stuck_at_constant_speed(bench: Case) -> None:
    _drive(bench)
    memory = FaultMemory(bench, "ABS")
    t_fault = _fault(bench, "FL", STUCK)
    bench.run(2.0)
    faults = steps.samples(bench, "ABS_SteerState", ["AbsFault"], since=t_fault, required=True)
    bench.expect("STUCK FL at constant speed: frames with AbsFault != 0 (a valid reading, no false fault)",
                 int(np.count_nonzero(faults["AbsFault"])), 0)
    sensor = steps.samples(bench, "ABS_WheelSpeeds", ["WheelSpeedFL"], since=t_fault + 0.1, required=True)
    bench.note(f"the stuck FL reading: {len(set(sensor['WheelSpeedFL'].tolist()))} distinct value(s) over "
               f"{sensor['WheelSpeedFL'].size} frames")
    memory.nothing_stored("a valid reading is no fault")
