"""Reference ECUs: one module per DBC node (stand-ins until a real ECU is plugged in)."""
