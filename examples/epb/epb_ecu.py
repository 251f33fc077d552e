"""An electric park brake (EPB) ECU on CAN FD, written from `contract.md` and `epb.dbc` alone.

Node `EPB` of `epb.dbc` (this folder), as an outside supplier would write it; comments cite the requirement ids.
- EPB-01: sends `EPB_Status` (0x200, CAN FD 64 bytes with bit rate switch, E2E Profile 7) every 20 ms,
  `EPB_Info` (0x210, pages 0, 1, 2 in turn) every 100 ms and `EPB_Event` (29-bit 0x18FF3020) once per event.
- EPB-02: uses `HIL_VehicleState` (0x100, CAN FD, E2E Profile 5) only when intact and 1 or 2 ahead of the last
  intact frame's counter; the speed is valid while the last used frame is at most 50 ms old.
- EPB-03/04/05: the state machine RELEASED -> APPLYING -> APPLIED -> RELEASING -> RELEASED driven by the changes
  of `HIL_ParkSwitch` (29-bit 0x18FF2010), the clamp force ramped by 0.4 kN per status frame, the motor currents.
- EPB-06: events (APPLIED, RELEASED, REFUSED_*), at least 10 ms apart, counted modulo 256.
- EPB-07: service mode from `HIL_Service` (ON in RELEASED -> SERVICE; OFF or 150 ms of silence -> RELEASED).
- EPB-08: power-up in RELEASED, no force, counters 0.

One loop on time.monotonic: a 10 ms task on an absolute grid (no drift) sends what is due; between tasks the
loop waits for frames in bus.recv (timeout up to the next deadline) and reacts to each at once.

    python epb_ecu.py --interface udp_multicast --channel 239.255.7.1
    python epb_ecu.py --interface socketcan --channel vcan0

Needs python-can, cantools and autosar-e2e (import name `e2e`) and the standard library; nothing of the bench.
"""

from __future__ import annotations

import argparse
import signal
import socket
import time
from collections import deque
from pathlib import Path
from typing import Any

import can
import cantools
from e2e import p05, p07

# --- Timing (EPB-01, EPB-02, EPB-06, EPB-07) -------------------------------------------------------------------
TASK_S = 0.010  # the task grid
STATUS_EVERY = 2  # tasks: EPB_Status every 20 ms (EPB-01)
INFO_EVERY = 10  # tasks: EPB_Info every 100 ms (EPB-01)
EVENT_GAP_S = 0.012  # EPB-06: "never two frames less than 10 ms apart" (2 ms margin for the bus's jitter)
# EPB-02: valid while the last used frame is at most 50 ms old, INVALID sent at most 70 ms after it; the status
# frames are 20 ms apart, so 50 + 20 = 70 leaves nothing for the task's jitter: 2 ms of the 50 are kept for it
SPEED_FRESH_S = 0.048
SERVICE_SILENCE_S = 0.150  # EPB-07: 150 ms without HIL_Service leaves SERVICE

# --- E2E (EPB-01, EPB-02) --------------------------------------------------------------------------------------
STATUS_DATA_ID = 0x0EB00200  # EPB_Status, Profile 7, header at byte 0, whole frame
VEHICLE_STATE_DATA_ID = 0x1100  # HIL_VehicleState, Profile 5, header at byte 0, whole frame
P05_COUNTER_BYTE = 2
P05_MAX_DELTA = 2  # MaxDeltaCounter: a used frame is 1 or 2 ahead of the last used one
P07_COUNTER = slice(12, 16)  # the Profile 7 header: CRC 0-7, length 8-11, counter 12-15, Data ID 16-19

# --- Raw signal values (epb.dbc: VAL_ tables and scalings) -----------------------------------------------------
RELEASED, APPLYING, APPLIED, RELEASING, SERVICE = range(5)  # ParkState
NEUTRAL, APPLY, RELEASE = range(3)  # HIL_ParkSwitch.Switch
EV_APPLIED, EV_RELEASED, EV_REFUSED_MOVING, EV_REFUSED_NO_BRAKE, EV_REFUSED_NO_SPEED = range(1, 6)  # EventCode
FORCE_STEP = 400  # ClampForce raw (0.001 kN): 0.4 kN per 20 ms frame = 20 kN/s (EPB-03, EPB-04)
FORCE_APPLIED = 16000  # 16.000 kN (EPB-03)
MOTOR_CURRENT = 800  # MotorCurrentLeft/Right raw (0.01 A): 8.00 A (EPB-05)
SPEED_LIMIT = 300  # VehicleSpeed raw (0.01 km/h): 3 km/h (EPB-03)
PEDAL_RELEASED = 0  # BrakePedal
SOFTWARE_VERSION = (1, 0)  # EPB-01: major 1
PAD_TEMPERATURE_DEGC = 25  # EPB-01: any value in range

