"""The plant's entry point (`bench.plants: chassis = plant.factory:build`): behaviours per vehicle.

Step order within a tick: the returned list IS the order and must be stepped front to back:
VCU, WHL_FL, WHL_FR, WHL_RL, WHL_RR, PLANT, IMU. The VCU and the wheels talk over the bus (their
frames carry the latency a real network has); the body then reads the wheels' true states of this very
tick, and the IMU the body's motion of this very tick, through direct references (no bus latency
between physics and its sensors). Nodes named in `external` are left out: an external wheel's state
reaches the body through WHL_Status_xx, an external PLANT's motion reaches the IMU through PLANT_*.
"""

from __future__ import annotations

from collections.abc import Collection

from bench.node import Behaviour
from plant.body import BodyNode, BusWheel, WheelSource
from plant.ecus.imu import Imu
from plant.ecus.vcu import Vcu
from plant.ecus.wheel import WheelEcu
from plant.kinematics import CORNERS
from plant.vehicles import load_vehicle

DEFAULT_VEHICLE = "EV4WIS"


def build(external: Collection[str] = (), vehicle: str | None = None) -> list[Behaviour]:
    """Behaviours for every node of `vehicle` not in `external` (node names as in the DBC); the
    signature of the entry-point group bench.plants (bench/plugins.py).

    vehicle None means DEFAULT_VEHICLE. Names in `external` that are not nodes of this vehicle
    (DRIVER, TESTER, SBW, ...) are ignored.
    """
    name = (vehicle or DEFAULT_VEHICLE).upper()
    outside = frozenset(external or ())
    if name == "EV4WIS":
        return _ev4wis(outside)
    raise ValueError(f"plant.factory: no plant for vehicle {vehicle!r} (available: EV4WIS)")


def _ev4wis(external: frozenset[str]) -> list[Behaviour]:
    params = load_vehicle("EV4WIS")
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
        body_node = BodyNode(params.geometry, sources, vehicle="EV4WIS", linked=list(behaviours))
        behaviours.append(body_node)
    if "IMU" not in external:
        imu = Imu(body_node.body if body_node is not None else None)
        behaviours.append(imu)
        if body_node is not None:
            body_node.linked = (*body_node.linked, imu)
    return behaviours
