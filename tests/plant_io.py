"""One fake bus for stepping the EV's plant behaviours in a test: the latest values of each message.

Every value sent must be finite and inside its DBC range (plant/signal_ranges.py), so a test that steps the plant also
checks that no behaviour would put a NaN or an out-of-range value on the bus.
"""

from __future__ import annotations

import math

from plant import signal_ranges as ranges


class RangeCheckedIO:
    """The bus reduced to a dict of latest values (every node in one process, no latency)."""

    def __init__(self) -> None:
        self.t = 0.0
        self.values: dict[str, dict[str, float]] = {}

    @property
    def now(self) -> float:
        return self.t

    def send_values(self, message: str, **signals: float) -> None:
        for name, value in signals.items():
            assert math.isfinite(value), f"{message}.{name} = {value!r}"
            bounds = ranges.BY_SIGNAL.get((message, name))
            assert bounds is None or bounds[0] <= value <= bounds[1], f"{message}.{name} = {value}"
        self.values.setdefault(message, {}).update(signals)

    def latest(self, message: str) -> dict[str, float] | None:
        return self.values.get(message)

    def timed_out(self, message: str) -> bool:
        return message not in self.values

    def invalid(self, message: str) -> bool:
        return False

    def reset_outputs(self) -> None:
        pass

    def stop_sending(self, message: str) -> None:
        pass

    def resume_sending(self, message: str) -> None:
        pass