INPUTS = ("HIL_VehicleState", "HIL_ParkSwitch", "HIL_Service")


class Epb:
    """The park brake's logic, without a bus: inputs with their arrival times (time.monotonic), outputs as the
    raw signal values of the next frames."""

    def __init__(self) -> None:
        # EPB-08: power-up state
        self.state = RELEASED
        self.force = 0  # raw ClampForce
        self.apply_count = 0
        self.event_count = 0
        self.events: deque[int] = deque()  # EventCodes waiting for their frame (EPB-06)
        # EPB-02: the last used HIL_VehicleState frame
        self.last_counter: int | None = None
        self.last_used_at: float | None = None
        self.speed = 0  # raw VehicleSpeed
        self.pedal = PEDAL_RELEASED
        # EPB-03/04: the previous park switch frame (None: no frame since power-up)
        self.previous_switch: int | None = None
        # EPB-07: arrival of the last ServiceMode ON frame
        self.service_on_at = 0.0

    # --- EPB-02 ------------------------------------------------------------------------------------------------
    def on_vehicle_state(self, data: bytes, signals: dict[str, int], at: float) -> None:
        if not p05.e2e_p05_check(bytearray(data), VEHICLE_STATE_DATA_ID):
            return  # CRC wrong: not used
        counter, last = data[P05_COUNTER_BYTE], self.last_counter
        self.last_counter = counter  # every intact frame is the reference of the next (AUTOSAR's E2E_P05Check)
        if last is not None and not 1 <= (counter - last) % 256 <= P05_MAX_DELTA:
            return  # repeated, or too far ahead of the last intact frame: not used
        self.last_used_at = at  # the first intact frame is used whatever its counter
        self.speed, self.pedal = signals["VehicleSpeed"], signals["BrakePedal"]

    def speed_valid(self, now: float) -> bool:
        """EPB-02: the last used frame is at most 50 ms old (48 ms here, SPEED_FRESH_S)."""
        return self.last_used_at is not None and now - self.last_used_at <= SPEED_FRESH_S

    # --- EPB-03, EPB-04 ----------------------------------------------------------------------------------------
    def on_park_switch(self, switch: int, at: float) -> None:
        changed = switch != self.previous_switch  # the repetitions change nothing
        self.previous_switch = switch
        if not changed or self.state == SERVICE:  # EPB-07: in SERVICE the switch does nothing
            return
        if switch == APPLY and self.state in (RELEASED, RELEASING):  # EPB-03
            if not self.speed_valid(at):
                self.events.append(EV_REFUSED_NO_SPEED)
            elif self.speed > SPEED_LIMIT:
                self.events.append(EV_REFUSED_MOVING)
            else:
                self.state = APPLYING  # in the next status frame, at most 20 ms away
        elif switch == RELEASE and self.state in (APPLIED, APPLYING):  # EPB-04
            if not self.speed_valid(at):
                self.events.append(EV_REFUSED_NO_SPEED)
            elif self.pedal == PEDAL_RELEASED:
                self.events.append(EV_REFUSED_NO_BRAKE)
            else:
                self.state = RELEASING
        # NEUTRAL, APPLY in APPLYING/APPLIED and RELEASE in RELEASED/RELEASING do nothing (EPB-03, EPB-04)

    # --- EPB-07 ------------------------------------------------------------------------------------------------
    def on_service(self, on: bool, at: float) -> None:
        if on:
            self.service_on_at = at
            if self.state == RELEASED:
                self.state = SERVICE  # ClampForce is 0 in RELEASED already: the pads stay retracted
        elif self.state == SERVICE:
            self.state = RELEASED

    def task(self, now: float) -> None:
        """EPB-07: leave SERVICE after 150 ms without a ServiceMode ON frame (checked every 10 ms task)."""
        if self.state == SERVICE and now - self.service_on_at > SERVICE_SILENCE_S:
            self.state = RELEASED

    # --- EPB-01, EPB-03..05: one EPB_Status frame --------------------------------------------------------------
    def status(self, now: float) -> dict[str, int]:
        """Advance the ramp by one frame and return the frame's raw signals. The frame that first carries
        16.000 kN (0.000 kN) carries APPLIED (RELEASED), and the event goes out (EPB-03, EPB-04)."""
        if self.state == APPLYING:
            self.force = min(FORCE_APPLIED, self.force + FORCE_STEP)
            if self.force == FORCE_APPLIED:
                self.state = APPLIED
                self.apply_count += 1  # EPB-01 page 1: applies completed
                self.events.append(EV_APPLIED)
        elif self.state == RELEASING:
            self.force = max(0, self.force - FORCE_STEP)
            if self.force == 0:
                self.state = RELEASED
                self.events.append(EV_RELEASED)
        current = MOTOR_CURRENT if self.state in (APPLYING, RELEASING) else 0  # EPB-05
        return {"ParkState": self.state, "ClampForce": self.force, "SpeedValid": int(self.speed_valid(now)),
                "MotorCurrentLeft": current, "MotorCurrentRight": current}

    def next_event(self) -> dict[str, int]:
        """EPB-06: the next event's frame; EventCount counts events since power-up (1 for the first), mod 256."""
        self.event_count = (self.event_count + 1) % 256
        return {"EventCode": self.events.popleft(), "EventCount": self.event_count}


