"""HIL CAN test bench for chassis ECUs: vehicle-agnostic bus access, restbus, monitors, logs and reports."""

__version__ = "0.1.0"
