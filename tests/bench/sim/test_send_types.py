"""Each send type frame by frame: when the restbus sends a message against its database's attributes, and how the
monitor judges a correct and a wrong sender of it (bench.database.sendtype).

The database below declares one message per send type with Vector's attributes; the expected ticks are worked out
here from those attributes by hand (the comments say how), not from the restbus.
"""

from __future__ import annotations

from collections.abc import Callable

import cantools
import pytest

from bench.checks.monitor import Monitor
from bench.database.codec import Codebook
from bench.database.sendtype import CYCLIC, CYCLIC_AND_ON_CHANGE, IF_ACTIVE, ON_CHANGE, ON_WRITE
from bench.sim.restbus import Restbus

DBC = """VERSION ""
NS_ :
BS_:
BU_: SENDER RECEIVER
BO_ 256 Cyc: 8 SENDER
 SG_ Value : 0|8@1+ (1,0) [0|255] "" RECEIVER
BO_ 257 Chg: 8 SENDER
 SG_ Value : 0|8@1+ (1,0) [0|255] "" RECEIVER
BO_ 258 Wr: 8 SENDER
 SG_ Value : 0|8@1+ (1,0) [0|255] "" RECEIVER
BO_ 259 Act: 8 SENDER
 SG_ Value : 0|8@1+ (1,0) [0|255] "" RECEIVER
 SG_ Mode : 8|8@1+ (1,0) [0|255] "" RECEIVER
BO_ 260 Both: 8 SENDER
 SG_ Value : 0|8@1+ (1,0) [0|255] "" RECEIVER
BA_DEF_ BO_ "GenMsgCycleTime" INT 0 10000;
BA_DEF_ BO_ "GenMsgSendType" ENUM "Cyclic","Spontan","OnWrite","IfActive","CyclicAndSpontan";
BA_DEF_ BO_ "GenMsgDelayTime" INT 0 10000;
BA_DEF_ BO_ "GenMsgNrOfRepetition" INT 0 100;
BA_DEF_ BO_ "GenMsgCycleTimeFast" INT 0 10000;
BA_DEF_ BO_ "GenMsgStartDelayTime" INT 0 10000;
BA_DEF_ SG_ "GenSigInactiveValue" INT 0 255;
BA_DEF_ SG_ "GenSigStartValue" INT 0 255;
BA_DEF_DEF_ "GenMsgCycleTime" 0;
BA_DEF_DEF_ "GenMsgSendType" "Cyclic";
BA_DEF_DEF_ "GenMsgDelayTime" 0;
BA_DEF_DEF_ "GenMsgNrOfRepetition" 0;
BA_DEF_DEF_ "GenMsgCycleTimeFast" 0;
BA_DEF_DEF_ "GenMsgStartDelayTime" 0;
BA_DEF_DEF_ "GenSigInactiveValue" 0;
BA_DEF_DEF_ "GenSigStartValue" 0;
BA_ "GenMsgCycleTime" BO_ 256 10;
BA_ "GenMsgStartDelayTime" BO_ 256 30;
BA_ "GenMsgSendType" BO_ 257 1;
BA_ "GenMsgDelayTime" BO_ 257 20;
BA_ "GenMsgNrOfRepetition" BO_ 257 2;
BA_ "GenMsgCycleTimeFast" BO_ 257 5;
BA_ "GenMsgSendType" BO_ 258 2;
BA_ "GenMsgDelayTime" BO_ 258 10;
BA_ "GenMsgSendType" BO_ 259 3;
BA_ "GenMsgCycleTime" BO_ 259 10;
BA_ "GenSigInactiveValue" SG_ 259 Mode 7;
BA_ "GenSigStartValue" SG_ 259 Mode 7;
BA_ "GenMsgSendType" BO_ 260 4;
BA_ "GenMsgCycleTime" BO_ 260 50;
BA_ "GenMsgDelayTime" BO_ 260 10;
"""
#: What the restbus is told, by tick (1 ms ticks): (tick, message, values)
SCRIPT = [(100, "Chg", {"Value": 1}), (112, "Chg", {"Value": 2}), (150, "Chg", {"Value": 2}),
          (200, "Wr", {"Value": 5}), (203, "Wr", {"Value": 5}),
          (300, "Act", {"Value": 3, "Mode": 7}), (330, "Act", {"Value": 0}),
          (115, "Both", {"Value": 7}), (118, "Both", {"Value": 8})]
TICKS = 400
EXPECTED = {
    # cyclic, 10 ms, its first frame after GenMsgStartDelayTime 30 ms
    "Cyc": list(range(30, TICKS, 10)),
    # on change: the frame and GenMsgNrOfRepetition 2 repeats GenMsgCycleTimeFast 5 ms apart (100, 105, 110); the
    # change at 112 waits for GenMsgDelayTime 20 ms after the last frame (130, 135, 140); 150 changes nothing
    "Chg": [100, 105, 110, 130, 135, 140],
    # on write: every write, GenMsgDelayTime 10 ms apart: 200, then 210 for the write at 203 (same value)
    "Wr": [200, 210],
    # if active: silent while every signal has its inactive value (Value 0, Mode 7); active from 300, on its cycle
    # ticks (identifier 259 mod 10 = 9: 309, 319, 329), the inactive frame at 339 once, then silent
    "Act": [309, 319, 329, 339],
    # cyclic 50 ms (identifier 260 mod 50 = 10: 10, 60, 110, ...) and on change: 115 at once, 118's change after
    # GenMsgDelayTime 10 ms (125)
    "Both": sorted([*range(10, TICKS, 50), 115, 125]),
}