class Node:
    """The EPB on its bus: the 10 ms task, the frames it sends and the frames it reads."""

    def __init__(self, bus: can.BusABC, db: cantools.database.Database) -> None:
        self.bus, self.db, self.epb = bus, db, Epb()
        self.status_msg = db.get_message_by_name("EPB_Status")
        self.info_msg = db.get_message_by_name("EPB_Info")
        self.event_msg = db.get_message_by_name("EPB_Event")
        self.inputs = {db.get_message_by_name(name).frame_id: db.get_message_by_name(name) for name in INPUTS}
        self.status_counter = 0  # EPB-01: 0 at power-up, +1 per frame sent
        self.info_page = 0
        self.last_event_at = -1.0
        self.send_failed = False

    # --- sending -----------------------------------------------------------------------------------------------
    def send(self, message: cantools.database.Message, data: bytes) -> bool:
        frame = can.Message(arbitration_id=message.frame_id, is_extended_id=message.is_extended_frame,
                            is_fd=message.is_fd, bitrate_switch=message.is_fd, data=data)
        try:
            self.bus.send(frame, timeout=0.005)
        except can.CanError as error:
            if not self.send_failed:  # say it once, keep running (e.g. FD frames on a --no-fd bus)
                print(f"epb_ecu: cannot send {message.name}: {error}", flush=True)
                self.send_failed = True
            return False
        return True

    def send_status(self, now: float) -> None:
        """EPB-01: 64 bytes, signals in bytes 20-27, every other byte 0 but the P07 header (bytes 0-19)."""
        data = bytearray(self.status_msg.encode(self.epb.status(now), scaling=False, strict=True))
        data[P07_COUNTER] = self.status_counter.to_bytes(4, "big")
        p07.e2e_p07_protect(data, STATUS_DATA_ID, increment_counter=False)  # CRC, length, Data ID
        if self.send(self.status_msg, bytes(data)):
            self.status_counter = (self.status_counter + 1) & 0xFFFFFFFF

    def send_info(self) -> None:
        """EPB-01: pages 0, 1, 2, 0, ... one per frame."""
        page = self.info_page
        values = [{"SoftwareMajor": SOFTWARE_VERSION[0], "SoftwareMinor": SOFTWARE_VERSION[1]},
                  {"ApplyCount": self.epb.apply_count},
                  {"PadTemperature": PAD_TEMPERATURE_DEGC}][page]
        data = self.info_msg.encode({"InfoPage": page, **values}, strict=True)
        self.send(self.info_msg, data)
        self.info_page = (page + 1) % 3

    def send_event(self, now: float) -> None:
        """EPB-06: one frame per event, the second of two close events waits for the gap."""
        if self.epb.events and now - self.last_event_at >= EVENT_GAP_S:
            self.send(self.event_msg, self.event_msg.encode(self.epb.next_event(), scaling=False, strict=True))
            self.last_event_at = now

    def event_due(self) -> float:
        return self.last_event_at + EVENT_GAP_S if self.epb.events else float("inf")

    # --- receiving ---------------------------------------------------------------------------------------------
    def on_frame(self, msg: can.Message) -> None:
        """Use a frame only if it is one of the EPB's inputs in the DBC's format (11/29-bit, classical/FD, length)."""
        if msg.is_error_frame or msg.is_remote_frame:
            return
        message = self.inputs.get(msg.arbitration_id)
        if message is None or msg.is_extended_id != message.is_extended_frame or msg.is_fd != message.is_fd \
                or len(msg.data) != message.length:
            return  # not ours (among them our own frames, looped back), or not in the DBC's format
        at = arrival(msg)
        try:
            decoded = message.decode(bytes(msg.data), decode_choices=False, scaling=False)
        except (cantools.database.errors.DecodeError, ValueError):
            return
        if not isinstance(decoded, dict):
            return
        signals = {name: int(value) for name, value in decoded.items() if isinstance(value, (int, float))}  # raw
        if message.name == "HIL_VehicleState":  # EPB-02
            self.epb.on_vehicle_state(bytes(msg.data), signals, at)
        elif message.name == "HIL_ParkSwitch":  # EPB-03, EPB-04
            self.epb.on_park_switch(signals["Switch"], at)
        else:  # HIL_Service, EPB-07
            self.epb.on_service(bool(signals["ServiceMode"]), at)
        self.send_event(time.monotonic())  # EPB-06: a refusal goes out at once when the gap allows

    def drain(self) -> None:
        """Take in every frame already queued (after a late wake-up: before the task judges the speed's age)."""
        while (msg := self.bus.recv(timeout=0.0)) is not None:
            self.on_frame(msg)

    # --- the loop ----------------------------------------------------------------------------------------------
    def run(self, stopped: list[bool]) -> None:
        """The 10 ms task on the grid t0 + n * 10 ms (deadlines from the start, no drift; a late task skips the
        slots it missed instead of sending a burst); between tasks, frames as they come."""
        t0 = time.monotonic()
        next_slot, status_slot, info_slot = 0, 0, 0
        while not stopped[0]:
            now = time.monotonic()
            slot = int((now - t0) / TASK_S)
            if slot >= next_slot:
                self.drain()
                now = time.monotonic()
                self.epb.task(now)  # EPB-07
                if slot >= status_slot:  # EPB-01: from power-up, every 20 ms
                    self.send_status(now)
                    status_slot = (slot // STATUS_EVERY + 1) * STATUS_EVERY
                if slot >= info_slot:  # EPB-01: every 100 ms
                    self.send_info()
                    info_slot = (slot // INFO_EVERY + 1) * INFO_EVERY
                self.send_event(now)  # EPB-03/04: the APPLIED / RELEASED event after its status frame
                next_slot = slot + 1
                continue
            self.send_event(now)
            wait = min(t0 + next_slot * TASK_S, self.event_due()) - now
            msg = self.bus.recv(timeout=max(0.0, wait))
            if msg is not None:
                self.on_frame(msg)


def arrival(msg: can.Message) -> float:
    """A frame's arrival on the time.monotonic clock, from its receive stamp (wall clock) when it has one."""
    mono, wall = time.monotonic(), time.time()
    age = wall - msg.timestamp
    return mono - age if 0.0 <= age < 1.0 else mono


def open_bus(args: argparse.Namespace) -> can.BusABC:
    kwargs: dict[str, Any] = {"interface": args.interface, "channel": args.channel, "fd": not args.no_fd}
    if args.interface == "udp_multicast":
        kwargs["hop_limit"] = 0  # loopback only: this host
    bus = can.Bus(**kwargs)
    if args.interface == "udp_multicast":
        only_own_group(bus)
    return bus


def only_own_group(bus: can.BusABC) -> None:
    """Linux delivers to a socket bound to the port every group any process on the host joined on that port
    (IP_MULTICAST_ALL defaults to 1): another bench's frames would look like ours. Receive our group only."""
    sock = getattr(getattr(bus, "_multicast", None), "_socket", None)
    if sock is None:
        return
    try:
        if sock.family == socket.AF_INET:
            sock.setsockopt(socket.IPPROTO_IP, 49, 0)  # IP_MULTICAST_ALL, linux/in.h
        else:
            sock.setsockopt(socket.IPPROTO_IPV6, 29, 0)  # IPV6_MULTICAST_ALL, linux/in6.h
    except OSError:
        pass  # not Linux


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--interface", default="udp_multicast", help="python-can interface (default udp_multicast)")
    parser.add_argument("--channel", default="239.255.7.1",
                        help="python-can channel (default 239.255.7.1; vcan0 for socketcan)")
    parser.add_argument("--dbc", type=Path, default=Path(__file__).resolve().parent / "epb.dbc",
                        help="the network's DBC (default: epb.dbc beside this script)")
    parser.add_argument("--no-fd", action="store_true",
                        help="open the bus as classical CAN (EPB_Status, an FD frame, then cannot go out)")
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    try:
        db = cantools.database.load_file(str(args.dbc))
        if not isinstance(db, cantools.database.can.Database):
            raise cantools.database.errors.Error("not a CAN database")
    except (OSError, cantools.database.errors.Error) as error:
        print(f"epb_ecu: {args.dbc}: {error}", flush=True)
        return 2
    try:
        bus = open_bus(args)
    except (can.CanError, OSError, ValueError) as error:
        print(f"epb_ecu: cannot open {args.interface} {args.channel}: {error}", flush=True)
        return 2
    stopped = [False]

    def stop(*_: object) -> None:
        stopped[0] = True

    for signum in (signal.SIGINT, signal.SIGTERM):  # also when started in the background (SIGINT ignored there)
        signal.signal(signum, stop)
    print(f"EPB running on {args.interface} {args.channel}: EPB_Status 20 ms (E2E P07), EPB_Info 100 ms, "
          f"EPB_Event per event; reads HIL_VehicleState (E2E P05), HIL_ParkSwitch, HIL_Service", flush=True)
    try:
        Node(bus, db).run(stopped)
    finally:
        bus.shutdown()
        print("EPB stopped", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
