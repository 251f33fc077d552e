"""The soak case: the plant and the restbus run for BENCH_SOAK_SECONDS of real time with every message at
its cycle time; the bench keeps checking every frame (benchmarks/soak.py drives it)."""

import os


def test_soak(bench):
    seconds = float(os.environ.get("BENCH_SOAK_SECONDS", "20"))
    bench.start_scenario(Vehicle="EV4WIS")
    bench.set("DRV_MotionRequest", DriveMode="PIVOT", PivotX=8.0, PivotY=0.0, TargetSpeed=1.0)
    bench.run(seconds)
    # What a soak must not do is lose or corrupt frames (benchmarks/soak.py counts AliveCounter gaps in the
    # log) or grow; the cycle times under the host's scheduling are in the report's timing section.
    bench.expect("invalid frames", len(bench.invalid_log()), 0)
