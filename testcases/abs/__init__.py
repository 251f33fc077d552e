"""The ABS campaign: the ABS turning-state identification of the braking A-class car (docs/contract/abs.md)."""

CAMPAIGN = "ABS"
