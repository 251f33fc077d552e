"""examples/vcu_ecu.py, a VCU written from the contract documents alone, judged as an external node (issue 13).

Three processes on one host (udp_multicast, hop limit 0: nothing leaves the host): `bench plant --external VCU`
simulates every node but the VCU, the example plays the VCU, and `bench run --external all --dut VCU` runs every
case that judges the VCU (the 4WIS campaign, the 4WS cases at speed, the fault cases), whose expected values come
from testcases/ev4wis/oracle.py and testcases/rear_steer_4ws/oracle.py (docs/spec/formulas.md), not from the
example. Cases that can only judge the reference VCU (`reference_only`) must be skipped with their reason, and the
report must show the VCU's conformance table. Unit tests below check the example's kinematics without a bus against
the rigid-body definition of docs/spec/formulas.md §2 (independent of the paper's eq. 1-10 the example implements).
"""

from __future__ import annotations

import importlib.util
import math
import random
import sys
import time

import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from tests.repo import E2E_ATTRIBUTE_DEFINITIONS, ROOT

EXAMPLE = ROOT / "examples" / "vcu_ecu.py"


def _load_example():
    spec = importlib.util.spec_from_file_location("vcu_ecu", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module          # dataclasses look their module up while the class is built
    spec.loader.exec_module(module)
    return module


VCU = _load_example()
# docs/spec/vehicles.md A
WHEELS = {"FL": (-0.555, 1.38), "FR": (0.555, 1.38), "RL": (-0.555, -1.38), "RR": (0.555, -1.38)}
RADIUS = 0.281
RPM_PER_MPS = 30 / (math.pi * RADIUS)
HALF_ANGLE_STEP = math.sin(math.radians(0.005))   # half the bus step of SteerAngleCmd (0.01°), as a sine


@settings(max_examples=300, deadline=None)
@given(x=st.floats(-50, 50), y=st.floats(-50, 50), v=st.floats(-2, 2))
@example(x=0.5557757917453627, y=8.0, v=1.0)      # RR's exact angle -89.995° rounds to -90.00° on the bus
def test_example_kinematics_are_a_rigid_rotation(x: float, y: float, v: float) -> None:
    """docs/spec/formulas.md §2 without the paper: each wheel's velocity is ω × (P - S) with ω = v_o / r_o (clockwise);
    its heading must be perpendicular to P - S (angle in (-90°, 90°]) and its speed the projection."""
    plan = VCU.plan_pivot(x, y, v)
    fault = VCU.centre_fault(plan)
    r_o = math.hypot(x, y)
    if any(math.hypot(x - px, y - py) < 0.01 for px, py in WHEELS.values()) and not (r_o < 0.01 and v != 0.0):
        assert fault == VCU.CENTRE_ON_WHEEL
        return
    if r_o < 0.01 and v != 0.0:
        assert fault == VCU.CENTRE_AT_ORIGIN
        return
    assert fault == VCU.OK
    command = VCU.execute(plan)
    omega = v / r_o if v != 0.0 else 0.0
    speeds = {name: (omega * (py - y), omega * (x - px)) for name, (px, py) in WHEELS.items()}  # ω × (P - S)
    if VCU.exceeds_limits(command):                              # beyond the hub motors or the yaw limit
        worst = max(math.hypot(*s) for s in speeds.values()) * RPM_PER_MPS
        assert worst > 1500 - 1e-6 or abs(math.degrees(omega)) > 120 - 1e-6
        return
    for name, (px, py) in WHEELS.items():
        angle, rpm, (vx, vy) = command.angles[name], command.speeds[name], speeds[name]
        assert -90.0 < angle <= 90.0, (name, angle)
        heading = (math.sin(math.radians(angle)), math.cos(math.radians(angle)))
        radius = (px - x, py - y)
        # perpendicular to P - S and the projected speed, each within half a step of what the bus carries (0.01°,
        # 0.1 rpm): a centre whose exact angle rounds to -90.00° on the bus is sent as +90° (COM-VAL-02)
        assert abs(heading[0] * radius[0] + heading[1] * radius[1]) <= HALF_ANGLE_STEP * math.hypot(*radius), name
        projected = (vx * heading[0] + vy * heading[1]) * RPM_PER_MPS
        assert math.isclose(rpm, projected, rel_tol=1e-9, abs_tol=0.05), (name, rpm, projected)
    assert math.isclose(command.yaw_rate, math.degrees(omega), rel_tol=1e-12, abs_tol=1e-12)


def test_example_car_modes_put_the_centre_where_the_contract_says() -> None:
    """NORMAL: X = HandWheelAngle / 15 and S on y = -L (docs/contract/vcu.md VCU-MODE-04); ADAPTIVE below
    20 km/h: S on y = 0 (VCU-MODE-05); LATERAL: +90° with signed rpm (VCU-MODE-08)."""
    for plan, y_centre, factor in ((VCU.plan_normal(300.0, 1.0), -1.38, 2.0),
                                   (VCU.plan_adaptive(300.0, 1.0, 1.0), 0.0, 1.0)):
        x_deg = 300.0 / 15.0
        assert VCU.centre_fault(plan) == VCU.OK and plan.curvature == x_deg
        cx, cy = plan.centre
        assert math.isclose(cy, y_centre) and math.isclose(cx, factor * 1.38 / math.tan(math.radians(x_deg)))
        # the front-axle centre (0, L) heads at X about S ([P2]'s curvature angle)
        assert math.isclose(math.degrees(math.atan((1.38 - cy) / cx)), x_deg)
        assert all(n > 0 for n in VCU.execute(plan).speeds.values())   # forward: every wheel rolls forward
    command = VCU.execute(VCU.plan_lateral(-1.5))
    assert list(command.angles.values()) == [90.0] * 4
    assert all(math.isclose(n, -1.5 * RPM_PER_MPS) for n in command.speeds.values())


@settings(max_examples=300, deadline=None)
@given(st.lists(st.tuples(st.floats(-90, 90), st.floats(-1500, 1500)), min_size=4, max_size=4))
def test_example_rigid_fit_is_the_least_squares_fit(wheels: list[tuple[float, float]]) -> None:
    """VCU-OUT-05 without numpy in the example: its normal equations give numpy's pseudo-inverse fit."""
    import numpy as np

    rows, velocities = [], []
    for (x, y), (angle, rpm) in zip(WHEELS.values(), wheels):
        rows += [[1.0, 0.0, y], [0.0, 1.0, -x]]
        speed = rpm / RPM_PER_MPS
        velocities += [speed * math.sin(math.radians(angle)), speed * math.cos(math.radians(angle))]
    expected = np.linalg.pinv(np.array(rows)) @ np.array(velocities)
    fit = VCU.rigid_fit(dict(zip(WHEELS, wheels)))
    assert np.allclose(fit, expected, rtol=1e-12, atol=1e-12), (fit, expected)


def _chassis():
    import cantools

    return cantools.database.load_file(str(ROOT / "dbc" / "chassis.dbc"))


def test_example_protection_is_the_databases() -> None:
    """The example configures each message's E2E from the DBC's E2E_* attributes (the database's defaults where a
    message sets none; ENUM values by name) and protects with autosar-e2e: every frame it sends passes the
    library's P11 check with the message's E2E_DataID, and the bench's own check of that message."""
    from e2e import p11

    from bench.e2e import protection

    db = _chassis()
    definitions = db.dbc.attribute_definitions
    for message in db.messages:
        config = VCU.e2e_config(db, message)
        bench = protection(message, definitions)
        if message.name.startswith("DIAG_"):   # ISO-TP carries no E2E (docs/contract/diagnostics.md DIAG-TP-01)
            assert config is None and bench is None, message.name
            continue
        assert config is not None and bench is not None and config.profile == bench.profile == "P11"
        assert config.data_id == bench.data_id == message.dbc.attributes["E2E_DataID"].value
        assert 8 * config.offset == bench.offset == 48 and config.max_delta_counter == bench.max_delta_counter
        assert (config.window_size, config.min_ok["INIT"], config.max_error["INIT"], config.min_ok["VALID"],
                config.max_error["VALID"], config.min_ok["INVALID"], config.max_error["INVALID"]) == (
                bench.sm.window_size, bench.sm.min_ok_init, bench.sm.max_error_init, bench.sm.min_ok_valid,
                bench.sm.max_error_valid, bench.sm.min_ok_invalid, bench.sm.max_error_invalid)
    tx = VCU.Transmitter(db)
    seen: dict[int, list[int]] = {}
    for _ in range(40):                                   # 40 tasks: every counter wraps (14 -> 0) at least once
        for frame in tx.wheel_frames(VCU.Outputs()) + tx.state_frames(VCU.Outputs()):
            tx.sent(frame)
            data = bytearray(frame.data)
            assert p11.e2e_p11_check(data, frame.arbitration_id, offset=6)   # E2E_DataID = the identifier here
            assert protection(db.get_message_by_frame_id(frame.arbitration_id), definitions).counter_if_intact(
                frame.data) is not None
            seen.setdefault(frame.arbitration_id, []).append(frame.data[7] & 0x0F)
    assert len(seen) == 6 and all(set(c) == set(range(15)) for c in seen.values())


def test_example_receiver_accepts_the_bench_and_rejects_what_autosar_rejects() -> None:
    """Frames the bench protects (counter wraps included) are applied from the second one on (NODATA -> INIT ->
    VALID); a wrong CRC, a frame of another identifier, a repeated counter and a jump beyond MaxDeltaCounter get
    their AUTOSAR status, and none is applied."""
    from bench.e2e import protection

    db = _chassis()
    message = db.get_message_by_name("DRV_MotionRequest")
    payload = bytes(message.encode({s.name: 0 for s in message.signals}, scaling=False))

    def frame(counter: int, data_id_of: str = "DRV_MotionRequest") -> bytes:
        data = bytearray(payload)
        protection(db.get_message_by_name(data_id_of), db.dbc.attribute_definitions).protect(data, counter)
        return bytes(data)

    rx = VCU.E2EReceiver(db, message)
    assert rx.state == "NODATA" and rx.timed_out(0.0)
    applied = [rx.on_frame(frame(c % 15), c * 0.02) for c in range(45)]   # a first 0 is in sequence
    assert applied == [False] + [True] * 44 and rx.statuses == {"OK": 45} and rx.state == "VALID"
    t = 1.0
    cases = [
        (lambda d: d[:6] + bytes([d[6] ^ 0x01]) + d[7:], "ERROR"),           # CRC wrong
        (lambda d: d, "OKSOMELOST"),                                         # the frame after it: 2 steps on
        (lambda d: d, "REPEATED"),
        (lambda d: d, "OK"),
    ]
    counter = 44 % 15
    for corrupt, status in cases:
        if status != "REPEATED":
            counter = (counter + 1) % 15
        before = rx.statuses[status]
        assert rx.on_frame(corrupt(frame(counter)), t) is False, status
        assert rx.statuses[status] == before + 1, (status, rx.statuses)
        t += 0.02
    assert rx.state == "INVALID"
    assert rx.on_frame(frame((counter + 1) % 15, "DRV_Steering"), t) is False and rx.statuses["ERROR"] == 2
    assert rx.on_frame(frame((counter + 4) % 15), t) is False and rx.statuses["WRONGSEQUENCE"] == 1
    assert rx.on_frame(frame((counter + 5) % 15), t) is False                  # one OK in the window: INVALID
    assert rx.on_frame(frame((counter + 6) % 15), t) is True and rx.state == "VALID"


def test_example_runs_on_the_benchs_frames() -> None:
    """A few tasks of the example on frames the bench protects: the second frame of each input is applied (NODATA
    -> INIT -> VALID), the VCU reports no fault and sends its six messages, each passing the bench's check."""
    import can

    from bench.e2e import protection

    db = _chassis()
    vcu, tx = VCU.Vcu(db, 0.0), VCU.Transmitter(db)
    faults = []
    for task in range(12):
        t = task * 0.010
        for name in VCU.INPUTS:
            message = db.get_message_by_name(name)
            data = bytearray(message.encode({s.name: 0 for s in message.signals}, scaling=False))
            protection(message, db.dbc.attribute_definitions).protect(data, task)
            vcu.receive(can.Message(arbitration_id=message.frame_id, data=bytes(data), is_extended_id=False), t)
        faults.append(vcu.evaluate(t).fault)
        for frame in VCU.frames_of_task(tx, vcu.out, task):
            tx.sent(frame)
            assert protection(db.get_message_by_frame_id(frame.arbitration_id),
                              db.dbc.attribute_definitions).counter_if_intact(frame.data) is not None
    assert faults[0] == VCU.REQUEST_TIMEOUT and faults[-1] == VCU.OK == 0, faults
    assert all(rx.accepted == 11 and rx.rejected == 1 and rx.state == "VALID" for rx in vcu.rx.values())


#: A database of its own with a message per profile (P01 ALT, P02, P05 at byte 2, P11 NIBBLE), one without
#: protection, and state machine parameters other than the contract's (WindowSize 3).
PROFILES_DBC = f"""\
VERSION ""

NS_ :
    BA_DEF_
    BA_DEF_DEF_

BS_:

BU_: A B

BO_ 1 M01: 8 A
 SG_ Crc : 0|8@1+ (1,0) [0|255] "" B
 SG_ Cnt : 8|4@1+ (1,0) [0|14] "" B
 SG_ Val : 16|16@1+ (1,0) [0|65535] "" B

BO_ 2 M02: 8 A
 SG_ Crc : 0|8@1+ (1,0) [0|255] "" B
 SG_ Cnt : 8|4@1+ (1,0) [0|15] "" B
 SG_ Val : 16|16@1+ (1,0) [0|65535] "" B

BO_ 3 M05: 8 A
 SG_ Val : 0|16@1+ (1,0) [0|65535] "" B
 SG_ Crc : 16|16@1+ (1,0) [0|65535] "" B
 SG_ Cnt : 32|8@1+ (1,0) [0|255] "" B

BO_ 4 M11: 8 A
 SG_ Val : 0|16@1+ (1,0) [0|65535] "" B
 SG_ Crc : 48|8@1+ (1,0) [0|255] "" B
 SG_ Cnt : 56|4@1+ (1,0) [0|14] "" B

BO_ 5 Plain: 8 A
 SG_ Val : 0|16@1+ (1,0) [0|65535] "" B

BA_DEF_ BO_  "GenMsgCycleTime" INT 0 65535;
{E2E_ATTRIBUTE_DEFINITIONS}
BA_DEF_DEF_  "GenMsgCycleTime" 10;
BA_DEF_DEF_  "E2E_Profile" "None";
BA_DEF_DEF_  "E2E_DataID" 0;
BA_DEF_DEF_  "E2E_DataIDMode" "BOTH";
BA_DEF_DEF_  "E2E_DataIDList" "";
BA_DEF_DEF_  "E2E_Offset" 0;
BA_DEF_DEF_  "E2E_DataLength" 64;
BA_DEF_DEF_  "E2E_MaxDeltaCounter" 1;
BA_DEF_DEF_  "E2E_WindowSize" 3;
BA_DEF_DEF_  "E2E_MinOkStateInit" 2;
BA_DEF_DEF_  "E2E_MaxErrorStateInit" 1;
BA_DEF_DEF_  "E2E_MinOkStateValid" 2;
BA_DEF_DEF_  "E2E_MaxErrorStateValid" 1;
BA_DEF_DEF_  "E2E_MinOkStateInvalid" 3;
BA_DEF_DEF_  "E2E_MaxErrorStateInvalid" 0;
BA_ "E2E_Profile" BO_ 1 1;
BA_ "E2E_DataID" BO_ 1 291;
BA_ "E2E_DataIDMode" BO_ 1 1;
BA_ "E2E_Profile" BO_ 2 2;
BA_ "E2E_DataIDList" BO_ 2 "10 11 12 13 14 15 16 17 18 19 1A 1B 1C 1D 1E 1F";
BA_ "E2E_Profile" BO_ 3 3;
BA_ "E2E_DataID" BO_ 3 4660;
BA_ "E2E_Offset" BO_ 3 16;
BA_ "E2E_MaxDeltaCounter" BO_ 3 3;
BA_ "E2E_Profile" BO_ 4 4;
BA_ "E2E_DataID" BO_ 4 2564;
BA_ "E2E_DataIDMode" BO_ 4 3;
BA_ "E2E_Offset" BO_ 4 48;

"""


def _profiles_db(text: str = PROFILES_DBC):
    import cantools

    return cantools.database.load_string(text, database_format="dbc")


def test_example_speaks_every_profile_of_a_database_of_its_own() -> None:
    """P01, P02, P05 and P11 from the DBC's attributes alone: 600 frames of each (every counter value, the wraps)
    pass the bench's check with the same database; the unprotected message gets no header and is judged on its
    length and ranges only; a signal on the library's header is refused at start-up, naming message and signal."""

    from bench.e2e import protection

    db = _profiles_db()
    for message in db.messages:
        config, bench = VCU.e2e_config(db, message), protection(message, db.dbc.attribute_definitions)
        sender, receiver = VCU.E2ESender(db, message), VCU.E2EReceiver(db, message)
        if bench is None:
            assert config is None and message.name == "Plain"
            frame = sender.frame({"Val": 7})
            assert frame.data == bytes([7, 0, 0, 0, 0, 0, 0, 0]) and receiver.on_frame(frame.data, 0.0)
            assert not receiver.on_frame(frame.data[:7], 0.0)
            continue
        assert config is not None and config.profile == bench.profile == message.name.replace("M", "P")
        counters = []
        for i in range(600):
            frame = sender.frame({"Val": i})
            sender.sent(frame)
            assert bench.counter_if_intact(frame.data) is not None, (message.name, i)
            applied = receiver.on_frame(frame.data, i * 0.01)
            assert applied == (i >= 2), (message.name, i, receiver.statuses)   # MinOkStateInit 2: the third frame
            counters.append(bench.counter_of(frame.data))
        assert counters[:2] == [0, 1] and sorted(set(counters)) == list(range(bench.counter_modulo)), message.name
        assert receiver.values is not None and receiver.values["Val"] == 599
    broken = PROFILES_DBC.replace(' SG_ Cnt : 56|4@1+ (1,0) [0|14] "" B', ' SG_ Cnt : 56|4@1+ (1,0) [0|14] "" B\n'
                                  ' SG_ Mode : 60|4@1+ (1,0) [0|15] "" B')
    broken_db = _profiles_db(broken)   # NIBBLE: the library writes DataID bits 8-11 where Mode lies
    with pytest.raises(VCU.E2EConfigError, match="M11: signal Mode .* lies on the P11 header"):
        VCU.E2EReceiver(broken_db, broken_db.get_message_by_name("M11"))


def _operations():
    return st.lists(st.sampled_from(["next", "next", "next", "repeat", "skip2", "skip3", "back", "crc", "other_id",
                                     "second_sender"]), max_size=80)


@settings(max_examples=300, deadline=None)
@given(ops=_operations(), first=st.integers(0, 255), which=st.sampled_from(
    ["chassis:DRV_MotionRequest", "own:M01", "own:M02", "own:M05", "own:M11"]))
def test_example_receiver_judges_every_frame_as_the_bench_does(ops: list[str], first: int, which: str) -> None:
    """The example's receiver, written from the documents, against the bench's (bench/e2e/receiver.py) on the same
    frames: the same status, state and verdict for every frame of any pattern (docs/spec/e2e.md), for the
    contract's parameters and for another database's profiles and window."""
    from bench.e2e import Receiver, protection

    source, name = which.split(":")
    db = _chassis() if source == "chassis" else _profiles_db()
    message = db.get_message_by_name(name)
    prot = protection(message, db.dbc.attribute_definitions)
    other_message = next(m for m in db.messages if m.name != name and protection(m, db.dbc.attribute_definitions))
    other = protection(other_message, db.dbc.attribute_definitions)
    modulo = prot.counter_modulo
    payload = bytes(message.encode({s.name: 0 for s in message.signals}, scaling=False))
    example, bench = VCU.E2EReceiver(db, message), Receiver(modulo, prot.max_delta_counter, prot.sm)
    counter = first % modulo
    second = (counter + modulo // 2) % modulo
    for i, op in enumerate(["next", *ops]):
        data, sent = bytearray(payload), counter
        if op == "second_sender":
            sent, second = second, (second + 1) % modulo
        elif op != "repeat":
            step = {"skip2": 2, "skip3": 3, "back": -2}.get(op, 1)
            counter = sent = (counter + step) % modulo
        (other if op == "other_id" else prot).protect(data, sent)
        if op == "crc":
            data[prot.crc.first_byte] ^= 0x80
        statuses_before = example.statuses.copy()
        applied = example.on_frame(bytes(data), i * 0.02)
        status, bench_applied = bench.receive(prot.counter_if_intact(bytes(data)))
        assert (example.statuses - statuses_before) == {status.value: 1}, (i, op)
        assert (example.state, applied) == (bench.state.value, bench_applied), (i, op, status)


def test_example_reads_exactly_its_inputs_in_one_drain() -> None:
    """The example's acceptance filters name exactly the messages its receivers judge, each one the DBC says the
    VCU receives (in the kernel on socketcan). Where python-can would filter in software (here the virtual
    interface) the bus stays unfiltered: there recv(timeout=0) returns None at the first frame it drops, and one
    drain must still take in every frame that arrived."""
    import can
    import cantools

    db = cantools.database.load_file(str(ROOT / "dbc" / "chassis.dbc"))
    bench_db = cantools.database.load_file(str(ROOT / "dbc" / "bench.dbc"))
    vcu = VCU.Vcu(db, 0.0)
    judged = {receiver.message.frame_id for receiver in vcu.rx.values()}
    filters = VCU.receive_filters(db)
    assert {f["can_id"] for f in filters} == judged and len(filters) == len(judged) == 7
    assert all(f["can_mask"] == 0x7FF and f["extended"] is False for f in filters)
    assert all("VCU" in db.get_message_by_frame_id(frame_id).receivers for frame_id in judged)
    others = [m.frame_id for m in db.messages if m.frame_id not in judged] + [m.frame_id for m in bench_db.messages]
    channel = f"vcu-drain-{random.randint(0, 1 << 30)}"
    args = VCU.parse_args(["--interface", "virtual", "--channel", channel])
    with VCU.open_bus(args, filters) as vcu_bus, can.Bus(interface="virtual", channel=channel) as bench_bus:
        assert not vcu_bus.filters                          # software filtering: left off
        for frame_id in others[:5] + sorted(judged) + others[5:]:
            bench_bus.send(can.Message(arbitration_id=frame_id, data=bytes(8), is_extended_id=False))
        VCU.drain(vcu_bus, vcu, time.time())
        assert vcu_bus.recv(timeout=0.0) is None            # one drain took every frame
    assert all(rx.accepted + rx.rejected == 1 for rx in vcu.rx.values())   # each input judged once


def test_example_counter_advances_per_transmission() -> None:
    """COM-E2E-01: +1 per transmission (the library's increment), never a skipped value: a frame the driver refused
    (a full transmit queue) leaves its counter value to the next frame of that message."""
    import cantools

    db = cantools.database.load_file(str(ROOT / "dbc" / "chassis.dbc"))
    tx = VCU.Transmitter(db)
    refused = {3, 4, 9, 16, 17, 18}                       # tasks whose frames the driver refused
    on_bus: dict[int, list[int]] = {}
    for task in range(40):
        for frame in tx.wheel_frames(VCU.Outputs()) + tx.state_frames(VCU.Outputs()):
            if task not in refused:
                tx.sent(frame)
                on_bus.setdefault(frame.arbitration_id, []).append(frame.data[7] & 0x0F)   # P11, E2E_Offset 48
    assert len(on_bus) == 6
    for counters in on_bus.values():                      # P11 counts 0 ... 14
        assert counters[0] == 0 and max(counters) == 14
        assert len(counters) == 34 and all((b - a) % 15 == 1 for a, b in zip(counters, counters[1:]))
