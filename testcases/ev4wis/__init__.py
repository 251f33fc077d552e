"""The 4WIS campaign: the 4WIS EV's VCU and wheel modules at low speed (docs/contract/vcu.md, wheel.md) and
their faults."""

CAMPAIGN = "4WIS"