@pytest.fixture(scope="module")
def codebook() -> Codebook:
    return Codebook([("sendtypes.dbc", cantools.database.load_string(DBC, "dbc"))])


def _run(codebook: Codebook) -> list[tuple[int, str, bytes]]:
    restbus = Restbus(codebook, {"SENDER"})
    restbus.set_tick(0.001)
    by_id = {codec.send_id: codec.name for codec in codebook.by_id.values()}
    sent = []
    for tick in range(TICKS):
        for at, message, values in SCRIPT:
            if at == tick:
                restbus.set(message, **values)
        sent += [(tick, by_id[frame_id], data) for frame_id, data in restbus.due(tick)]
    return sent


def test_the_database_declares_one_message_per_send_type(codebook: Codebook) -> None:
    assert {name: codebook[name].sending.kind for name in EXPECTED} == {
        "Cyc": CYCLIC, "Chg": ON_CHANGE, "Wr": ON_WRITE, "Act": IF_ACTIVE, "Both": CYCLIC_AND_ON_CHANGE}


def test_the_restbus_sends_each_message_by_its_send_type(codebook: Codebook) -> None:
    sent = _run(codebook)
    assert {name: [tick for tick, message, _ in sent if message == name] for name in EXPECTED} == EXPECTED


Frames = list[tuple[float, str, bytes]]


def _judge(codebook: Codebook, frames: Frames, until: float) -> Monitor:
    monitor = Monitor(codebook)
    for t, name, data in sorted(frames, key=lambda f: f[0]):
        monitor.on_frame(t, codebook[name].frame_id, data, "rx")
    monitor.check_timeouts(until)
    return monitor


def _verdicts(monitor: Monitor, name: str) -> list[str]:
    return [f.reason for f in monitor.invalid_log if f.message == name] + \
        [f"timeout at {t:.3f}" for t in monitor.state(name).timeouts]


def test_the_monitor_accepts_the_restbus_as_a_correct_sender(codebook: Codebook) -> None:
    monitor = _judge(codebook, [(tick / 1000, name, data) for tick, name, data in _run(codebook)], TICKS / 1000)
    assert {name: _verdicts(monitor, name) for name in EXPECTED} == {name: [] for name in EXPECTED}


def _frame(codebook: Codebook, name: str, **values: float) -> bytes:
    codec = codebook[name]
    return bytes(codec.encode({**codec.start_values(), **values}))


WRONG: dict[str, tuple[Callable[[Codebook], Frames], str]] = {
    # a cyclic message that stops: its receivers time out 3 cycles after its last frame
    "Cyc": (lambda cb: [(t / 100, "Cyc", _frame(cb, "Cyc")) for t in range(5)], "timeout at 0.070"),
    # an on-change sender that sends every 10 ms without a change: beyond its 2 repetitions
    "Chg": (lambda cb: [(t / 100, "Chg", _frame(cb, "Chg", Value=4)) for t in range(5)], "without a change"),
    # an on-change sender faster than its minimum gap of 20 ms
    "Chg ": (lambda cb: [(0.0, "Chg", _frame(cb, "Chg", Value=1)), (0.002, "Chg", _frame(cb, "Chg", Value=2))],
             "2.0 ms after its previous frame, its minimum gap is 20 ms"),
    # an on-write sender faster than its minimum gap of 10 ms
    "Wr": (lambda cb: [(0.0, "Wr", _frame(cb, "Wr")), (0.004, "Wr", _frame(cb, "Wr"))], "minimum gap is 10 ms"),
    # an if-active sender that goes silent while active: late (its inactive frame would have ended the cycle)
    "Act": (lambda cb: [(t / 100, "Act", _frame(cb, "Act", Value=3, Mode=7)) for t in range(3)], "timeout at 0.050"),
    # a cyclic-and-on-change sender that stops its cycle
    "Both": (lambda cb: [(0.0, "Both", _frame(cb, "Both"))], "timeout at 0.150"),
}


@pytest.mark.parametrize("case", WRONG, ids=lambda c: c.strip() + (" gap" if c.endswith(" ") else ""))
def test_the_monitor_flags_a_wrong_sender(codebook: Codebook, case: str) -> None:
    frames, verdict = WRONG[case]
    monitor = _judge(codebook, frames(codebook), 1.0)
    found = _verdicts(monitor, case.strip())
    assert found and verdict in found[0], found


def test_silence_is_no_fault_of_an_event_or_an_inactive_message(codebook: Codebook) -> None:
    frames = [(0.0, "Chg", _frame(codebook, "Chg", Value=1)), (0.0, "Wr", _frame(codebook, "Wr")),
              (0.0, "Act", _frame(codebook, "Act", Value=0, Mode=7))]      # the inactive frame, then silence
    monitor = _judge(codebook, frames, 10.0)
    assert {name: _verdicts(monitor, name) for name in ("Chg", "Wr", "Act")} == {"Chg": [], "Wr": [], "Act": []}
    assert monitor.latest("Chg", 10.0) == {"Value": 1}      # its last value stands: it is not timed out
