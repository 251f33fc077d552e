"""A stand-alone driver: only python-can, cantools and the contract DBC.

It plays the DRIVER node towards a plant or a real vehicle: sends DRV_Steering, DRV_Pedals and
DRV_MotionRequest every cycle with AliveCounter and CRC-8/SAE-J1850 Checksum per docs/spec/k-matrix.md,
requests a rotation about a pivot, and prints the last WHL_Status_* of each wheel as JSON.

    python examples/drive_pivot.py --interface udp_multicast --channel 239.74.163.2 --pivot 5 -2 --speed 1
"""

from __future__ import annotations

import argparse
import json
import socket
import sys
import time
from pathlib import Path

import can
import cantools

DBC = Path(__file__).resolve().parent.parent / "dbc" / "chassis.dbc"


def crc8_sae_j1850(data: bytes) -> int:
    crc = 0xFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1D) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
    return crc ^ 0xFF


def protect(frame_id: int, payload: bytes, counter: int) -> bytes:
    data = bytearray(payload)
    data[6] = (data[6] & 0xF0) | (counter & 0x0F)
    data[7] = crc8_sae_j1850(bytes([frame_id & 0xFF, frame_id >> 8]) + bytes(data[:7]))
    return bytes(data)


def own_group_only(bus: can.BusABC) -> None:
    """udp_multicast on Linux: python-can binds its socket to the wildcard address on one fixed port, so it
    hears every group joined on this host: another bench's WHL_Status frames would be read as the plant's.
    Limit the socket to its own group (python-can has no option for it): IP_MULTICAST_ALL = 0 (49), and for an
    IPv6 group IPV6_MULTICAST_ALL = 0 (29) as well (python-can's IPv6 socket is dual-stack: it could also hear
    the port's IPv4 groups); then drop what it queued before. Other interfaces are left alone."""
    sock = getattr(getattr(bus, "_multicast", None), "_socket", None)
    if sock is None or not sys.platform.startswith("linux"):
        return
    if sock.family == socket.AF_INET6:
        sock.setsockopt(socket.IPPROTO_IPV6, 29, 0)   # IPV6_MULTICAST_ALL, linux/in6.h
    sock.setsockopt(socket.IPPROTO_IP, getattr(socket, "IP_MULTICAST_ALL", 49), 0)
    while True:
        try:
            sock.recv(65535, socket.MSG_DONTWAIT)
        except (BlockingIOError, InterruptedError):
            return


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--interface", default="udp_multicast")
    parser.add_argument("--channel", default="239.74.163.2")
    parser.add_argument("--pivot", nargs=2, type=float, default=(5.0, -2.0), metavar=("X", "Y"))
    parser.add_argument("--speed", type=float, default=1.0, help="TargetSpeed v_o, m/s (positive: clockwise)")
    parser.add_argument("--seconds", type=float, default=4.0)
    args = parser.parse_args()

    db = cantools.database.load_file(str(DBC))
    kwargs = {"hop_limit": 0} if args.interface == "udp_multicast" else {}
    bus = can.Bus(interface=args.interface, channel=args.channel, **kwargs)
    own_group_only(bus)
    stimulus = {
        "DRV_Steering": {"HandWheelAngle": 0.0, "HandWheelRate": 0.0, "DriverTorque": 0.0},
        "DRV_Pedals": {"AccelPedal": 0.0, "BrakePedal": 0.0, "BrakePressure": 0.0},
        "DRV_MotionRequest": {"DriveMode": 3, "PivotX": args.pivot[0], "PivotY": args.pivot[1],
                              "TargetSpeed": args.speed},
    }
    messages = {name: db.get_message_by_name(name) for name in stimulus}
    counters = dict.fromkeys(stimulus, 0)
    next_due = dict.fromkeys(stimulus, 0.0)
    status: dict[str, dict[str, float]] = {}
    t0 = time.monotonic()
    try:
        while (now := time.monotonic() - t0) < args.seconds:
            for name, message in messages.items():
                if now >= next_due[name]:
                    next_due[name] += message.cycle_time / 1000.0
                    values = dict(stimulus[name], AliveCounter=0, Checksum=0)
                    data = protect(message.frame_id, message.encode(values), counters[name])
                    counters[name] = (counters[name] + 1) % 16
                    bus.send(can.Message(arbitration_id=message.frame_id, data=data, is_extended_id=False))
            received = bus.recv(0.001)
            while received is not None:
                if 0x120 <= received.arbitration_id <= 0x123:
                    message = db.get_message_by_frame_id(received.arbitration_id)
                    status[message.name] = {k: float(v) for k, v in
                                            message.decode(received.data, decode_choices=False).items()}
                received = bus.recv(0.0)
    finally:
        bus.shutdown()
    print(json.dumps(status, sort_keys=True))


if __name__ == "__main__":
    main()
