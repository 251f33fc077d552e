"""The E2E receiver (docs/spec/e2e.md "Receiver"): every counter pattern of the document gets its verdict.

Expected verdicts come from the document's rules, written here once more as a small model
(`accepted_by_rules`, from the document's sentence "In words"), never from bench.e2e: a frame is accepted
when it is intact (length and checksum) and either starts a sequence (the first intact frame since the
start or since a reception gap of more than 3 cycles), or carries the counter after the previous frame's (a
frame that was not intact counts with the counter it should have had) while no repeated or wrong counter
came since the last accepted frame, or is the second of two such frames in a row after one. Frames are
DRV_MotionRequest (20 ms cycle), built with tests/reference.py's checksum; byte 0 carries the frame's
index (PivotX = 0.02 m x index) so that the applied values show which frame was applied.
"""

from __future__ import annotations

from dataclasses import dataclass

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bench.codec import Codebook
from bench.monitor import Monitor
from tests.reference import protected

MESSAGE = "DRV_MotionRequest"
FRAME_ID = 0x102
CYCLE_MS = 20
GAP_MS = 3 * CYCLE_MS       # a reception gap longer than this resynchronises (docs/spec/e2e.md)


@dataclass(frozen=True)
class Frame:
    t_ms: int
    counter: int
    intact: bool = True      # False: wrong checksum


def _payload(index: int) -> bytes:
    return bytes([index & 0x7F, 0, 0, 0, 0, 0, 0, 0])


def _wire(index: int, frame: Frame) -> bytes:
    data = bytearray(protected(FRAME_ID, _payload(index), frame.counter))
    if not frame.intact:
        data[7] ^= 0x5A
    return bytes(data)


def accepted_by_rules(frames: list[Frame]) -> list[bool]:
    """The document's verdicts, from its rules (not from the code): see the module docstring."""
    verdicts: list[bool] = []
    last_t: int | None = None
    previous: int | None = None     # counter of the previous frame since the last resync (not intact: + 1)
    clean = False                   # no repeated or wrong counter since the last accepted frame
    in_a_row = 0                    # in-sequence frames in a row since the last repeated or wrong counter
    for frame in frames:
        if last_t is not None and frame.t_ms - last_t > GAP_MS:
            previous, clean, in_a_row = None, False, 0
        last_t = frame.t_ms
        if not frame.intact:
            verdicts.append(False)
            previous = None if previous is None else (previous + 1) % 16
            in_a_row = 0
            continue
        if previous is None:
            accepted = True
        elif frame.counter == (previous + 1) % 16:
            in_a_row += 1
            accepted = clean or in_a_row >= 2
        else:
            accepted, clean, in_a_row = False, False, 0
        clean = clean or accepted
        verdicts.append(accepted)
        previous = frame.counter
    return verdicts


def _feed(codebook: Codebook, frames: list[Frame]) -> tuple[Monitor, list[bool]]:
    monitor = Monitor(codebook, keep_history=True)
    verdicts = [monitor.on_frame(f.t_ms / 1000.0, FRAME_ID, _wire(i, f), "rx") for i, f in enumerate(frames)]
    return monitor, verdicts


def _steady(counters: list[int], start_ms: int = 0) -> list[Frame]:
    return [Frame(start_ms + CYCLE_MS * i, c) for i, c in enumerate(counters)]


def _run(first: int, count: int) -> list[int]:
    return [(first + i) % 16 for i in range(count)]


def _applied_index(monitor: Monitor, t_ms: int) -> int:
    latest = monitor.state(MESSAGE).latest
    assert latest is not None
    return round(latest["PivotX"] / 0.02)


