"""The restbus' cache of unchanged values (bench/sim/restbus.py) sends exactly the frames a fresh check and encoding
would: for any sequence of values set, reset and sent, every frame equals cantools' encoding of the values with
the contract's AliveCounter and Profile 11 CRC (tests/reference.py), and every bad value is refused at every send,
named with its value."""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bench.database.codec import Codebook, MessageCodec, load_codebook
from bench.errors import SignalError
from bench.sim.restbus import Restbus
from tests.reference import COUNTER_VALUES, protected
from tests.repo import BENCH_DBC, CHASSIS_DBC

CODEBOOK = load_codebook([CHASSIS_DBC, BENCH_DBC])
MESSAGES = sorted(name for name, c in CODEBOOK.by_name.items() if c.cycle_time is not None)


def _good(codec: MessageCodec, name: str) -> list[float | int | str]:
    """Values a signal may take: exact raw steps inside its DBC range and its bit field, as float, int, -0.0
    and value-table names."""
    s = codec.by_name[name]
    lo_raw = -(1 << (s.length - 1)) if s.signed else 0
    hi_raw = (1 << (s.length - 1)) - 1 if s.signed else (1 << s.length) - 1
    raws = {lo_raw, hi_raw, 0, 1, (lo_raw + hi_raw) // 2}
    out: list[float | int | str] = []
    for raw in sorted(raws):
        value = raw * s.scale + s.offset
        if (s.minimum is None or value >= s.minimum) and (s.maximum is None or value <= s.maximum):
            out.append(value)
            if value == int(value):
                out.append(int(value))
            if value == 0:
                out.append(-0.0)
    out.extend(s.choices)
    return out or [codec.start_values()[name]]


def _bad(codec: MessageCodec, name: str) -> list[object]:
    s = codec.by_name[name]
    out: list[object] = [math.nan, math.inf, "no such name"]
    if s.maximum is not None:
        out.append(s.maximum + abs(s.scale) + 1.0)
    if s.minimum is not None:
        out.append(s.minimum - abs(s.scale) - 1.0)
    return out


def _number(codec: MessageCodec, name: str, value: object) -> float:
    return float(codec.by_name[name].choices[value]) if isinstance(value, str) else float(value)  # type: ignore[arg-type]


def _expected(codec: MessageCodec, values: dict[str, object], counter: int) -> bytes:
    """cantools' encoding, then the AliveCounter (bits 56-59) and the Profile 11 CRC in byte 6 over DataID (the
    identifier) low, high, bytes 0-5 and byte 7 (docs/spec/e2e.md)."""
    physical = {n: _number(codec, n, v) for n, v in values.items()}
    return protected(codec.frame_id, codec.message.encode(physical, scaling=True, strict=False, padding=False),
                     counter)


def _is_bad(codec: MessageCodec, name: str, value: object) -> bool:
    """Not a value-table name, not a finite number, or outside the DBC range (the bad values of `_bad` lie a
    step and more outside it, the good ones inside)."""
    s = codec.by_name[name]
    if isinstance(value, str):
        return value not in s.choices
    number = float(value)  # type: ignore[arg-type]
    return (not math.isfinite(number) or (s.minimum is not None and number < s.minimum)
            or (s.maximum is not None and number > s.maximum))


@st.composite
def _scenario(draw: st.DrawFn) -> tuple[str, list[tuple[str, dict[str, Any]]]]:
    name = draw(st.sampled_from(MESSAGES))
    codec = CODEBOOK[name]
    step: st.SearchStrategy[tuple[str, dict[str, Any]]] = st.one_of(
        st.just(("send", {})),
        st.just(("reset", {})),
        st.builds(lambda d: ("set", d), st.dictionaries(
            st.sampled_from(codec.signal_names),
            st.sampled_from(["good", "good", "good", "bad"]), max_size=3).flatmap(
            lambda kinds: st.fixed_dictionaries({
                sig: st.sampled_from(_good(codec, sig) if kind == "good" else _bad(codec, sig))
                for sig, kind in kinds.items()}))),
    )
    return name, draw(st.lists(step, min_size=1, max_size=40))


@settings(max_examples=300, deadline=None)
@given(_scenario())
def test_cached_frames_equal_a_fresh_encoding(scenario: tuple[str, list[tuple[str, dict[str, Any]]]]) -> None:
    name, steps = scenario
    codec = CODEBOOK[name]
    restbus = Restbus(CODEBOOK, codec.senders)
    slot = restbus.slots[name]
    model: dict[str, object] = dict(codec.start_values())
    counter = 0
    for kind, values in steps:
        if kind == "set":
            restbus.set_unchecked(name, values)
            model.update(values)
        elif kind == "reset":
            restbus.reset_values(name)
            model = dict(codec.start_values())
        for _ in range(2):                     # each state is sent twice: the second is the cache's
            bad = [n for n, v in model.items() if _is_bad(codec, n, v)]
            if bad:
                with pytest.raises(SignalError) as caught:
                    restbus.build(slot)
                assert any(f"{name}.{n}: {model[n]!r}" in str(caught.value)
                           or f"{name}.{n}: {_number_or(model[n])}" in str(caught.value) for n in bad), caught.value
                continue
            assert restbus.build(slot) == _expected(codec, model, counter)
            counter = (counter + 1) % COUNTER_VALUES


def _number_or(value: object) -> str:
    return f"{value:g}" if isinstance(value, float) else repr(value)


@pytest.mark.parametrize("name", ["DRV_MotionRequest", "VCU_WheelCmd_FL"])
def test_a_bad_value_is_refused_at_every_send(codebook: Codebook, name: str) -> None:
    """A value set unchecked that is out of range is refused at every send, not only the first, even after the
    same message was sent (and cached) with good values; the counter does not move for a refused frame."""
    restbus = Restbus(codebook, codebook[name].senders)
    slot = restbus.slots[name]
    first = restbus.build(slot)
    assert restbus.build(slot) != first       # another counter
    signal = next(s for s in codebook[name].signals if s.maximum is not None and s.name != "Checksum")
    assert signal.maximum is not None
    restbus.set_unchecked(name, {signal.name: signal.maximum + 10 * abs(signal.scale) + 1})
    for _ in range(3):
        with pytest.raises(SignalError, match=f"{name}.{signal.name}"):
            restbus.build(slot)
    assert slot.counter == 2
    restbus.reset_values(name)
    assert restbus.build(slot) == _expected(codebook[name], dict(codebook[name].start_values()), 2)


def _scan_due(restbus: Restbus, tick: int) -> Iterator[tuple[int, bytes]]:
    """The restbus' schedule as it was written before its queue: every message looked at every tick."""
    for slot in restbus.slots.values():
        if tick < slot.next_due or not slot.enabled:
            continue
        slot.next_due += slot.period
        if slot.next_due <= tick:
            slot.next_due = tick + slot.period
        yield slot.codec.frame_id, restbus.build(slot)


@settings(max_examples=150, deadline=None)
@given(st.sampled_from(["VCU", "PLANT", "BENCH"]),
       st.lists(st.tuples(st.integers(1, 25), st.sampled_from(["run", "run", "run", "stop", "resume", "partial"]),
                          st.integers(0, 40)), min_size=1, max_size=120))
def test_the_schedule_sends_what_a_scan_of_every_message_sent(node: str, steps: list[tuple[int, str, int]]) -> None:
    """The queue of due messages gives the frames (and their order within a tick) of a scan over every message,
    through skipped ticks (real time falling behind), stopped and resumed messages and a caller that stops
    reading a tick's frames part way."""
    nodes = {"BENCH": {"BENCH", "DRV"}}.get(node, {node})
    if not any(CODEBOOK.sent_by(nodes)):
        return
    ours, theirs = Restbus(CODEBOOK, nodes), Restbus(CODEBOOK, nodes)
    ours.set_tick(0.001)     # the scheduler's tick, given as a scheduler gives it
    theirs.set_tick(0.001)
    names = sorted(ours.slots)
    tick = 0
    for skip, action, pick in steps:
        name = names[pick % len(names)]
        if action == "stop":
            ours.stop_sending(name)
            theirs.stop_sending(name)
            continue
        if action == "resume":
            ours.resume_sending(name)
            theirs.resume_sending(name)
            continue
        tick += skip
        if action == "partial":   # the caller reads `pick % 3` frames of this tick, then closes the generator
            due = ours.due(tick)
            a = [f for _, f in zip(range(pick % 3), due)]
            due.close()
            b = [f for _, f in zip(range(pick % 3), _scan_due(theirs, tick))]
        else:
            a, b = list(ours.due(tick)), list(_scan_due(theirs, tick))
        assert a == b, (tick, action, name)
