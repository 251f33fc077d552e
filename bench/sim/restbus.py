"""Restbus simulation: every message of the simulated nodes, sent by its send type (bench.database.sendtype).

Cyclic messages go out at their cycle time; event messages (on change, on write) when a value is set, at least
their minimum gap apart and repeated as their database says; a cyclic-if-active message only while a signal differs
from its inactive value (and once more when it goes inactive); a cyclic-and-on-change message both ways.

Values start at the DBC start values; code (a test case or a node's behaviour) sets them by name.
The E2E counter and CRC are filled here by each message's profile (`bench.e2e.Protection`, docs/spec/e2e.md).
Values are checked when a frame is built (once per cycle), so a behaviour may set values every
plant tick at no cost; a NaN or out-of-range value stops the sender with an error naming it.

Most frames repeat their values (77 % of a PIVOT run's frames): a message whose values equal those of its last
frame reuses that frame's checked and encoded payload, and a payload keeps its protected frames (one per
counter value), so a repeat costs one dict comparison. Every new value is checked and encoded as before.
"""

from __future__ import annotations

import heapq
from collections.abc import Collection, Generator, Iterator, Mapping

from bench import canid
from bench.database import sendtype
from bench.database.codec import Codebook, MessageCodec
from bench.errors import ConfigError, SignalError

#: The largest E2E counter range whose frames the restbus keeps, one per counter value, while the values stay.
CACHED_COUNTERS = 256
#: How far a cycle time may lie from a whole number of ticks (relative): float noise, never a real offset.
TICK_FIT = 1e-6


class _Slot:
    __slots__ = ("codec", "values", "period", "next_due", "counter", "enabled", "sent_values", "payload", "frames",
                 "order", "modulo", "kind", "periodic", "events", "pending", "next_event", "gap", "repeat", "start",
                 "inactive_sent", "plain_cyclic", "variant", "pinned")

    def __init__(self, codec: MessageCodec, order: int) -> None:
        self.codec = codec
        self.order = order           # its place among the restbus' messages: frames due together go in this order
        self.values: dict[str, float | int | str] = dict(codec.start_values())
        self.period = 0              # ticks, and the first due tick: set with the scheduler's tick (Restbus.set_tick)
        self.next_due = 0
        self.counter = 0
        self.enabled = True
        # The cache of unchanged values (fast codecs only: equal values give equal raw numbers there; cantools'
        # float signals would not, -0.0 == 0.0): the values of the last frame as they were set (checked),
        # its payload without E2E bytes, and that payload's frames by counter.
        self.sent_values: dict[str, float | int | str] | None = None
        self.payload = b""
        self.modulo = codec.protection.counter_modulo if codec.protection is not None else 1
        # (a 32-bit counter, Profile 7, never comes round within a run: its frames are built each time)
        self.frames: list[bytes | None] | None = [None] * self.modulo if self.modulo <= CACHED_COUNTERS else None
        sending = codec.sending
        self.kind = sending.kind
        self.periodic = sending.periodic       # on the schedule at its cycle time
        self.events = sending.events           # sent when a value is set (on change, on write)
        # a frame every cycle, whatever its values, and the same frame while they stay (not multiplexed)
        self.plain_cyclic = sending.kind == sendtype.CYCLIC and not codec.multiplexed
        self.pending = 0                       # event frames still to send (the frame and its repetitions)
        self.next_event = 0                    # first tick an event frame may go out (its minimum gap after the last)
        self.gap = self.repeat = 1             # ticks: the minimum gap between event frames; between repetitions
        self.start = 0                         # ticks before its first frame (GenMsgStartDelayTime)
        self.inactive_sent = True              # cyclic_if_active: its last frame said "inactive" (or none yet): silent
        self.variant = 0                       # a multiplexed message: the index of its next frame's variant
        self.pinned: dict[str, int] = {}       # multiplexer values a case set: only variants with them are sent


def _order(slot: _Slot) -> int:
    return slot.order