# -- the model agrees with the document's table ---------------------------------------------------------------
def test_model_reads_the_documents_examples() -> None:
    """docs/spec/e2e.md "Counter patterns": the verdict column, row by row (x = rejected, a = accepted)."""
    # skip 1: 4 5 | 7 8 9
    assert accepted_by_rules(_steady([4, 5, 7, 8, 9])) == [True, True, False, False, True]
    # stale: 12 13 | 9 14 15 0
    assert accepted_by_rules(_steady([12, 13, 9, 14, 15, 0])) == [True, True, False, False, False, True]


# -- the patterns ---------------------------------------------------------------------------------------------
def test_frozen_counter_for_one_second_accepts_nothing(codebook: Codebook) -> None:
    """Acceptance 3 of issue 14: 50 frames (1 s at 20 ms) with the counter frozen at its last value: 0 accepted.
    The frames never stop, so there is no resynchronisation: the consumer sees the message timed out 3 cycles
    after the last valid frame, once, and it stays timed out for the whole second."""
    good = _steady(_run(0, 11))                                    # counters 0..10, the last valid one is 10
    frozen = [Frame(good[-1].t_ms + CYCLE_MS * (i + 1), 10) for i in range(50)]
    frames = good + frozen
    monitor, verdicts = _feed(codebook, frames)
    assert verdicts == accepted_by_rules(frames)
    assert verdicts[11:].count(True) == 0
    state = monitor.state(MESSAGE)
    assert state.last_valid == pytest.approx(good[-1].t_ms / 1000.0)
    assert _applied_index(monitor, frames[-1].t_ms) == 10        # the frozen frames' values never applied
    assert state.timeouts == [pytest.approx((good[-1].t_ms + GAP_MS) / 1000.0)]
    assert monitor.timed_out(MESSAGE, frames[-1].t_ms / 1000.0)
    assert state.invalid == {"counter": 50}
    assert all(r.reason == "counter 10 repeated" for r in monitor.invalid_log)


def test_freeze_ends_recovery_after_two_consecutive_good_frames(codebook: Codebook) -> None:
    """After the freeze the sender's counter is where it would have been: one wrong sequence, then the second
    consecutive in-sequence frame is the first accepted."""
    counters = _run(0, 11) + [10] * 50 + _run(61 % 16, 4)       # the sender's own count continues at frame 61
    frames = _steady(counters)
    monitor, verdicts = _feed(codebook, frames)
    assert verdicts == accepted_by_rules(frames)
    assert verdicts[61:] == [False, False, True, True]
    assert [r.reason.split(",")[0] for r in monitor.invalid_log[-2:]] == ["counter 13", "counter 14 in sequence"]


@pytest.mark.parametrize("skip", [1, 2], ids=["skip 1", "skip 2"])
def test_skipped_counter_is_a_wrong_sequence(codebook: Codebook, skip: int) -> None:
    """A step of 2 (one frame lost) or 3 is a wrong sequence: rejected, and so is the next in-sequence frame;
    the second in-sequence frame is accepted."""
    counters = [3, 4, 5] + _run(6 + skip, 4)
    frames = _steady(counters)
    monitor, verdicts = _feed(codebook, frames)
    assert verdicts == accepted_by_rules(frames) == [True, True, True, False, False, True, True]
    assert monitor.invalid_log[0].reason == f"counter {6 + skip}, expected 6"
    assert monitor.state(MESSAGE).invalid == {"counter": 1, "revalidating": 1}


def test_counter_going_backwards(codebook: Codebook) -> None:
    """One step back (7 after 8) is a wrong sequence; a sender counting down is never accepted."""
    one_back = _steady([6, 7, 8, 7, 8, 9, 10])
    _, verdicts = _feed(codebook, one_back)
    assert verdicts == accepted_by_rules(one_back) == [True, True, True, False, False, True, True]
    down = _steady([5, 6, 7] + [(6 - i) % 16 for i in range(40)])
    _, verdicts = _feed(codebook, down)
    assert verdicts == accepted_by_rules(down)
    assert verdicts[3:].count(True) == 0


