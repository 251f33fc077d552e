"""A frame's identity as one int, the way SocketCAN writes it: the bench's `frame_id` everywhere.

Why one int: the restbus, the faults, the transports, the monitor and the log pass a frame's identifier from hand
to hand, and an 11-bit 0x123 and a 29-bit 0x123 are two different identifiers on the bus. Linux's `can_id`
(linux/can.h) already says it in one number that every CAN engineer has seen in candump: the identifier, with
CAN_EFF_FLAG for a 29-bit one, CAN_RTR_FLAG for a remote frame and CAN_ERR_FLAG for an error frame. Above those 32
bits the bench keeps the CAN FD frame's flags (canfd_frame.flags: FD, bit rate switch, error state indicator), so
that what a frame was on the bus travels with it to the log.

A message's `frame_id` (bench.database.codec.MessageCodec) is its identifier with CAN_EFF_FLAG when 29-bit and
FD when the database declares a CAN FD frame; a received frame's `frame_id & IDENTITY` looks it up. Its frames go
out as its `send_id`: with BRS where the database asks for it.
"""

from __future__ import annotations

from typing import Any

EFF = 0x80000000          # CAN_EFF_FLAG: a 29-bit (extended) identifier
RTR = 0x40000000          # CAN_RTR_FLAG: a remote frame
ERR = 0x20000000          # CAN_ERR_FLAG: an error frame
EFF_MASK = 0x1FFFFFFF     # CAN_EFF_MASK
SFF_MASK = 0x7FF          # CAN_SFF_MASK
FD = 1 << 32              # a CAN FD frame (the bench's; SocketCAN tells it by the frame's size)
BRS = 1 << 33             # CANFD_BRS: its data phase at the data bit rate
ESI = 1 << 34             # CANFD_ESI: its sender was error passive
CAN_ID = 0xFFFFFFFF       # the SocketCAN can_id part
#: What a message is looked up by: the can_id (identifier, 11/29-bit, remote and error frames never match a message's)
#: and CAN FD or not; a frame's BRS and ESI say how it crossed the bus, not which message it is.
IDENTITY = CAN_ID | FD


#: The data lengths a CAN FD frame's DLC can say (ISO 11898-1); a classical frame's are 0 to 8.
FD_LENGTHS = (0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64)


def fd_length(length: int) -> int:
    """The CAN FD frame length a payload of `length` bytes goes out with (the next one of FD_LENGTHS; the bus pads);
    ValueError beyond 64 bytes."""
    for valid in FD_LENGTHS:
        if valid >= length:
            return valid
    raise ValueError(f"a CAN FD frame carries at most {FD_LENGTHS[-1]} bytes, not {length}")


def of(arbitration_id: int, is_extended: bool = False, *, is_remote: bool = False, is_error: bool = False,
       is_fd: bool = False, bitrate_switch: bool = False, error_state_indicator: bool = False) -> int:
    """The frame_id of a frame described as python-can describes it."""
    key = arbitration_id
    if is_extended:
        key |= EFF
    if is_remote:
        key |= RTR
    if is_error:
        key |= ERR
    if is_fd:
        key |= FD
        if bitrate_switch:
            key |= BRS
        if error_state_indicator:
            key |= ESI
    return key


def of_message(msg: Any) -> int:
    """The frame_id of a received frame: its own `frame_id` when it carries one (the bench's embedded bus and
    SocketCAN receiver), else computed from a python-can Message's fields."""
    key = getattr(msg, "frame_id", None)
    if key is not None:
        return int(key)
    return of(msg.arbitration_id, msg.is_extended_id, is_remote=msg.is_remote_frame, is_error=msg.is_error_frame,
              is_fd=getattr(msg, "is_fd", False), bitrate_switch=getattr(msg, "bitrate_switch", False),
              error_state_indicator=getattr(msg, "error_state_indicator", False))


def problem(frame_id: object) -> str | None:
    """Why `frame_id` is no frame_id (None: it is one): not an int, negative, flags the bench does not know, or an
    11-bit identifier above 0x7FF."""
    if not isinstance(frame_id, int) or isinstance(frame_id, bool):
        return f"frame_id {frame_id!r} is not an int"
    if frame_id < 0 or frame_id & ~(CAN_ID | FD | BRS | ESI):
        return f"frame_id {frame_id!r} is not an identifier with SocketCAN's flags (bench.canid)"
    if not frame_id & EFF and frame_id & EFF_MASK > SFF_MASK:
        return f"frame_id 0x{frame_id:X}: an 11-bit identifier above 0x7FF (a 29-bit one carries CAN_EFF_FLAG)"
    if frame_id & (BRS | ESI) and not frame_id & FD:
        return f"frame_id 0x{frame_id:X}: BRS or ESI on a classical frame"
    return None


def arbitration_id(frame_id: int) -> int:
    """The identifier on the bus (11 or 29 bits), as python-can's `arbitration_id`."""
    return frame_id & (EFF_MASK if frame_id & EFF else SFF_MASK)


def is_extended(frame_id: int) -> bool:
    return bool(frame_id & EFF)


def is_error(frame_id: int) -> bool:
    return bool(frame_id & ERR)


def is_remote(frame_id: int) -> bool:
    return bool(frame_id & RTR)


def is_fd(frame_id: int) -> bool:
    return bool(frame_id & FD)


def message_kwargs(frame_id: int) -> dict[str, Any]:
    """python-can Message keywords for a frame of this frame_id (all but its time and data)."""
    return {"arbitration_id": arbitration_id(frame_id), "is_extended_id": bool(frame_id & EFF),
            "is_remote_frame": bool(frame_id & RTR), "is_error_frame": bool(frame_id & ERR),
            "is_fd": bool(frame_id & FD), "bitrate_switch": bool(frame_id & BRS),
            "error_state_indicator": bool(frame_id & ESI)}


def text(frame_id: int) -> str:
    """The identifier as the bench shows it: 0x123 for 11 bits, 0x18FEF100 (eight digits) for 29 bits, so that a
    29-bit identifier below 0x800 still reads as one. A bare number above 0x7FF (a raw 29-bit identifier, as
    python-can's arbitration_id) reads as 29-bit too."""
    if frame_id & EFF or frame_id & CAN_ID > SFF_MASK:
        return f"0x{frame_id & EFF_MASK:08X}"
    return f"0x{frame_id & SFF_MASK:03X}"


def parse(spec: str) -> int:
    """An identifier written in a fault or on a command line: 0x123 is 11-bit; a value above 0x7FF, or one written
    with eight hex digits (0x00000123), is 29-bit. ValueError for anything else."""
    word = spec.strip()
    value = int(word, 0)
    digits = word[2:] if word[:2].lower() == "0x" else ""
    if value < 0 or value > EFF_MASK:
        raise ValueError(f"{spec!r} is no CAN identifier (0 to 0x7FF, or 29-bit up to 0x1FFFFFFF)")
    if value > SFF_MASK or len(digits) == 8:
        return value | EFF
    return value


def priority(frame_id: int) -> int:
    """Its place in arbitration (lower wins): the 11 base bits first; at equal base bits an 11-bit data frame
    wins over a 29-bit one (its RTR/IDE bits are dominant where the 29-bit frame's SRR/IDE are recessive)."""
    if frame_id & EFF:
        ident = frame_id & EFF_MASK
        return ((ident >> 18) << 20) | (3 << 18) | (ident & 0x3FFFF)
    return (frame_id & SFF_MASK) << 20
