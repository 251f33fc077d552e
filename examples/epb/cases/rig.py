"""What every EPB case does on the rig: move the park switch, set the vehicle, bring the EPB to a state, read its
events. Numbers are those of contract.md."""

from __future__ import annotations

from collections.abc import Callable

from bench.case import Case

#: contract.md EPB-03/-04/-06/-07: a reaction within 30 ms, seen in the next EPB_Status (20 ms) or EPB_Event
REACTION_S = 0.030 + 0.020
#: EPB-03/-04: 16 kN at 20 kN/s
FORCE_KN, RATE_KN_S = 16.0, 20.0
#: the ramp's time from 0 to 16 kN, and the reaction before it
RAMP_S = FORCE_KN / RATE_KN_S + REACTION_S


def park_state(bench: Case, name: str) -> int:
    """The number of a ParkState name (the database's value table)."""
    return bench.value_table("EPB_Status", "ParkState")[name]


def in_state(bench: Case, name: str) -> Callable[[], bool]:
    """A predicate for `eventually`/`always`: the latest EPB_Status says ParkState `name`."""
    wanted = park_state(bench, name)
    return lambda: bench.value("EPB_Status", "ParkState") == wanted


def vehicle(bench: Case, speed_kmh: float, pedal: str) -> None:
    bench.set("HIL_VehicleState", VehicleSpeed=speed_kmh, BrakePedal=pedal)


def switch(bench: Case, position: str) -> float:
    """Move the park switch to `position` from NEUTRAL (a change the EPB reacts to, EPB-03: the switch frame goes
    out only when the position changes); returns the bench time of the change."""
    bench.set("HIL_ParkSwitch", Switch="NEUTRAL")
    bench.run(0.05)
    bench.set("HIL_ParkSwitch", Switch=position)
    return bench.now


def service(bench: Case, mode: str) -> None:
    """Switch the service request and wait for its first frame (HIL_Service is cyclic-if-active: the frame that
    starts or ends it goes at the message's next cycle, up to 50 ms later); the EPB's reaction counts from it."""
    bench.set("HIL_Service", ServiceMode=mode)
    wanted = bench.value_table("HIL_Service", "ServiceMode")[mode]
    bench.wait_until(lambda: bench.value("HIL_Service", "ServiceMode") == wanted, 0.1)


def bring_to(bench: Case, wanted: str) -> None:
    """The EPB in RELEASED or APPLIED before a case (the state stays from the last case): one step of the case."""
    vehicle(bench, 0.0, "PRESSED")
    bench.run(0.05)
    there = in_state(bench, wanted)
    if not there():
        switch(bench, "APPLY" if wanted == "APPLIED" else "RELEASE")
    bench.eventually(f"the EPB is {wanted} before the case", there, RAMP_S + 0.5)
    bench.run(0.05)   # the event of that move is out before the case looks for its own


def events(bench: Case, since: float) -> list[str]:
    """The EventCode names of the EPB_Event frames since `since` (bench time), in order."""
    names = {number: name for name, number in bench.value_table("EPB_Event", "EventCode").items()}
    _, codes = bench.history("EPB_Event", "EventCode", since=since)
    return [names.get(int(c), str(int(c))) for c in codes]


def expect_events(bench: Case, since: float, wanted: list[str]) -> bool:
    """One step: the EPB's events since `since` are `wanted`, in order, and no other (EPB-06)."""
    got = events(bench, since)
    return bench.expect_true(f"events: {', '.join(wanted) or 'none'}", got == wanted,
                             measured=", ".join(got) or "none", expected=", ".join(wanted) or "none")
