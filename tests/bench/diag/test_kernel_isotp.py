"""The tester's endpoint on the kernel's ISO-TP (bench.diag.kernel_isotp).

On any host: the kernel's socket errors become the problem records the connection reports (a stand-in socket).
With CAN_ISOTP in the kernel (the vcan lane: scripts/vcan-lane --command 'python -m pytest
tests/bench/diag/test_kernel_isotp.py'): the kernel endpoint exchanges multi-frame messages on vcan0 with the
bench's own ISO-TP as the ECU, and reports a consecutive frame with the wrong sequence number as the rule it broke.
"""

from __future__ import annotations

import errno
import time

import can
import pytest

from bench.diag.isotp import IsoTpEndpoint, IsoTpParams
from bench.diag.kernel_isotp import KernelIsoTpEndpoint, kernel_isotp_available
from tests.integration.vcan import IN_LANE, has_vcan

REQUEST, RESPONSE = 0x7E0, 0x7E8
PARAMS = IsoTpParams(padding=0xCC)


class ErrorSocket:
    """A kernel ISO-TP socket that reports errors, then has nothing more."""

    def __init__(self, *errors: int) -> None:
        self.errors = list(errors)
        self.sent: list[bytes] = []

    def recv(self, size: int) -> bytes:
        if self.errors:
            raise OSError(self.errors.pop(0), "kernel")
        raise BlockingIOError

    def send(self, payload: bytes) -> int:
        self.sent.append(payload)
        return len(payload)


def test_kernel_errors_become_the_rules_they_break() -> None:
    endpoint = KernelIsoTpEndpoint("vcan0", REQUEST, RESPONSE, PARAMS)
    endpoint._socket = ErrorSocket(errno.EILSEQ, errno.ETIMEDOUT)   # type: ignore[assignment]
    endpoint.poll(1.5)
    assert [(p.t, p.rule) for p in endpoint.problems] == [(1.5, "sequence number"), (1.5, "N_Cr timeout")]
    assert "vcan0" in endpoint.problems[0].text and "0x7E0" in endpoint.problems[0].text
    assert not endpoint.received


def test_an_earlier_exchanges_error_is_recorded_before_the_next_request() -> None:
    endpoint = KernelIsoTpEndpoint("vcan0", REQUEST, RESPONSE, PARAMS)
    sock = ErrorSocket(errno.ECOMM)
    endpoint._socket = sock   # type: ignore[assignment]
    endpoint.transmit(2.0, b"\x19\x02\xff")
    assert [p.rule for p in endpoint.problems] == ["N_Bs timeout"]
    assert sock.sent == [b"\x19\x02\xff"]


# -- the real kernel (vcan lane) --------------------------------------------------------------------------
def _kernel_endpoint() -> KernelIsoTpEndpoint:
    endpoint = KernelIsoTpEndpoint("vcan0", REQUEST, RESPONSE, PARAMS)
    endpoint.open()
    return endpoint


def _run(bus: can.BusABC, ecu: IsoTpEndpoint, tester: KernelIsoTpEndpoint, until: float, done) -> None:
    """Carry frames from vcan0 to the bench's own endpoint (the ECU) and poll both until `done()` or `until` s."""
    t0 = time.monotonic()
    while not done() and (t := time.monotonic() - t0) < until:
        msg = bus.recv(0.002)
        if msg is not None and msg.arbitration_id == REQUEST:
            ecu.on_frame(t, bytes(msg.data))
        ecu.poll(t)
        tester.poll(t)


needs_kernel = pytest.mark.skipif(not (IN_LANE or (has_vcan("vcan0") and kernel_isotp_available())),
                                  reason="needs vcan0 and the kernel's ISO-TP (the vcan lane runs it)")


@needs_kernel
@pytest.mark.realtime
def test_multi_frame_both_ways_with_the_benchs_own_isotp() -> None:
    assert kernel_isotp_available(), "the lane's kernel must have CONFIG_CAN_ISOTP"
    bus = can.Bus(interface="socketcan", channel="vcan0", can_filters=[{"can_id": REQUEST, "can_mask": 0x7FF}])
    ecu = IsoTpEndpoint(RESPONSE, REQUEST,
                        lambda frame_id, data: bus.send(can.Message(arbitration_id=frame_id, data=data,
                                                                    is_extended_id=False)), PARAMS)
    tester = _kernel_endpoint()
    try:
        request = bytes(range(20))
        tester.transmit(0.0, request)
        _run(bus, ecu, tester, 2.0, lambda: bool(ecu.received))
        assert [payload for _, payload in ecu.received] == [request]
        response = bytes(range(100, 160))
        ecu.transmit(0.0, response)
        _run(bus, ecu, tester, 2.0, lambda: bool(tester.received))
        assert [payload for _, payload in tester.received] == [response]
        assert not tester.problems and not ecu.problems
    finally:
        tester.close()
        bus.shutdown()


@needs_kernel
@pytest.mark.realtime
def test_a_wrong_sequence_number_is_reported_by_rule() -> None:
    bus = can.Bus(interface="socketcan", channel="vcan0", can_filters=[{"can_id": REQUEST, "can_mask": 0x7FF}])
    tester = _kernel_endpoint()
    try:
        bus.send(can.Message(arbitration_id=RESPONSE, data=bytes([0x10, 20, 1, 2, 3, 4, 5, 6]), is_extended_id=False))
        flow = bus.recv(1.0)   # the kernel's flow control to our first frame
        assert flow is not None and flow.arbitration_id == REQUEST and flow.data[0] == 0x30, flow
        bus.send(can.Message(arbitration_id=RESPONSE, data=bytes([0x22, 7, 8, 9, 10, 11, 12, 13]),
                             is_extended_id=False))   # SN 2 where 1 is due
        t0 = time.monotonic()
        while not tester.problems and time.monotonic() - t0 < 1.0:
            tester.poll(time.monotonic() - t0)
            time.sleep(0.002)
        assert [p.rule for p in tester.problems] == ["sequence number"] and not tester.received
    finally:
        tester.close()
        bus.shutdown()
