"""Multiplexed messages: the restbus sends each multiplexer value's frame in turn, the monitor decodes and judges
the signals each frame carries and keeps the others' last values, and a case reads and sets them by name.

Every multiplexed message of cantools' test databases (the corpus beside the repository), cascaded ones included: the
restbus's frames are decoded by cantools itself, which must find each variant's multiplexer values and signals.
"""

from __future__ import annotations

import math
from pathlib import Path

import cantools
import pytest

from bench.checks.monitor import Monitor
from bench.database.codec import Codebook, load_dbc
from bench.errors import SignalError
from bench.sim.restbus import Restbus
from tests.repo import ROOT

CORPUS = ROOT.parent / "shared" / "corpus" / "dbc"
DBC = """VERSION ""
NS_ :
BS_:
BU_: SENDER RECEIVER
BO_ 512 Shared: 8 SENDER
 SG_ Page M : 0|8@1+ (1,0) [0|255] "" RECEIVER
 SG_ Speed m1 : 8|16@1+ (0.1,0) [0|300] "km/h" RECEIVER
 SG_ Torque m2 : 8|16@1- (0.5,0) [-1000|1000] "Nm" RECEIVER
 SG_ Both m3 : 8|8@1+ (1,0) [0|200] "" RECEIVER
 SG_ Always : 56|8@1+ (1,0) [0|255] "" RECEIVER
BA_DEF_ BO_ "GenMsgCycleTime" INT 0 10000;
BA_DEF_DEF_ "GenMsgCycleTime" 0;
BA_ "GenMsgCycleTime" BO_ 512 10;
"""


def _multiplexed(path: Path) -> list[tuple[str, cantools.database.can.Database]]:
    try:
        db = load_dbc(path)
    except Exception:   # noqa: BLE001 - files cantools cannot load are another test's business
        return []
    return [(m.name, db) for m in db.messages if m.is_multiplexed()]


CASES = [(path.name, name, db) for path in sorted(CORPUS.glob("*.dbc")) if CORPUS.is_dir()
         for name, db in _multiplexed(path)]


@pytest.mark.skipif(not CASES, reason=f"no DBC corpus at {CORPUS}")
@pytest.mark.parametrize(("file", "name", "db"), CASES, ids=[f"{f}:{n}" for f, n, _ in CASES])
def test_each_variant_goes_out_as_cantools_decodes_it(file: str, name: str, db: cantools.database.Database) -> None:
    codebook = Codebook([(file, db)])
    codec = codebook[name]
    message = db.get_message_by_name(name)
    restbus = Restbus(codebook, set(codec.senders) or {"x"})
    slot = restbus.slots.get(name)
    if slot is None:   # no sender node or no cycle time: build the frames by hand from a slot of its own
        from bench.sim.restbus import _Slot
        slot = _Slot(codec, 0)
    seen = []
    monitor = Monitor(codebook)
    for i, (chosen, names) in enumerate(codec.variants):
        data = restbus.build(slot)
        decoded = message.decode(data, decode_choices=False)
        assert set(decoded) == set(names), (chosen, sorted(decoded))               # cantools: this variant's signals
        assert {k: decoded[k] for k in chosen} == chosen                           # with its multiplexer values
        seen.append(tuple(sorted(chosen.items())))
        monitor.on_frame(i * 0.01, codec.frame_id, data, "rx")
    assert len(set(seen)) == len(codec.variants)                                 # each variant once per round
    assert monitor.invalid_log == []
    assert set(monitor.state(name).latest or {}) == {s.name for s in message.signals}   # every signal known now


@pytest.fixture(scope="module")
def codebook() -> Codebook:
    return Codebook([("mux.dbc", cantools.database.load_string(DBC, "dbc"))])


def test_a_case_reads_each_signal_and_its_history(codebook: Codebook) -> None:
    restbus = Restbus(codebook, {"SENDER"})
    restbus.set("Shared", Speed=123.4, Torque=-250.0, Both=7, Always=9)
    monitor = Monitor(codebook, keep_history=True)
    codec = codebook["Shared"]
    slot = restbus.slots["Shared"]
    for i in range(6):                                   # two rounds of the three pages
        monitor.on_frame(i * 0.01, codec.frame_id, restbus.build(slot), "rx")
    latest = monitor.latest("Shared", 0.05)
    assert latest is not None
    assert (latest["Speed"], latest["Torque"], latest["Both"], latest["Always"]) == \
        (pytest.approx(123.4), -250.0, 7, 9)
    t, v = monitor.history("Shared", "Torque")           # the frames of page 2 only
    assert t == pytest.approx([0.01, 0.04]) and v == [-250.0, -250.0]
    t, _ = monitor.history("Shared", "Always")            # in every frame
    assert len(t) == 6 and not any(math.isnan(x) for x in _)


def test_a_case_pins_a_multiplexer_value_and_a_wrong_one_is_refused(codebook: Codebook) -> None:
    restbus = Restbus(codebook, {"SENDER"})
    slot = restbus.slots["Shared"]
    message = codebook["Shared"].message
    restbus.set("Shared", Page=2)
    assert {message.decode(restbus.build(slot))["Page"] for _ in range(5)} == {2}
    with pytest.raises(SignalError, match=r"Shared.Page: 4 is no multiplexer value of the database "
                                          r"\(its values: 1.0, 2.0, 3.0\)"):
        restbus.set("Shared", Page=4)
    restbus.reset_values("Shared")
    assert {message.decode(restbus.build(slot))["Page"] for _ in range(3)} == {1, 2, 3}
