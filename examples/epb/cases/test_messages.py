"""EPB-01: what the EPB sends on its own (cycle times, Profile 7, the multiplexed pages), and the rest of the vehicle
that the bench plays from the database (the gateway's 29-bit J1939 message) and the rig's cyclic-if-active
message: no plant, only the database's start values and send types."""

from __future__ import annotations

import pytest

from bench.case import Case


@pytest.mark.dut("EPB")
@pytest.mark.req("EPB-01")
def test_status_and_info_are_cyclic_and_protected(bench: Case) -> None:
    bench.run(2.0)
    bench.check_cycle_times(["EPB_Status", "EPB_Info"])
    bench.expect_clean_bus()   # every EPB_Status passes the Profile 7 check (CRC, counter in sequence)
    _, pages = bench.history("EPB_Info", "InfoPage")
    steps = [int(b) - int(a) for a, b in zip(pages, pages[1:])]
    bench.expect_true("EPB_Info pages in the order 0, 1, 2, 0, ...", len(pages) >= 15 and all(
        s in (1, -2) for s in steps), measured=" ".join(str(int(p)) for p in pages[:9]) + " ...",
        expected="0 1 2 0 1 2 ...")
    bench.expect("SoftwareMajor (page 0)", bench.value("EPB_Info", "SoftwareMajor"), 1)
    bench.expect_between("PadTemperature (page 2)", bench.value("EPB_Info", "PadTemperature"), -40, 215,
                         unit="degC")


def test_the_rest_of_the_vehicle_is_on_the_bus(bench: Case) -> None:
    """GW_Odometer (29-bit 0x18FEC1EE) from its GenSigStartValue: 2400000 raw × 0.005 km = 12000 km."""
    bench.run(1.2)
    bench.check_cycle_times(["GW_Odometer"])
    bench.expect("GW_Odometer.TotalDistance (its start value)", bench.value("GW_Odometer", "TotalDistance"),
                 12000.0, unit="km")


def test_the_service_request_is_sent_only_while_active(bench: Case) -> None:
    """HIL_Service is IfActive: silent while ServiceMode is OFF (its GenSigInactiveValue), every 50 ms while ON,
    one last frame saying OFF."""
    t0 = bench.now
    bench.run(0.5)
    bench.expect("HIL_Service frames while OFF", len(bench.history("HIL_Service", "ServiceMode", since=t0)[0]), 0)
    bench.set("HIL_Service", ServiceMode="ON")
    t_on = bench.now
    bench.run(0.5)
    on_times, _ = bench.history("HIL_Service", "ServiceMode", since=t_on)
    bench.expect("HIL_Service frames in 0.5 s ON (50 ms cycle)", len(on_times), 10, abs_tol=1)
    bench.set("HIL_Service", ServiceMode="OFF")
    t_off = bench.now
    bench.run(0.5)
    _, after = bench.history("HIL_Service", "ServiceMode", since=t_off)
    bench.expect_true("one last frame saying OFF, then silence", list(after) == [0.0],
                      measured=" ".join(f"{v:g}" for v in after) or "none", expected="0")
