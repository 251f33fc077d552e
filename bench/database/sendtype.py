"""How a message is sent: its send type and the timing attributes that go with it, as a database declares them.

Why: an OEM's database has event-triggered messages beside cyclic ones, and Vector's interaction layer (the
attributes CANdb++ writes) says how each is sent. The restbus sends each message by its send type
(bench.sim.restbus) and the monitor judges it by the same (bench.checks.monitor): an on-change message is not late
for being silent, and a cyclic one is. The bench's names, and the database attributes they come from:

- `cyclic`: every cycle time (`GenMsgSendType` Cyclic);
- `on_change`: when a value changes (Spontan, OnChange), at least `GenMsgDelayTime` apart;
- `on_write`: whenever a value is written, changed or not (OnWrite; NoMsgSendType: not sent by the interaction layer
  on its own, only when written);
- `cyclic_if_active`: every cycle time while a signal differs from its inactive value (`GenSigInactiveValue`, else
  its start value), one last frame when it goes inactive, then silent (IfActive);
- `cyclic_and_on_change`: every cycle time and at once on a change, events at least `GenMsgDelayTime` apart
  (CyclicAndSpontan, CyclicAndOnChange).

An event frame is repeated `GenMsgNrOfRepetition` times, `GenMsgCycleTimeFast` apart (else `GenMsgDelayTime`, else
one tick); the first frame of any message waits `GenMsgStartDelayTime`. bench.toml's `[messages.NAME] send_type`
(the names above) overrides the database's. An ARXML frame, and a DBC message without any GenMsgSendType, is cyclic
when it has a cycle time, else sent when written.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from cantools.database.can import Message

CYCLIC, ON_CHANGE, ON_WRITE, IF_ACTIVE, CYCLIC_AND_ON_CHANGE = (
    "cyclic", "on_change", "on_write", "cyclic_if_active", "cyclic_and_on_change")
#: The bench's send types (bench.toml's `send_type` values), in the order the docs list them.
KINDS = (CYCLIC, ON_CHANGE, ON_WRITE, IF_ACTIVE, CYCLIC_AND_ON_CHANGE)
PERIODIC = frozenset((CYCLIC, IF_ACTIVE, CYCLIC_AND_ON_CHANGE))   # need a cycle time
EVENTS = frozenset((ON_CHANGE, ON_WRITE, CYCLIC_AND_ON_CHANGE))    # sent when a value is set

#: Vector's GenMsgSendType values (case, "_" and blanks ignored) -> the bench's send type.
VECTOR = {"cyclic": CYCLIC, "spontan": ON_CHANGE, "spontaneous": ON_CHANGE, "onchange": ON_CHANGE,
          "onchangewithrepetition": ON_CHANGE, "onwrite": ON_WRITE, "onwritewithrepetition": ON_WRITE,
          "nomsgsendtype": ON_WRITE, "ifactive": IF_ACTIVE, "cyclicifactive": IF_ACTIVE,
          "ifactivewithrepetition": IF_ACTIVE, "cyclicandspontan": CYCLIC_AND_ON_CHANGE,
          "cyclicandspontaneous": CYCLIC_AND_ON_CHANGE, "cyclicandonchange": CYCLIC_AND_ON_CHANGE,
          "cyclicandonwrite": CYCLIC_AND_ON_CHANGE, "event": ON_CHANGE}


class SendTypeError(ValueError):
    """A send type or timing attribute the bench cannot use (the text names it)."""


@dataclass(frozen=True, slots=True)
class Sending:
    """How one message is sent."""

    kind: str = CYCLIC
    min_gap: float = 0.0          # s between two event frames at least (GenMsgDelayTime)
    repetitions: int = 0          # extra frames after an event frame (GenMsgNrOfRepetition)
    repeat_gap: float = 0.0       # s between those repetitions (GenMsgCycleTimeFast, else min_gap; 0: a tick)
    start_delay: float = 0.0      # s before its first frame (GenMsgStartDelayTime)
    source: str = ""              # where the kind came from, for messages ("GenMsgSendType 'Spontan'")

    @property
    def periodic(self) -> bool:
        return self.kind in PERIODIC

    @property
    def events(self) -> bool:
        return self.kind in EVENTS


def kind_of(name: object) -> str | None:
    """The bench's send type of a database's (or bench.toml's) name; None when the bench knows no such type."""
    text = str(name).strip().strip('"')
    if text in KINDS:
        return text
    return VECTOR.get(text.lower().replace("_", "").replace(" ", "").replace("-", ""))


def sending(message: Message, definitions: Mapping[str, Any] | None = None, override: str | None = None
            ) -> Sending:
    """The message's sending from its database (`definitions`: the DBC's attribute definitions, for the defaults of
    attributes the message does not set) and bench.toml's send type `override`. SendTypeError names the problem."""
    attributes = message.dbc.attributes if message.dbc is not None else {}

    def attribute(name: str) -> Any:
        found = attributes.get(name)
        if found is not None:
            return found.value
        return getattr((definitions or {}).get(name), "default_value", None)

    def milliseconds(name: str) -> float:
        value = attribute(name)
        if value in (None, ""):
            return 0.0
        try:
            number = float(value)
        except (TypeError, ValueError):
            raise SendTypeError(f"{name} {value!r} is not a number of ms") from None
        if not number >= 0:
            raise SendTypeError(f"{name} {value!r} is not a number of ms >= 0")
        return number / 1000.0

    if override is not None:
        kind, source = kind_of(override), f"bench.toml send_type {override!r}"
        if kind is None:
            raise SendTypeError(f"send_type {override!r} is no send type the bench knows ({', '.join(KINDS)})")
    elif message.dbc is None:     # ARXML: its timing has a cycle time, or it is sent when written
        kind = CYCLIC if message.cycle_time else ON_WRITE
        source = "the frame's cyclic timing" if message.cycle_time else "no cyclic timing: sent when written"
    else:
        declared = message.send_type if message.send_type is not None else attribute("GenMsgSendType")
        if declared is None:   # the database says nothing: cyclic with a cycle time (as an interaction layer)
            kind = CYCLIC if message.cycle_time else ON_WRITE
            return Sending(kind, source=f"no GenMsgSendType: {kind}, the bench's default "
                                        f"({'it has' if message.cycle_time else 'without'} a cycle time)")
        kind, source = kind_of(declared), f"GenMsgSendType {declared!r}"
        if kind is None:
            raise SendTypeError(f"GenMsgSendType {declared!r} is no send type the bench knows (Vector's Cyclic, "
                                "Spontan/OnChange, OnWrite, NoMsgSendType, IfActive, CyclicAndSpontan)")
    repetitions = attribute("GenMsgNrOfRepetition")
    try:
        repeats = int(repetitions or 0)
    except (TypeError, ValueError):
        raise SendTypeError(f"GenMsgNrOfRepetition {repetitions!r} is not a whole number") from None
    if repeats < 0:
        raise SendTypeError(f"GenMsgNrOfRepetition {repetitions!r} is not a whole number >= 0")
    min_gap = milliseconds("GenMsgDelayTime")
    return Sending(kind, min_gap, repeats, milliseconds("GenMsgCycleTimeFast") or min_gap,
                   milliseconds("GenMsgStartDelayTime"), source)


def inactive_values(message: Message, definitions: Mapping[str, Any] | None = None) -> dict[str, float] | None:
    """Each signal's inactive raw value (`GenSigInactiveValue`), None when the database declares none for any."""
    found: dict[str, float] = {}
    default = getattr((definitions or {}).get("GenSigInactiveValue"), "default_value", None)
    for signal in message.signals:
        attributes = signal.dbc.attributes if signal.dbc is not None else {}
        value = attributes["GenSigInactiveValue"].value if "GenSigInactiveValue" in attributes else default
        if value is not None:
            found[signal.name] = float(value)
    return found or None
