"""The stimulus messages each vehicle's network reads (besides BENCH_Control, which every scenario sends).

A scenario sends only these (`bench.start_scenario(stimulus=...)`): a 4WIS EV's bus carries no steering-robot
or ABS stimulus, as the plant sends only the vehicle's own ECUs (plant/assemblies MESSAGES). Taken from what
the plant's models and reference ECUs read (io.latest in plant/): the 4WIS VCU reads DRV_MotionRequest,
DRV_Steering and BENCH_VcuConfig; the A-class SBW car the steering robot, the SBW configuration and its
sensor faults; the braking A-class the ABS stimulus, the pedals and the hand wheel.
"""

STIMULUS: dict[str, tuple[str, ...]] = {
    "EV4WIS": ("DRV_MotionRequest", "DRV_Steering", "BENCH_VcuConfig"),
    "ACLASS": ("BENCH_SteeringRobot", "BENCH_SbwConfig", "BENCH_SbwSensorFault"),
    "ACLASS_ABS": ("BENCH_AbsStimulus", "DRV_Pedals", "DRV_Steering"),
}
