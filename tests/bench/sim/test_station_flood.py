"""A babbling node on a bus that loops a sender's frames back (udp_multicast): the flood's identifier is no
periodic message, and the station must neither crash on it nor count its own echoes as foreign frames.

Issue 13: `flood:0x000` raised KeyError in Station._transmit on udp_multicast, and the next case then failed
in start_scenario.
"""

from __future__ import annotations

from bench.checks.monitor import Monitor
from bench.faults.plan import FaultPlan, parse_fault
from bench.sim.restbus import Restbus
from bench.sim.station import Station
from tests.fakes import FakeBus


def test_a_flood_on_a_looping_bus_is_sent_and_its_echoes_are_recognised(codebook) -> None:
    # like python-can's udp_multicast: every frame sent comes back to the sender's own socket, and the bus says
    # so with `receive_own_messages` (what bench.transport.capabilities asks of a bus without a socket)
    bus = FakeBus("loop", receive_own_messages=True)
    station = Station("runner", bus, Restbus(codebook, {"DRIVER"}), Monitor(codebook), lambda: 0.0, ())
    assert station.loops_back
    plan = FaultPlan(codebook)
    plan.add(parse_fault("flood:0x000:8@0-0.002"))
    station.faults, station.babbles = plan, True

    station.tick(0, 0.0, 0.001)           # 8 frames of identifier 0 at 8 frames/ms, no KeyError
    sent_floods = [m for m in bus.inbox if m.arbitration_id == 0]
    assert len(sent_floods) == 8
    unknown_before = station.monitor.unknown_frames   # the station logged its own 8 flood frames (tx)
    assert unknown_before == 8

    station.poll(0.0)                     # the echoes come back: recognised as our own, not counted again
    assert station.monitor.unknown_frames == unknown_before
    assert not any(m.arbitration_id == 0 for m in bus.inbox)
    bus.shutdown()
