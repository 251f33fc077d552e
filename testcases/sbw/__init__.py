"""The SBW campaign: the steer-by-wire A-class car (docs/contract/sbw.md)."""

CAMPAIGN = "SBW"
