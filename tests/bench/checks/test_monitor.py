"""The monitor: every contract check detects its fault, and arbitrary frames never make it raise."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from bench import canid, e2e
from bench.checks.monitor import Monitor
from bench.database.codec import Codebook
from bench.sim.restbus import Restbus


def _frames(codebook: Codebook, message: str, count: int, **values: float) -> list[bytes]:
    restbus = Restbus(codebook, codebook[message].senders)
    if values:
        restbus.set(message, **values)
    slot = restbus.slots[message]
    return [restbus.build(slot) for _ in range(count)]


def test_valid_sequence_is_applied(codebook: Codebook) -> None:
    """A sender in sequence from power-up: every frame but the first is applied (the first only moves the E2E
    state machine from NODATA to INIT, docs/spec/e2e.md); the first is no invalid frame (nothing is wrong
    with it), only not applied."""
    monitor = Monitor(codebook, keep_history=True)
    frame_id = codebook["VCU_WheelCmd_FL"].frame_id
    verdicts = [monitor.on_frame(i * 0.01, frame_id, data, "rx")
                for i, data in enumerate(_frames(codebook, "VCU_WheelCmd_FL", 20, SteerAngleCmd=12.34))]
    assert verdicts == [False] + [True] * 19                        # applied: all but the first, which is valid
    assert monitor.state("VCU_WheelCmd_FL").starting == 1           # (logged as such) and held back
    assert monitor.latest("VCU_WheelCmd_FL", 0.19)["SteerAngleCmd"] == 12.34
    t, v = monitor.history("VCU_WheelCmd_FL", "SteerAngleCmd")
    assert len(t) == 19 and v[-1] == 12.34
    assert monitor.invalid_frames == 0 and monitor.invalid_log == []
    state = monitor.state("VCU_WheelCmd_FL")
    assert state.e2e_status == {"OK": 20} and state.rx is not None and state.rx.state is e2e.SMState.VALID


def test_each_fault_is_detected_and_not_applied(codebook: Codebook) -> None:
    monitor = Monitor(codebook)
    frame_id = codebook["VCU_WheelCmd_FL"].frame_id
    good = _frames(codebook, "VCU_WheelCmd_FL", 6, SteerAngleCmd=5.0)        # counters 0 ... 5
    assert not monitor.on_frame(0.00, frame_id, good[0], "rx")       # NODATA -> INIT: valid, not applied
    assert monitor.latest("VCU_WheelCmd_FL", 0.0) is None
    assert monitor.on_frame(0.01, frame_id, good[1], "rx")           # INIT -> VALID
    bad_crc = bytearray(good[2])
    bad_crc[6] ^= 0x01                                                # the CRC (byte 6)
    assert not monitor.on_frame(0.02, frame_id, bytes(bad_crc), "rx")    # ERROR
    assert not monitor.on_frame(0.03, frame_id, good[5], "rx")       # counter 5 after 1 (the bad frame's
                                                                      # counter is not read): WRONGSEQUENCE
    assert not monitor.on_frame(0.04, frame_id, good[4][:7], "rx")   # short frame: ERROR, reason length
    state = monitor.state("VCU_WheelCmd_FL")
    assert state.invalid == {"checksum": 1, "counter": 1, "length": 1}
    assert state.e2e_status == {"OK": 2, "ERROR": 2, "WRONGSEQUENCE": 1}
    assert [r.reason for r in monitor.invalid_log] == [
        "E2E ERROR: CRC wrong, state INVALID", "E2E WRONGSEQUENCE: counter 5, expected 2, state INVALID",
        "length 7, DBC says 8"]
    # out of range: a raw angle of +200 deg (the DBC range is +-90) with a right counter and CRC, in VALID
    codec = codebook["VCU_WheelCmd_FL"]
    assert codec.protection is not None
    monitor2 = Monitor(codebook)
    assert not monitor2.on_frame(0.0, frame_id, good[0], "rx")
    data = codec.encode(dict(codec.start_values(), SteerAngleCmd=200.0))
    codec.protection.protect(data, 1)
    assert not monitor2.on_frame(0.01, frame_id, bytes(data), "rx")
    assert monitor2.state("VCU_WheelCmd_FL").invalid == {"range": 1}
    assert monitor2.state("VCU_WheelCmd_FL").rx.state is e2e.SMState.VALID   # a range error is no E2E status
    assert monitor2.latest("VCU_WheelCmd_FL", 0.01) is None


def test_timeout_after_three_cycles(codebook: Codebook) -> None:
    monitor = Monitor(codebook)
    frame_id = codebook["VCU_WheelCmd_FL"].frame_id
    first, second = _frames(codebook, "VCU_WheelCmd_FL", 2)
    monitor.on_frame(0.99, frame_id, first, "rx")
    assert monitor.timed_out("VCU_WheelCmd_FL", 0.99), "nothing applied yet"
    assert monitor.on_frame(1.0, frame_id, second, "rx")
    assert not monitor.timed_out("VCU_WheelCmd_FL", 1.0 + 0.030)
    assert monitor.timed_out("VCU_WheelCmd_FL", 1.0 + 0.0301)
    monitor.check_timeouts(1.031)
    assert monitor.state("VCU_WheelCmd_FL").timeouts == [1.03]


@settings(max_examples=400, deadline=None)
@given(identifier=st.integers(0, 0x1FFFFFFF), data=st.binary(max_size=64), extended=st.booleans(),
       error=st.booleans(), remote=st.booleans(), fd=st.booleans())
def test_arbitrary_frames_never_raise(codebook: Codebook, identifier: int, data: bytes, extended: bool,
                                      error: bool, remote: bool, fd: bool) -> None:
    monitor = Monitor(codebook, keep_history=True)
    frame_id = canid.of(identifier if extended else identifier & canid.SFF_MASK, extended, is_error=error,
                        is_remote=remote, is_fd=fd, bitrate_switch=fd)
    for t in (0.0, 0.01):
        monitor.on_frame(t, frame_id, data, "rx")
    monitor.check_timeouts(1.0)


@settings(max_examples=300, deadline=None)
@given(st.sampled_from(sorted(range(0x100, 0x170))), st.binary(min_size=8, max_size=8))
def test_random_payloads_on_contract_ids_never_raise(codebook: Codebook, frame_id: int, data: bytes) -> None:
    monitor = Monitor(codebook)
    monitor.on_frame(0.0, frame_id, data, "rx")


def test_long_runs_keep_memory_bounded_and_say_so(codebook: Codebook, monkeypatch) -> None:
    import bench.checks.monitor as monitor_module
    monkeypatch.setattr(monitor_module, "HISTORY_CAP", 50)
    monkeypatch.setattr(monitor_module, "INTERVALS_CAP", 50)
    monitor = Monitor(codebook, keep_history=True)
    frame_id = codebook["VCU_WheelCmd_FL"].frame_id
    for i, data in enumerate(_frames(codebook, "VCU_WheelCmd_FL", 500)):
        monitor.on_frame(i * 0.01, frame_id, data, "rx")
    state = monitor.state("VCU_WheelCmd_FL")
    assert len(state.history_t) <= 100 and len(state.intervals) <= 100
    assert state.history_dropped + len(state.history_t) == 499      # every frame but the first is applied
    assert state.intervals_dropped + len(state.intervals) == 499
    t, _ = monitor.history("VCU_WheelCmd_FL", "SteerAngleCmd", since=4.5)
    assert t[0] == 4.5
    import pytest

    from bench.errors import BenchError
    with pytest.raises(BenchError, match="only the last"):
        monitor.history("VCU_WheelCmd_FL", "SteerAngleCmd", since=0.0)


def test_the_sink_gets_each_frame_as_one_object_with_its_verdict(codebook: Codebook) -> None:
    """The sink (the run's log and timing) gets a CheckedFrame per frame: its fields by name, slotted (no per-frame
    dict); an unknown identifier and a short frame come rejected with their reason, a valid one with its values."""
    from bench.checks.monitor import CheckedFrame

    got: list[CheckedFrame] = []
    monitor = Monitor(codebook, sink=got.append)
    codec = codebook["VCU_WheelCmd_FL"]
    frames = _frames(codebook, "VCU_WheelCmd_FL", 2, SteerAngleCmd=12.34)
    monitor.on_frame(0.0, codec.frame_id, frames[0], "rx")
    monitor.on_frame(0.01, codec.frame_id, frames[1], "tx")
    monitor.on_frame(0.02, 0x7FE, b"\x01", "rx")                       # no message of the databases
    monitor.on_frame(0.03, codec.frame_id, frames[1][:2], "rx")        # shorter than the DBC says
    assert [(f.t, f.frame_id, f.direction, f.valid) for f in got] == [
        (0.0, codec.frame_id, "rx", True), (0.01, codec.frame_id, "tx", True), (0.02, 0x7FE, "rx", False),
        (0.03, codec.frame_id, "rx", False)]
    assert got[1].data == frames[1] and got[1].codec is codec and got[1].values is not None
    assert got[1].values["SteerAngleCmd"] == 12.34
    assert got[2].codec is None and got[2].values is None and got[2].reason == "unknown identifier"
    assert got[3].values is None and got[3].reason.startswith("length 2")
    assert not hasattr(got[0], "__dict__")