class Restbus:
    """The periodic transmitter of one bus handle.

    It counts in the ticks of the scheduler that drives it, and the scheduler owns their length: it gives its dt
    (`set_tick`, bench.sim.clock.Scheduler; a station ticked by hand gives the dt of its first tick), and every
    message's period in ticks follows from that dt and the message's DBC cycle time. Why: with a tick length of
    its own the restbus would silently send every message at another cycle whenever the scheduler's dt changed."""

    def __init__(self, codebook: Codebook, nodes: Collection[str]) -> None:
        self.codebook = codebook
        self.nodes = frozenset(nodes)
        self.slots: dict[str, _Slot] = {}
        for codec in sorted(codebook.sent_by(self.nodes), key=lambda c: c.frame_id):
            if codec.diagnostic or (codec.sending.periodic and codec.cycle_time is None):
                continue   # sent by the diagnostic stack; a periodic one without a cycle time (bench dbc check)
            self.slots[codec.name] = _Slot(codec, len(self.slots))
        #: event messages with frames to send (an event frame's minimum gap or repetitions may still hold them)
        self.events: list[_Slot] = []
        self.dt: float | None = None   # s per tick, from the scheduler; None: no tick yet, nothing scheduled
        # The schedule: (next due tick, order, message), so a tick looks at the messages due then, not at all of
        # them; a stopped message that falls due waits aside (parked) until it is resumed. Read-only for others:
        # schedule[0][0] is the next due tick (a station skips `due` before it). Filled in place by `set_tick`.
        self.schedule: list[tuple[int, int, _Slot]] = []
        self._parked: dict[int, _Slot] = {}

    def set_tick(self, dt: float) -> None:
        """Schedule every message on ticks of `dt` seconds: its period is its DBC cycle time in ticks, its first
        frame at tick `identifier mod period` (messages of equal cycle spread over the period, so the bus load is
        even; deterministic). ConfigError, naming the message, when a cycle time is no whole number of ticks: the
        message could not keep its cycle. Called before the first tick; again with another dt, it schedules anew."""
        if dt == self.dt:
            return
        if not dt > 0:
            raise ConfigError(f"restbus: a tick of {dt!r} s is no tick (it must be a positive number of seconds)")
        periods: list[tuple[_Slot, int]] = []
        for slot in self.slots.values():
            sending = slot.codec.sending
            slot.gap = max(1, round(sending.min_gap / dt))
            slot.repeat = max(1, round(sending.repeat_gap / dt))
            slot.start = slot.next_event = round(sending.start_delay / dt)
            if not slot.periodic:
                continue
            cycle = slot.codec.cycle_time
            assert cycle is not None
            ticks = cycle / dt
            period = round(ticks)
            if period < 1 or abs(ticks - period) > TICK_FIT * ticks:
                raise ConfigError(f"{slot.codec.name}: its cycle time of {cycle * 1000:g} ms is no whole number of "
                                  f"the scheduler's {dt * 1000:g} ms ticks, so it cannot be sent at its cycle "
                                  "(choose a tick that divides every cycle time)")
            periods.append((slot, period))
        self.dt = dt
        for slot, period in periods:
            slot.period = period
            slot.next_due = slot.start or canid.arbitration_id(slot.codec.frame_id) % period
        self._parked.clear()
        self.schedule[:] = [(p.next_due, p.order, p) for p in self.slots.values() if p.periodic]
        heapq.heapify(self.schedule)

    def set(self, message: str, **signals: float | int | str) -> None:
        """Set values of a message this restbus sends (checked now: for test code)."""
        slot = self._slot(message)
        for name, value in signals.items():
            slot.codec.physical(name, value)
            if name in slot.codec.multiplexer_values:
                slot.pinned[name] = self._multiplexer_value(slot, name, value)
        if slot.events:
            self._event(slot, signals)
        slot.values.update(signals)

    def set_unchecked(self, message: str, signals: Mapping[str, float | int | str]) -> None:
        """Set values without checking now (for behaviours stepping every tick); checked at send."""
        slot = self.slots.get(message)
        if slot is None:
            slot = self._slot(message)
        if slot.events:
            self._event(slot, signals)
        slot.values.update(signals)

    def _event(self, slot: _Slot, signals: Mapping[str, float | int | str]) -> None:
        """An event message was written (before its values change): its frame and repetitions become due, for an
        on-change one only when a value changes."""
        if slot.kind != sendtype.ON_WRITE and all(slot.values.get(k) == v for k, v in signals.items()):
            return
        slot.pending = 1 + slot.codec.sending.repetitions
        if slot not in self.events:
            self.events.append(slot)

    def value(self, message: str, signal: str) -> float:
        """What the restbus sends for one signal now (physical; an enumeration's number): a simulated node's live
        value, e.g. for its diagnostic side's ReadDataByIdentifier."""
        slot = self._slot(message)
        value = slot.values[signal]
        if isinstance(value, str):
            return float(slot.codec.by_name[signal].choices[value])
        return float(value)

    @staticmethod
    def _multiplexer_value(slot: _Slot, name: str, value: float | int | str) -> int:
        """The raw multiplexer value a case sets (a SignalError naming the database's values when it has none)."""
        codec = slot.codec
        sig = codec.by_name[name]
        raw = round((codec.physical(name, value) - sig.offset) / sig.scale)
        known = codec.multiplexer_values[name]
        if raw not in known:
            raise SignalError(f"{codec.name}.{name}: {value!r} is no multiplexer value of the database "
                              f"(its values: {', '.join(str(k * sig.scale + sig.offset) for k in known)})")
        return raw

    def reset_values(self, message: str) -> None:
        slot = self._slot(message)
        slot.pinned.clear()
        start = slot.codec.start_values()
        if slot.events and slot.values != start:
            self._event(slot, start)
        slot.values = dict(start)

    def reset_all(self) -> None:
        for name in self.slots:
            self.reset_values(name)

    def stop_sending(self, message: str) -> None:
        """Stop sending a message until `resume_sending` (its counter carries on where it stopped). The one
        verb pair for this everywhere: Restbus, NodeIO and the `bench` fixture."""
        self._slot(message).enabled = False

    def resume_sending(self, message: str) -> None:
        """Send a message again after `stop_sending`, from its next due cycle on."""
        slot = self._slot(message)
        slot.enabled = True
        if self._parked.pop(slot.order, None) is not None:
            heapq.heappush(self.schedule, (slot.next_due, slot.order, slot))

    def _slot(self, message: str) -> _Slot:
        slot = self.slots.get(message)
        if slot is None:
            codec = self.codebook[message]
            raise SignalError(f"{message} is sent by {', '.join(codec.senders)}, which this bus handle "
                              f"does not simulate (simulated: {', '.join(sorted(self.nodes)) or 'none'})")
        return slot

    def due(self, tick: int) -> Generator[tuple[int, bytes], None, None]:
        """The frames due at this tick, each with its counter and checksum: the periodic ones in the messages' order,
        then the event frames whose minimum gap has passed. A caller that stops early closes the generator, so that
        the messages it did not take stay due (compiled, a generator is not closed when it is collected)."""
        queue = self.schedule
        if not queue or queue[0][0] > tick:
            if self.events:
                yield from self._events_due(tick)
            return
        ready = []
        while queue and queue[0][0] <= tick:
            ready.append(heapq.heappop(queue)[2])
        if len(ready) > 1:
            ready.sort(key=_order)
        done = 0
        try:
            for slot in ready:
                done += 1
                if not slot.enabled:
                    self._parked[slot.order] = slot
                    continue
                slot.next_due += slot.period
                if slot.next_due <= tick:           # fell behind (real time): skip, do not burst
                    slot.next_due = tick + slot.period
                heapq.heappush(queue, (slot.next_due, slot.order, slot))
                if not slot.plain_cyclic and slot.kind == sendtype.IF_ACTIVE and not self._active(slot):
                    if slot.inactive_sent:
                        continue             # inactive, and its last frame said so: silent until a value changes
                    slot.inactive_sent = True
                else:
                    slot.inactive_sent = False
                yield slot.codec.send_id, self.build(slot)
        finally:   # the caller stopped early (or a value was refused): the rest stay due
            for slot in ready[done:]:
                heapq.heappush(queue, (slot.next_due, slot.order, slot))
        if self.events:
            yield from self._events_due(tick)

    def _events_due(self, tick: int) -> Iterator[tuple[int, bytes]]:
        for slot in list(self.events):
            if not slot.enabled or tick < slot.next_event:
                continue
            slot.pending -= 1
            slot.next_event = tick + (slot.repeat if slot.pending else slot.gap)
            if not slot.pending:
                self.events.remove(slot)
            yield slot.codec.send_id, self.build(slot)

    @staticmethod
    def _next_variant(slot: _Slot) -> dict[str, float | int | str]:
        """A multiplexed message's values for its next frame: the next of its variants (the database's order, one
        per frame; only those with the multiplexer values a case set), its multiplexers set to that variant's."""
        codec = slot.codec
        pinned = slot.pinned
        count = len(codec.variants)
        for step in range(count):
            index = (slot.variant + step) % count
            chosen = codec.variants[index][0]
            if all(chosen.get(name, value) == value for name, value in pinned.items()):
                slot.variant = index + 1
                values = dict(slot.values)
                for name, raw in chosen.items():
                    sig = codec.by_name[name]
                    values[name] = raw * sig.scale + sig.offset
                return values
        return dict(slot.values)     # no variant has the pinned values (a cascaded one set alone): as set

    @staticmethod
    def _active(slot: _Slot) -> bool:
        """Whether a cyclic-if-active message has a signal away from its inactive value."""
        inactive = slot.codec.inactive or {}
        for name, value in slot.values.items():
            number = float(slot.codec.by_name[name].choices[value]) if isinstance(value, str) else value
            if name in inactive and number != inactive[name] and name not in slot.codec.e2e_signals:
                return True
        return False

    def build(self, slot: _Slot) -> bytes:
        """The next frame of a message: its values checked and encoded (or the last frame's payload when they
        are unchanged), then its counter and checksum."""
        codec = slot.codec
        values = slot.values
        if codec.multiplexed:
            values = self._next_variant(slot)
        if values != slot.sent_values:
            snapshot = dict(values)          # what is checked is what the cache remembers
            data = codec.encode(codec.checked(snapshot))
            protection = codec.protection
            if not codec.fast:
                if protection is not None:
                    protection.protect(data, slot.counter)
                    slot.counter = protection.next_counter(slot.counter)
                return bytes(data)
            payload = bytes(data)
            if payload != slot.payload:
                slot.payload = payload
                if slot.frames is not None:
                    slot.frames = [None] * slot.modulo
            slot.sent_values = snapshot
        protection = codec.protection
        if protection is None:
            return slot.payload
        counter = slot.counter
        frames = slot.frames
        frame = None if frames is None else frames[counter]
        if frame is None:
            data = bytearray(slot.payload)
            protection.protect(data, counter)
            frame = bytes(data)
            if frames is not None:
                frames[counter] = frame
        slot.counter = protection.next_counter(counter)
        return frame
