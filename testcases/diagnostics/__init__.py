"""The diagnostics campaign: every node's UDS services, sessions, security, coding, routines and fault memory
(docs/contract/diagnostics.md, the `*-DIAG-*` sections of the node documents, dbc/diagnostics.toml)."""

CAMPAIGN = "diagnostics"
