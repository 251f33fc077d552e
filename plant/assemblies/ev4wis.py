"""The 4WIS steer-by-wire EV (docs/spec/vehicles.md A) as bus nodes.

Step order within a tick: the returned list IS the order and must be stepped front to back:
VCU, WHL_FL, WHL_FR, WHL_RL, WHL_RR, PLANT, IMU. The VCU and the wheels talk over the bus (their
frames carry the latency a real network has); the body then reads the wheels' true states of this very
tick, and the IMU the body's motion of this very tick, through direct references (no bus latency
between physics and its sensors). The body is kinematic at low speed and the single-track model with
saturating tyres at speed (plant/dynamic_body.py: EvBodyNode, VehicleBody). Nodes named in `external` are
left out: an external wheel's state reaches the body through WHL_Status_xx, an external PLANT's motion
reaches the IMU through PLANT_*.
"""

from __future__ import annotations

from collections.abc import Collection

from bench.sim.node import Behaviour
from plant.body import BusWheel, WheelSource
from plant.declaration import Vehicle
from plant.dynamic_body import EvBodyNode
from plant.ecus.imu import Imu
from plant.ecus.vcu import Vcu
from plant.ecus.wheel import WheelEcu
from plant.kinematics import CORNERS
from plant.vehicles import PARAMETER_FILES

NAME, CODE = "EV4WIS", 0     # BENCH_Control.Vehicle value table
PARAMETERS = PARAMETER_FILES["EV4WIS"]


#: What this vehicle's network carries from the plant's side (plant/factory.py stops the rest): the VCU's
#: commands and state, the four wheel ECUs' status, the IMU and the ground truth of the body.
MESSAGES = frozenset({
    "VCU_WheelCmd_FL", "VCU_WheelCmd_FR", "VCU_WheelCmd_RL", "VCU_WheelCmd_RR", "VCU_VehicleState",
    "VCU_RotationCentre", "WHL_Status_FL", "WHL_Status_FR", "WHL_Status_RL", "WHL_Status_RR", "IMU_Motion",
    "PLANT_Status", "PLANT_Position", "PLANT_Motion", "PLANT_Dynamics",
})

#: What its behaviours read of the stimulus: the VCU's driver requests (its rear-steering law is diagnostic coding,
#: docs/contract/vcu.md VCU-DIAG-02).
STIMULUS = ("DRV_MotionRequest", "DRV_Steering")


def build(external: Collection[str]) -> list[Behaviour]:
    """The EV's behaviours not in `external`, in step order (module docstring)."""
    params = PARAMETERS.load()
    behaviours: list[Behaviour] = []
    if "VCU" not in external:
        behaviours.append(Vcu(params))
    sources: dict[str, WheelSource] = {}
    for corner in CORNERS:
        if f"WHL_{corner}" in external:
            sources[corner] = BusWheel(corner)
        else:
            wheel = WheelEcu(corner, params)
            behaviours.append(wheel)
            sources[corner] = wheel
    body_node = None
    if "PLANT" not in external:
        body_node = EvBodyNode(params, sources, vehicle_code=CODE, linked=list(behaviours))
        behaviours.append(body_node)
    if "IMU" not in external:
        imu = Imu(body_node.body if body_node is not None else None)
        behaviours.append(imu)
        if body_node is not None:
            body_node.linked = (*body_node.linked, imu)
    return behaviours


VEHICLE = Vehicle(name=NAME, code=CODE, build=build, parameters=(PARAMETERS,), messages=MESSAGES, stimulus=STIMULUS)
