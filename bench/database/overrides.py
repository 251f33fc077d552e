"""bench.toml's `[messages.NAME]`: what a database lacks, or gets wrong, for one message, supplied by the project.

An OEM's database is not the engineer's to edit, and many lack what the restbus needs to send a message: a cycle
time (`GenMsgCycleTime`) or a send type (`GenMsgSendType`). A table per message supplies it, over the database's
own value, the way `[e2e.NAME]` supplies end-to-end protection:

    [messages.BrakeStatus]
    cycle_time_ms = 10
    send_type = "cyclic"        # or on_change, on_write, cyclic_if_active, cyclic_and_on_change

Only the form is checked when bench.toml is read (`bench.config`); a message name no database has is refused with the
databases (`bench.database.codec.Codebook`, `bench dbc check`), with the name meant.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from bench.database import sendtype
from bench.errors import did_you_mean

TABLE = "messages"
CYCLE_TIME = "cycle_time_ms"
SEND_TYPE = "send_type"
SEND_TYPES = sendtype.KINDS      # send_type's values (bench.database.sendtype)

MessageOverrides = Mapping[str, Mapping[str, Any]]


def cycle_time_ms(overrides: MessageOverrides | None, message: str) -> float | None:
    """The cycle time bench.toml gives this message, ms; None when it gives none."""
    value = (overrides or {}).get(message, {}).get(CYCLE_TIME)
    return None if value is None else float(value)


def send_type(overrides: MessageOverrides | None, message: str) -> str | None:
    """The send type bench.toml gives this message; None when it gives none."""
    value = (overrides or {}).get(message, {}).get(SEND_TYPE)
    return None if value is None else str(value)


def unknown_messages(overrides: MessageOverrides | None, names: list[str]) -> list[str]:
    """One line per [messages.NAME] that names no message of the databases."""
    return [f"bench.toml: [{TABLE}.{name}]: no such message in the databases{did_you_mean(name, names)}"
            for name in (overrides or {}) if name not in names]


def hint(message: str, key: str, example: str) -> str:
    """How a project supplies what its database lacks: the key to set."""
    return f"bench.toml [{TABLE}.{message}] {key} = {example} supplies it"