def test_wrap_15_to_0_is_in_sequence(codebook: Codebook) -> None:
    frames = _steady(_run(12, 40))
    _, verdicts = _feed(codebook, frames)
    assert all(verdicts)


@pytest.mark.parametrize("offset", range(16))
def test_two_interleaved_senders(codebook: Codebook, offset: int) -> None:
    """A second sender B of the same message at the same rate, 10 ms before each frame of A, its counter
    `offset` ahead of the one A sends next: while both send, nothing is accepted, except, for offset 0, B's
    first frame (it carries exactly the counter A would send next; no receiver can tell). Once B stops, A
    alone is accepted again by its third frame at the latest."""
    a = _steady(_run(0, 10))                                       # sender A alone: VALID, last counter 9
    both = []
    for i in range(40):
        t = a[-1].t_ms + CYCLE_MS * (i + 1)
        both += [Frame(t - CYCLE_MS // 2, (10 + offset + i) % 16), Frame(t, (10 + i) % 16)]
    after = [Frame(both[-1].t_ms + CYCLE_MS * (i + 1), (50 + i) % 16) for i in range(5)]
    frames = a + both + after
    _, verdicts = _feed(codebook, frames)
    assert verdicts == accepted_by_rules(frames)
    accepted_while_both = verdicts[10:10 + len(both)]
    assert accepted_while_both.count(True) == (1 if offset == 0 else 0)
    assert offset != 0 or accepted_while_both[0]
    assert verdicts[-3:] == [True, True, True]


def test_delayed_stale_frame(codebook: Codebook) -> None:
    """Counter 9 arriving after 13 (a stale frame delivered late) is never accepted, nor is the next frame
    (14 does not follow 9); 15 is the first in-sequence frame, 0 is accepted. The values applied never go
    back to the stale frame's."""
    counters = [10, 11, 12, 13]
    frames = _steady(counters) + [Frame(70, 9)] + [Frame(80 + CYCLE_MS * i, c) for i, c in enumerate([14, 15, 0, 1])]
    monitor, verdicts = _feed(codebook, frames)
    assert verdicts == accepted_by_rules(frames) == [True] * 4 + [False, False, False, True, True]
    t, x = monitor.history(MESSAGE, "PivotX")
    assert [round(v / 0.02) for v in x] == [0, 1, 2, 3, 7, 8]     # frame 4 (the stale one) never applied
    assert monitor.invalid_log[0].reason == "counter 9, expected 14"


def test_checksum_error_costs_only_its_frame(codebook: Codebook) -> None:
    """A frame with a wrong checksum is rejected and counted as the frame of its slot (counter 4 here), so the
    next frame, 5, is in sequence and accepted: the consumer misses one cycle, no timeout."""
    frames = _steady([3, 4, 5, 6])
    frames[1] = Frame(frames[1].t_ms, 4, intact=False)
    monitor, verdicts = _feed(codebook, frames)
    assert verdicts == accepted_by_rules(frames) == [True, False, True, True]
    assert [r.reason for r in monitor.invalid_log] == ["checksum"]
    assert monitor.state(MESSAGE).timeouts == []


def test_checksum_burst_then_the_first_intact_frame(codebook: Codebook) -> None:
    """Ten frames with a wrong checksum from a sender that kept counting: each takes its slot, so the first
    intact frame after them (14) is in sequence and accepted at once; the consumer timed out meanwhile."""
    frames = _steady([3] + _run(4, 10) + [14, 15])
    frames[1:11] = [Frame(f.t_ms, f.counter, intact=False) for f in frames[1:11]]
    monitor, verdicts = _feed(codebook, frames)
    assert verdicts == accepted_by_rules(frames) == [True] + [False] * 10 + [True, True]
    assert monitor.state(MESSAGE).timeouts == [pytest.approx(GAP_MS / 1000.0)]


def test_lost_frame_after_a_bad_checksum_is_a_wrong_sequence(codebook: Codebook) -> None:
    """3, a bad frame (the slot of 4), then 6: a frame was lost, a wrong sequence; 7 is the first of the two
    in-sequence frames that re-validate, 8 is accepted."""
    frames = _steady([3, 4, 6, 7, 8])
    frames[1] = Frame(frames[1].t_ms, 4, intact=False)
    monitor, verdicts = _feed(codebook, frames)
    assert verdicts == accepted_by_rules(frames) == [True, False, False, False, True]
    assert [r.reason.split(",")[0] for r in monitor.invalid_log] == ["checksum", "counter 6", "counter 7 in sequence"]


def test_timeout_then_resume(codebook: Codebook) -> None:
    """Frames stop for 200 ms (more than 3 cycles): the consumer sees a timeout 60 ms after the last frame;
    the first frame after the gap starts a new sequence, whatever its counter, and is accepted."""
    before = _steady(_run(0, 5))
    resume = _steady(_run(9, 5), start_ms=before[-1].t_ms + 200)
    frames = before + resume
    monitor, verdicts = _feed(codebook, frames)
    assert verdicts == accepted_by_rules(frames) == [True] * 10
    assert monitor.state(MESSAGE).timeouts == [pytest.approx((before[-1].t_ms + GAP_MS) / 1000.0)]
    assert not monitor.timed_out(MESSAGE, resume[0].t_ms / 1000.0)


def test_gap_of_exactly_three_cycles_does_not_resynchronise(codebook: Codebook) -> None:
    """The gap must be longer than 3 cycles: a frame 60 ms after the last one is judged on its counter."""
    frames = _steady([1, 2, 3]) + [Frame(40 + GAP_MS, 3), Frame(40 + GAP_MS + 61, 3)]
    _, verdicts = _feed(codebook, frames)
    assert verdicts == accepted_by_rules(frames) == [True, True, True, False, True]


def test_rejected_frames_keep_the_gap_closed(codebook: Codebook) -> None:
    """Issue 14: every frame counts for the gap, valid or not, so a frozen counter sent every 80 ms (longer than
    the consumer's timeout, shorter than a gap) is never accepted either."""
    frames = _steady([1, 2, 3]) + [Frame(40 + 50 * (i + 1), 3) for i in range(20)]
    _, verdicts = _feed(codebook, frames)
    assert verdicts == accepted_by_rules(frames)
    assert verdicts[3:].count(True) == 0


# -- generated sequences against the model ------------------------------------------------------------------
_STEP = st.one_of(st.just(1), st.just(1), st.just(0), st.integers(2, 15))   # mostly in sequence
_EVENT = st.tuples(_STEP, st.sampled_from([CYCLE_MS, CYCLE_MS, CYCLE_MS // 2, GAP_MS, GAP_MS + 1, 200]),
                   st.integers(0, 9))


@settings(max_examples=300, deadline=None)
@given(start=st.integers(0, 15), events=st.lists(_EVENT, max_size=60))
def test_generated_counter_sequences_follow_the_rules(codebook: Codebook, start: int,
                                                      events: list[tuple[int, int, int]]) -> None:
    """Random steps (mostly +1, some repeats and jumps), random gaps and about 1 in 10 frames with a wrong
    checksum: the monitor accepts exactly the frames the rules accept, and applies the last of them."""
    frames = [Frame(0, start)]
    for step, dt, corrupt in events:
        frames.append(Frame(frames[-1].t_ms + dt, (frames[-1].counter + step) % 16, intact=corrupt != 0))
    monitor, verdicts = _feed(codebook, frames)
    expected = accepted_by_rules(frames)
    assert verdicts == expected
    last = max(i for i, ok in enumerate(expected) if ok) if any(expected) else None
    state = monitor.state(MESSAGE)
    assert (state.latest is None) == (last is None)
    if last is not None:
        assert _applied_index(monitor, frames[-1].t_ms) == last & 0x7F
        assert state.last_valid == pytest.approx(frames[last].t_ms / 1000.0)
