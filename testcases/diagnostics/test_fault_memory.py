"""The fault memory over operation cycles (docs/contract/diagnostics.md DIAG-OPC-01, DIAG-DTC-02 to -05), judged on
the VCU, whose fault the bench can provoke on any VCU, simulated or real: its request DRV_MotionRequest withheld
(VCU-FLT-01, REQUEST_TIMEOUT) for longer than the DTC's confirmation time.

Expected, from the contract's rules (the numbers from the declaration): the status byte while failing and confirmed
(0xAF with the warning indicator), after the fault (0xAE: testFailed clear, the rest kept); after an ECUReset
(a new operation cycle) testFailedThisOperationCycle clear and pendingDTC kept (the ended cycle failed); after the
next reset pendingDTC clear and, `healing_cycles` = 1 good cycle later, the warning indicator off; confirmedDTC
cleared (aged) after `aging_cycles` good cycles, with its snapshot and occurrence counter erased;
testFailedSinceLastClear kept throughout.
"""

from __future__ import annotations

import pytest

from bench.case import Case
from testcases.diagnostics.uds import limit, start
from testcases.fault_memory import CONFIRMED, PENDING, TFSLC, TFTOC, WIR, FaultMemory

NODE, DTC = "VCU", "REQUEST_TIMEOUT"


def _status(memory: FaultMemory, number: int) -> int:
    return memory.stored(0xFF).get(number, 0)


@pytest.mark.dut(NODE)
@pytest.mark.req("DIAG-OPC-01", "DIAG-DTC-01", "DIAG-DTC-02", "DIAG-DTC-03", "DIAG-DTC-04", "DIAG-DTC-05",
                 "VCU-DIAG-01", "VCU-FLT-01")
def test_confirmation_healing_and_aging(bench: Case) -> None:
    client = start(bench, NODE)
    memory = FaultMemory(bench, NODE)
    protocol, dtc = bench.diagnostic_protocol, bench.diagnostics(NODE).dtc(DTC)
    bench.run(0.5)
    t_fault = bench.now
    bench.stop_sending("DRV_MotionRequest")
    bench.run(dtc.confirm + 0.3)
    memory.during(DTC, t_fault)
    bench.resume_sending("DRV_MotionRequest")
    bench.wait_until(lambda: bench.value("VCU_VehicleState", "VcuFault") == 0, 1.0)
    bench.run(0.2)
    memory.after(DTC, t_fault)
    after = _status(memory, dtc.number)
    confirmed = TFTOC | PENDING | CONFIRMED | TFSLC | (WIR if dtc.warning_indicator else 0)
    bench.expect(f"{DTC} after the fault (status byte)", after, confirmed, detail="DIAG-DTC-03's example 0x2E + WIR")

    def new_cycle(why: str, expected: int) -> None:
        client.ecu_reset(1)
        bench.run(limit("reset_silence_max"))
        bench.expect(f"{DTC} status after an ECUReset: {why}", _status(memory, dtc.number), expected)

    cycle = confirmed & ~TFTOC                    # the ended cycle failed: pending and the lamp stay
    new_cycle("a new cycle, the last one failed", cycle)
    healed = cycle & ~PENDING
    if protocol.healing_cycles == 1:
        healed &= ~WIR
    new_cycle("one cycle without failure (healing)", healed)
    for n in range(2, protocol.aging_cycles):
        new_cycle(f"{n} cycles without failure", healed & ~WIR if n >= protocol.healing_cycles else healed)
    aged = TFSLC
    new_cycle(f"{protocol.aging_cycles} cycles without failure (aged)", aged)
    snapshot = client.get_dtc_snapshot_by_dtc_number(dtc.number, record_number=1).service_data.dtcs
    bench.expect("snapshot records after aging", sum(len(d.snapshots) for d in snapshot), 0)
    bench.expect_true("no status bit but testFailedSinceLastClear", _status(memory, dtc.number) & ~TFSLC == 0,
                      measured=f"0x{_status(memory, dtc.number):02X}", expected="0x20")
    memory.clear_and_reset()
