"""The DTC side of a fault case (docs/contract/diagnostics.md DIAG-DTC-*), read as a tester reads it.

A fault case clears the node's fault memory before its fault (nothing stored), and after it judges what the node
stored against the declaration (dbc/diagnostics.toml) and against the bus, which the bench recorded independently:
- while the fault lasts: the DTC of the fault code's name with testFailed, testFailedThisOperationCycle, pendingDTC
  and testFailedSinceLastClear; confirmedDTC once the fault code was on the bus longer than the DTC's confirmation
  time (not judged within one message cycle of it either way: the ECU's condition and its frame differ by up to a
  cycle);
- after it: testFailed clear, confirmedDTC kept as it was, the occurrence counter 1, the snapshot's live values
  within what the node sent around the moment its fault code first appeared on the bus, and its operating time
  consistent with the bench's clock;
- ClearDiagnosticInformation empties the memory, and it stays empty after an ECUReset.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from bench.case import Case
from testcases.diagnostics.uds import limit

#: status bits a failure sets (testFailed, TFTOC, pendingDTC, confirmedDTC, TFSLC): "stored" means any of them
STORED = 0x2F
TF, TFTOC, PENDING, CONFIRMED, TNCSLC, TFSLC, TNCTOC, WIR = (1 << bit for bit in range(8))
ALL_DTCS = 0xFFFFFF


@dataclass(frozen=True)
class OnBus:
    """How the fault code showed on the bus: first frame, how long it stayed, how many separate runs, the first
    frame of the latest run (the occurrence the snapshot records), and whether that frame may be late."""

    first: float
    lasted: float
    runs: int
    latest: float
    latest_may_be_late: bool


class FaultMemory:
    """One node's fault memory in one case: cleared at construction, judged by `during` and `after`."""

    def __init__(self, bench: Case, node: str) -> None:
        self.bench, self.node = bench, node
        self.declaration = bench.diagnostics(node)
        self.client = bench.diag(node)
        self.client.clear_dtc(ALL_DTCS)
        stored = self.stored()
        bench.expect_true(f"{node}: no DTC stored after ClearDiagnosticInformation, before the fault",
                          not stored, measured=self._text(stored) or "none", expected="none", node=node)

    # -- reading ----------------------------------------------------------------------------------
    def stored(self, mask: int = STORED) -> dict[int, int]:
        """{DTC number: status} of the DTCs whose status has a bit of `mask` (ReadDTCInformation 0x02)."""
        response = self.client.get_dtc_by_status_mask(mask)
        return {dtc.id: dtc.status.get_byte_as_int() for dtc in response.service_data.dtcs}

    def _text(self, stored: dict[int, int]) -> str:
        names = {d.number: f"{d.code} {d.name}" for d in self.declaration.dtcs}
        return ", ".join(f"{names.get(n, f'0x{n:06X}')} status 0x{s:02X}" for n, s in sorted(stored.items()))

    def _code_on_bus(self, name: str, since: float) -> OnBus:
        """The bench's own record of the fault, from the frames it received since `since`."""
        dtc = self.declaration.dtc(name)
        message, _, signal = dtc.fault.partition(".")
        value = self.bench.value_table(message, signal)[dtc.name]
        t, codes = self.bench.history(message, signal, since)
        is_on = codes == value
        on = np.flatnonzero(is_on)
        if not len(on):
            return OnBus(math.nan, math.nan, 0, math.nan, False)
        first = on[0]
        off = np.flatnonzero(~is_on[first:])
        end = t[first + off[0]] if len(off) else self.bench.now
        starts = np.flatnonzero(is_on & np.concatenate(([True], ~is_on[:-1])))
        last = int(starts[-1])
        cycle = float(np.median(np.diff(t))) if len(t) > 2 else 0.0
        # a gap of the message just before the code appeared: the node may have detected it while its frames could
        # not reach the bus (a flood, a bus-off), so the bus shows the code late
        late = last == 0 or t[last] - t[last - 1] > 2.5 * cycle
        return OnBus(float(t[first]), float(end - t[first]), len(starts), float(t[last]), bool(late))

    # -- judging ----------------------------------------------------------------------------------
    def during(self, name: str, since: float) -> None:
        """While the fault lasts: the DTC failed in this operation cycle; confirmed when its code has been on the
        bus for longer than its confirmation time (by more than a cycle of the fault message)."""
        bench, dtc = self.bench, self.declaration.dtc(name)
        seen = self._code_on_bus(name, since)
        first, lasted = seen.first, seen.lasted
        message, _, signal = dtc.fault.partition(".")
        if dtc.fault and bench.value(message, signal) != bench.value_table(message, signal)[dtc.name]:
            bench.note(f"{self.node}: {dtc.name} while it lasts: not judged, the fault code is no longer on the bus")
            return
        t_request = bench.now
        status = self.stored().get(dtc.number, 0)
        if dtc.fault and self._changed_during(message, signal, dtc.name, t_request):
            bench.note(f"{self.node}: {dtc.name} while it lasts: not judged, the node's fault code changed while the "
                       "tester read its status")
            return
        must = TF | TFTOC | PENDING | TFSLC
        bench.expect_true(f"{self.node}: DTC {dtc.code} {dtc.name} stored while the fault lasts "
                          "(testFailed, testFailedThisOperationCycle, pendingDTC, testFailedSinceLastClear)",
                          status & must == must, measured=f"0x{status:02X}", expected=f"bits 0x{must:02X} set",
                          detail=f"requirement {dtc.requirement}; fault code on the bus from "
                                 f"{first - bench.start:.3f} s" if math.isfinite(first) else "fault code never seen")
        self._confirmed(dtc.name, status, lasted)

    def _changed_during(self, message: str, signal: str, code_name: str, t_request: float) -> bool:
        """Whether a frame of the node from the request until the answer was complete carried another code, or the
        latest one does now: the node answered from a state the bus no longer shows (e.g. one fault code replaced
        by the next, a late host reading the answer late)."""
        bench = self.bench
        code = bench.value_table(message, signal)[code_name]
        t, values = bench.history(message, signal, since=t_request)
        return bool(np.any(values[t <= bench.now] != code)) or bench.value(message, signal) != code

    def _confirmed(self, name: str, status: int, lasted: float) -> None:
        bench, dtc = self.bench, self.declaration.dtc(name)
        message = dtc.fault.partition(".")[0]
        cycle = self._cycle(message)
        if not math.isfinite(lasted):
            return
        if lasted >= dtc.confirm + cycle:
            bench.expect_true(f"{self.node}: {dtc.name} confirmedDTC after {dtc.confirm * 1000:g} ms of failure",
                              bool(status & CONFIRMED), measured=f"0x{status:02X}", expected="confirmedDTC (0x08)",
                              detail=f"fault code on the bus for {lasted * 1000:.0f} ms")
            if dtc.warning_indicator:
                bench.expect_true(f"{self.node}: {dtc.name} warningIndicatorRequested with the confirmation",
                                  bool(status & WIR), measured=f"0x{status:02X}", expected="bit 0x80")
        elif lasted <= dtc.confirm - cycle:
            bench.expect_true(f"{self.node}: {dtc.name} not confirmed after {lasted * 1000:.0f} ms "
                              f"(confirmation {dtc.confirm * 1000:g} ms)", not status & CONFIRMED,
                              measured=f"0x{status:02X}", expected="no confirmedDTC (0x08)")
        else:
            bench.note(f"{dtc.name}: confirmedDTC not judged: the fault code lasted {lasted * 1000:.0f} ms, within a "
                       f"cycle ({cycle * 1000:g} ms) of the confirmation time {dtc.confirm * 1000:g} ms")

    def _cycle(self, message: str) -> float:
        """The fault message's cycle as the bench received it (median interval), s."""
        dtc = next(d for d in self.declaration.dtcs if d.fault.startswith(f"{message}."))
        t, _ = self.bench.history(message, dtc.fault.partition(".")[2])
        return float(np.median(np.diff(t))) if len(t) > 2 else 0.02

    def after(self, name: str, since: float, known: OnBus | None = None) -> None:
        """The fault is over: testFailed clear, the failure remembered (TFTOC, pending, TFSLC), confirmedDTC as it
        was while it lasted, one occurrence, and a snapshot consistent with what the bench recorded. `known`: what
        the case knows of the fault's presence from the fault itself, where the bus could not show it (a flood
        starves the node's frames while it detects the fault), in place of the bus's record."""
        bench, dtc = self.bench, self.declaration.dtc(name)
        seen = known or self._code_on_bus(name, since)
        lasted, runs = seen.lasted, seen.runs
        status = self.stored().get(dtc.number, 0)
        bench.expect_true(f"{self.node}: {dtc.name} testFailed clear once the fault is over", not status & TF,
                          measured=f"0x{status:02X}", expected="bit 0x01 clear")
        remembered = TFTOC | PENDING | TFSLC
        bench.expect_true(f"{self.node}: {dtc.name} failure remembered (TFTOC, pendingDTC, TFSLC)",
                          status & remembered == remembered, measured=f"0x{status:02X}",
                          expected=f"bits 0x{remembered:02X} set")
        self._confirmed(dtc.name, status, lasted)
        extended = self.client.get_dtc_extended_data_by_dtc_number(dtc.number, record_number=1, data_size=1)
        records = extended.service_data.dtcs[0].extended_data if extended.service_data.dtcs else []
        occurrences = records[0].raw_data[0] if records and records[0].raw_data else -1
        bench.expect(f"{self.node}: {dtc.name} occurrence counter (extended data record 0x01)", occurrences, runs,
                     detail=f"the fault code appeared {runs} separate time(s) on {dtc.fault}" if known is None
                     else "the fault was present once (known from the fault injected, not from the bus)")
        if math.isfinite(seen.latest):
            self._snapshot(dtc.number, dtc.name, seen)

    def _snapshot(self, number: int, name: str, seen: OnBus) -> None:
        bench, node = self.bench, self.declaration
        response = self.client.get_dtc_snapshot_by_dtc_number(number, record_number=1)
        dtcs = response.service_data.dtcs
        snapshots = {s.did: s.data for s in dtcs[0].snapshots} if dtcs else {}
        bench.expect_true(f"{self.node}: {name} snapshot record 0x01 holds the declared DIDs",
                          sorted(snapshots) == sorted(node.snapshot),
                          measured=", ".join(f"0x{d:04X}" for d in sorted(snapshots)) or "none",
                          expected=", ".join(f"0x{d:04X}" for d in sorted(node.snapshot)))
        for did_id, value in snapshots.items():
            did = node.did(did_id)
            if did.name == "OperatingTime":
                now = self.client.read_data_by_identifier_first(did.id)
                elapsed_node = float(now) - float(value)
                elapsed_bench = bench.now - seen.latest
                # the snapshot is taken when the ECU's condition is met, up to one cycle before its frame; the read
                # of the operating time now and the frame's receive time each add up to one tick and P2
                tol = limit("snapshot_time_slack") + bench.diagnostic_protocol.p2 + 2 * did.scale
                what = f"{self.node}: {name} snapshot OperatingTime against the bench's clock (time since the fault)"
                if seen.latest_may_be_late:
                    bench.expect_between(what, elapsed_node, elapsed_bench - tol, math.inf, unit="s",
                                         detail="the message had a gap just before: the node may have seen it first")
                else:
                    bench.expect(what, elapsed_node, elapsed_bench, abs_tol=tol, unit="s")
            elif did.signal and not isinstance(value, str):
                if seen.latest_may_be_late:
                    continue
                first = seen.latest
                message, _, signal = did.signal.partition(".")
                t, values = bench.history(message, signal, first - 0.1)
                span = limit("snapshot_window")
                window = values[(t >= first - span) & (t <= first + span)]
                if not len(window):
                    continue
                low, high = float(window.min()), float(window.max())
                bench.expect_between(f"{self.node}: {name} snapshot {did.name} within what {message}.{signal} "
                                     "carried around the fault", float(value), low - did.scale, high + did.scale,
                                     unit=did.unit, detail="±30 ms of the first frame with the fault code, ±1 LSB")

    def nothing_stored(self, why: str) -> None:
        """No DTC stored since the memory was cleared (a condition that is no fault)."""
        stored = self.stored()
        self.bench.expect_true(f"{self.node}: no DTC stored ({why})", not stored, measured=self._text(stored) or "none",
                               expected="none")

    def clear_and_reset(self) -> None:
        """ClearDiagnosticInformation empties the memory, and it stays empty after an ECUReset (hardReset)."""
        bench = self.bench
        self.client.clear_dtc(ALL_DTCS)
        stored = self.stored()
        bench.expect_true(f"{self.node}: no DTC stored after ClearDiagnosticInformation", not stored,
                          measured=self._text(stored) or "none", expected="none")
        self.client.ecu_reset(1)
        bench.run(limit("reset_silence_max"))
        stored = self.stored()
        bench.expect_true(f"{self.node}: still none after an ECUReset", not stored,
                          measured=self._text(stored) or "none", expected="none")
