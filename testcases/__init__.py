"""HIL test cases of the chassis bench (run with `bench run`), one package per campaign:

- `ev4wis/` (4WIS): the 4WIS EV's VCU and wheel modules at low speed and their faults,
- `rear_steer_4ws/` (4WS): the VCU's rear steering at speed,
- `sbw/` (SBW): the steer-by-wire A-class car,
- `abs/` (ABS): the ABS turning-state identification.

Each package holds its cases (`test_*.py`), its oracle (`oracle.py`: expected values from docs/spec/formulas.md),
its common steps (`steps.py`) and its acceptance limits (`limits.toml`, read by `testcases/limits.py`), and names
its campaign in `CAMPAIGN`, which testcases/conftest.py puts on every case as `@pytest.mark.campaign(name=...)`.
"""
