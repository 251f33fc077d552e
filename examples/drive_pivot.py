"""A stand-alone driver: only python-can, cantools, autosar-e2e and the contract DBC.

It plays the DRIVER node towards a plant or a real vehicle: sends DRV_Steering, DRV_Pedals and
DRV_MotionRequest every cycle protected by AUTOSAR E2E Profile 11 (the `autosar-e2e` package, parameters from
the DBC's E2E_* attributes, docs/spec/e2e.md), requests a rotation about a pivot, and prints the last
WHL_Status_* of each wheel as JSON.

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
from e2e import p11

DBC = Path(__file__).resolve().parent.parent / "dbc" / "chassis.dbc"


def e2e_parameters(db: cantools.database.can.Database, message: cantools.database.can.Message) -> tuple[int, int]:
    """(DataID, header byte) of a message from the DBC's E2E attributes (docs/spec/e2e.md): the message's own value,
    else the database's default; this driver speaks the contract's profile, AUTOSAR Profile 11 with DataIDMode
    BOTH, and refuses any other."""
    definitions = db.dbc.attribute_definitions

    def attribute(name: str) -> object:
        found = message.dbc.attributes.get(name)
        definition = definitions[name]
        value = definition.default_value if found is None else found.value
        return definition.choices[value] if definition.choices and isinstance(value, int) else value

    if attribute("E2E_Profile") != "P11" or attribute("E2E_DataIDMode") != "BOTH":
        raise SystemExit(f"{message.name}: this example speaks E2E Profile 11, DataIDMode BOTH only")
    return int(attribute("E2E_DataID")), int(attribute("E2E_Offset")) // 8


def protect(payload: bytes, counter: int, data_id: int, offset: int) -> bytes:
    """COM-E2E-01/02: the counter (0-14) in the low nibble after the CRC byte, then the CRC by autosar-e2e."""
    data = bytearray(payload)
    data[offset + 1] = (data[offset + 1] & 0xF0) | counter
    p11.e2e_p11_protect(data, data_id, offset=offset, increment_counter=False)
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
    protection = {name: e2e_parameters(db, message) for name, message in messages.items()}
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
                    data = protect(message.encode(values), counters[name], *protection[name])
                    counters[name] = (counters[name] + 1) % 15     # Profile 11 counts 0 ... 14
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
