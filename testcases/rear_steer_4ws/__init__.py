"""The 4WS campaign: the VCU's rear steering at speed (docs/contract/vcu-4ws.md) and the A-class plant it is compared with."""

CAMPAIGN = "4WS"
