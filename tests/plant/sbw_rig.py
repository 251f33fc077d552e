"""The ACLASS plant with its SBW on a fake NodeIO (bench.sim.testing.MemoryIO) at dt = 1 ms, no bus: the rig of the
plant's SBW tests (test_sbw_model, test_sbw_io)."""

from __future__ import annotations

from bench.sim.testing import CodedSide, MemoryIO
from plant import signal_ranges as ranges
from plant.assemblies import aclass
from plant.driver import ANGLE
from plant.ecus.sbw import SbwEcu
from plant.factory import assemble
from plant.sbw import SbwMechanics

DT = 1e-3
BOUNDS = ranges.BY_SIGNAL


class Rig:
    """The ACLASS behaviours in factory order on a MemoryIO, at `kmh`, the robot holding the hand wheel."""

    def __init__(self, kmh: float = 50.0, mode: int = 0, external: tuple[str, ...] = (), scenario: int = 1) -> None:
        self.io = MemoryIO(BOUNDS)
        self.behaviours = assemble("ACLASS", external)
        self.tick = 0
        by_node = {b.nodes[0]: b for b in self.behaviours}
        self.plant: aclass.AclassPlant | None = by_node.get("PLANT")  # type: ignore[assignment]
        self.ecu: SbwEcu | None = by_node.get("SBW")  # type: ignore[assignment]
        self.io.values["BENCH_Control"] = {"ScenarioId": scenario, "InitialSpeed": round(kmh / 3.6, 2), "Vehicle": 1,
                                           "RoadMu": 1.0, "SensorNoise": 0.0}
        self.coding = CodedSide({"SteeringMode": mode, "IdealYawGain": 0.28})   # the SBW's (SBW-DIAG-02)
        self.io.diagnostic_sides["SBW"] = self.coding
        self.robot(ANGLE, 0.0)

    def robot(self, mode: int, angle: float = 0.0, torque: float = 0.0) -> None:
        self.io.values["BENCH_SteeringRobot"] = {"RobotMode": mode, "RobotAngle": angle, "RobotTorque": torque}

    def fault(self, fault: int, offset: float = 0.0) -> None:
        self.io.values["BENCH_SbwSensorFault"] = {"SensorFault": fault, "SensorOffset": offset}

    def run(self, seconds: float) -> None:
        for _ in range(round(seconds / DT)):
            self.tick += 1
            self.io.t = self.tick * DT
            for b in self.behaviours:
                b.step(self.io, self.io.t, DT)

    def v(self, message: str, signal: str) -> float:
        return self.io.values[message][signal]

    @property
    def mech(self) -> SbwMechanics:
        assert self.plant is not None and self.plant.mechanics is not None
        return self.plant.mechanics
