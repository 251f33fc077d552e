"""Vehicle ACLASS_ABS: the A-class car of docs/spec/vehicles.md B with brake hydraulics, Magic Formula tyres,
wheel-speed sensors and the reference ABS ECU of [P4].

Parameters: plant/vehicles/aclass.toml (the car) and plant/vehicles/abs.toml (what braking adds; its
hand_wheel_ratio 18 is [P4]'s i_w and replaces the car's 15 for this vehicle).

Step order (the returned list IS the order): PLANT, then ABS. The ABS reads the sensors and commands the
valves of the plant by direct reference (its wires), so it sees the wheels of this very tick; its valve
commands act from the next plant tick (the hydraulics' own delay). Nodes named in `external` are left out:
with ABS external the plant sends the sensor readings in IO_AbsSensors and takes the valve commands from
IO_AbsValves (the bench I/O, docs/contract/plant.md PLANT-IO-ABS-01, -02); with PLANT external nothing is built
(the ABS has no sensors to read).
"""

from __future__ import annotations

from collections.abc import Collection

from bench.sim.node import Behaviour
from plant.braking_plant import BrakingPlantNode
from plant.declaration import Vehicle
from plant.ecus.abs import AbsEcu
from plant.vehicles import PARAMETER_FILES

NAME, CODE = "ACLASS_ABS", 2     # BENCH_Control.Vehicle value table
PARAMETERS = (PARAMETER_FILES["ACLASS"], PARAMETER_FILES["ABS"])


#: The bench I/O of an external ABS (docs/contract/plant.md PLANT-IO-ABS-*): its wheel-speed sensors and its valves;
#: on the bus only while the ABS is external (plant/factory.py).
IO = {"ABS": frozenset({"IO_AbsSensors", "IO_AbsValves"})}

#: What this vehicle's network carries from the plant's side (plant/factory.py stops the rest): the ABS ECU
#: and the ground truth of the body and of the braking wheels.
MESSAGES = frozenset({
    "ABS_WheelSpeeds", "ABS_SteerState", "PLANT_Status", "PLANT_Position", "PLANT_Motion", "PLANT_Dynamics",
    "PLANT_AbsVehicle", "PLANT_AbsWheel_FL", "PLANT_AbsWheel_FR", "PLANT_AbsWheel_RL", "PLANT_AbsWheel_RR",
})

#: What its behaviours read of the stimulus: the ABS test's drive robot and valve bypass, the sensor faults, the
#: pedals, the hand wheel.
STIMULUS = ("BENCH_AbsStimulus", "BENCH_AbsSensorFault", "DRV_Pedals", "DRV_Steering")


def build(external: Collection[str]) -> list[Behaviour]:
    """The braking car's behaviours not in `external`, in step order (module docstring)."""
    if "PLANT" in external:
        return []
    car, abs_params = (parameters.load() for parameters in PARAMETERS)
    plant = BrakingPlantNode(car, abs_params, vehicle_code=CODE, external_abs="ABS" in external)
    behaviours: list[Behaviour] = [plant]
    if "ABS" not in external:
        ecu = AbsEcu(abs_params, car, plant)
        behaviours.append(ecu)
        plant.linked = (ecu,)
    return behaviours


VEHICLE = Vehicle(name=NAME, code=CODE, build=build, parameters=PARAMETERS, messages=MESSAGES, stimulus=STIMULUS,
                  io=IO)
