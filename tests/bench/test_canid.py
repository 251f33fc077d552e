"""bench.canid: a frame's identity as SocketCAN's can_id (and the CAN FD flags above it).

Checked against python-can (a Message built from the frame_id describes the same frame, and back) and against the
arbitration field of ISO 11898-1 written out bit by bit (which frame wins), not against the module's own formulas.
"""

from __future__ import annotations

import can
import pytest
from hypothesis import given
from hypothesis import strategies as st

from bench import canid

# a frame as python-can describes it: (arbitration_id, extended, remote, error, fd, brs, esi)
frames = st.tuples(st.booleans(), st.integers(0, 0x1FFFFFFF), st.booleans(), st.booleans(), st.booleans(),
                   st.booleans(), st.booleans()).map(
    lambda f: (f[1] if f[0] else f[1] & 0x7FF, f[0], f[2], f[3], f[4], f[4] and f[5], f[4] and f[6]))


@given(frames)
def test_a_frame_id_and_a_python_can_message_describe_the_same_frame(frame: tuple) -> None:
    ident, extended, remote, error, fd, brs, esi = frame
    frame_id = canid.of(ident, extended, is_remote=remote, is_error=error, is_fd=fd, bitrate_switch=brs,
                        error_state_indicator=esi)
    msg = can.Message(data=b"", **canid.message_kwargs(frame_id))
    assert (msg.arbitration_id, msg.is_extended_id, msg.is_remote_frame, msg.is_error_frame, msg.is_fd,
            msg.bitrate_switch, msg.error_state_indicator) == frame
    assert canid.of_message(msg) == frame_id and canid.problem(frame_id) is None
    assert frame_id & canid.CAN_ID == ident | (extended << 31) | (remote << 30) | (error << 29)   # linux/can.h


def _arbitration_bits(frame_id: int) -> list[int]:
    """The arbitration field of a data frame as ISO 11898-1 sends it (0 dominant): base identifier, then RTR and IDE
    for an 11-bit frame; base identifier, SRR (1), IDE (1), the 18 extension bits and RTR for a 29-bit one."""
    if frame_id & canid.EFF:
        ident = frame_id & canid.EFF_MASK
        base, ext = ident >> 18, ident & 0x3FFFF
        return [base >> i & 1 for i in range(10, -1, -1)] + [1, 1] + [ext >> i & 1 for i in range(17, -1, -1)] + [0]
    ident = frame_id & canid.SFF_MASK
    return [ident >> i & 1 for i in range(10, -1, -1)] + [0, 0]


def _wins(a: int, b: int) -> bool:
    """Whether `a` wins arbitration against `b`: the first differing bit, dominant (0) wins."""
    for x, y in zip(_arbitration_bits(a), _arbitration_bits(b)):
        if x != y:
            return x == 0
    return False


@given(frames, frames)
def test_priority_orders_frames_as_arbitration_does(a: tuple, b: tuple) -> None:
    first, second = canid.of(a[0], a[1]), canid.of(b[0], b[1])
    if first != second:
        assert (canid.priority(first) < canid.priority(second)) == _wins(first, second)


@pytest.mark.parametrize(("text", "frame_id", "shown"), [
    ("0x000", 0x000, "0x000"), ("0x7FF", 0x7FF, "0x7FF"), ("0x123", 0x123, "0x123"), ("291", 0x123, "0x123"),
    ("0x800", 0x800 | canid.EFF, "0x00000800"), ("0x00000123", 0x123 | canid.EFF, "0x00000123"),
    ("0x18FEF100", 0x18FEF100 | canid.EFF, "0x18FEF100")])
def test_identifiers_as_written_and_shown(text: str, frame_id: int, shown: str) -> None:
    assert canid.parse(text) == frame_id and canid.text(frame_id) == shown


@pytest.mark.parametrize("text", ["0x20000000", "-1", "bus", "0x"])
def test_what_is_no_identifier(text: str) -> None:
    with pytest.raises(ValueError):
        canid.parse(text)


@pytest.mark.parametrize(("frame_id", "why"), [
    (0x800, "above 0x7FF"), (-1, "not an identifier"), (1 << 40, "not an identifier"), ("0x1", "not an int"),
    (canid.BRS | 0x100, "classical frame")])
def test_what_is_no_frame_id(frame_id: object, why: str) -> None:
    assert why in (canid.problem(frame_id) or "")


def test_fd_lengths() -> None:
    assert [canid.fd_length(n) for n in (0, 8, 9, 12, 13, 33, 64)] == [0, 8, 12, 12, 16, 48, 64]
    with pytest.raises(ValueError, match="at most 64"):
        canid.fd_length(65)
