"""The 4WS campaign: the VCU's rear steering at speed (docs/contract/vcu-4ws.md), and [P3] §2's closed forms
cross-checked on the A-class car."""

CAMPAIGN = "4WS"
