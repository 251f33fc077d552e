"""Fault injection: what a broken ECU or bus does to frames, scoped to a message or node and a window.

Faults act on the frames a station sends, after the restbus built them (so they look like a real
broken sender: a wrong counter carries a correct checksum unless the checksum is the fault).
Spec syntax (command line, `--fault`): `KIND:TARGET[:PARAM]@START[-END]`, times in bench seconds,
an open END lasting to the end of the run; e.g. `drop:VCU_WheelCmd_FL@2-3`, `silence:WHL_FR@1.5-`,
`checksum_offset:IMU_Motion:1@2-4`, `flood:0x000:8@1-2`.

On the virtual-time bus there is no arbitration; `flood` therefore models it: a babbling node
sending PARAM frames per millisecond at identifier TARGET takes the whole bus at or above
FLOOD_SATURATION frames/ms (500 kbit/s carries about 4.3 eight-byte frames per ms), and every frame
of a lower priority (higher identifier) sent meanwhile is lost, as on a real bus it would wait forever.
"""

from __future__ import annotations

import math
import random
from collections.abc import Iterable
from dataclasses import dataclass, field

from bench import e2e
from bench.codec import Codebook
from bench.errors import ConfigError

FRAME_KINDS = ("drop", "delay", "duplicate", "bitflip", "counter_freeze", "counter_jump", "checksum_value",
               "checksum_freeze", "checksum_random", "checksum_offset")
NODE_KINDS = ("silence", "bus_off")
BUS_KINDS = ("flood", "error_frame")
KINDS = FRAME_KINDS + NODE_KINDS + BUS_KINDS
FLOOD_SATURATION = 4.0   # babbling frames per ms from which lower-priority frames never win arbitration
RANDOM_SEED = 0x5EED     # checksum_random is deterministic, so a campaign stays reproducible


@dataclass
class Fault:
    kind: str
    target: str          # message name (frame kinds), node name (silence, bus_off), identifier (flood)
    start: float         # bench time, s
    end: float = math.inf
    param: float = 0.0   # delay s, bit index, counter jump, checksum value/offset, flood frames per ms
    frozen: int | None = field(default=None, repr=False)   # counter/checksum value at the fault's start

    def active(self, t: float) -> bool:
        return self.start <= t < self.end

    def describe(self) -> str:
        end = "" if math.isinf(self.end) else f"{self.end:g}"
        param = f":{self.param:g}" if self.param else ""
        return f"{self.kind}:{self.target}{param}@{self.start:g}-{end}"


def parse_fault(spec: str) -> Fault:
    """`KIND:TARGET[:PARAM]@START[-END]` -> Fault; ConfigError naming the spec and what is wrong."""
    head, at, window = spec.partition("@")
    parts = head.split(":")
    if not at or len(parts) not in (2, 3):
        raise ConfigError(f"--fault {spec!r}: expected KIND:TARGET[:PARAM]@START[-END]")
    kind, target = parts[0], parts[1]
    if kind not in KINDS:
        raise ConfigError(f"--fault {spec!r}: unknown kind {kind!r} (kinds: {', '.join(KINDS)})")
    start_text, _, end_text = window.partition("-")
    try:
        param = float(parts[2]) if len(parts) == 3 else 0.0
        start = float(start_text)
        end = float(end_text) if end_text else math.inf
    except ValueError:
        raise ConfigError(f"--fault {spec!r}: PARAM, START and END must be numbers") from None
    if not (math.isfinite(param) and math.isfinite(start) and start >= 0 and end > start):
        raise ConfigError(f"--fault {spec!r}: need 0 <= START < END and a finite PARAM")
    return Fault(kind, target, start, end, param)


class FaultPlan:
    """The faults of a run; every station of the run applies them to the frames it sends."""

    def __init__(self, codebook: Codebook) -> None:
        self.codebook = codebook
        self.faults: list[Fault] = []
        self._rng = random.Random(RANDOM_SEED)

    def add(self, fault: Fault) -> Fault:
        self._check(fault)
        self.faults.append(fault)
        return fault

    def extend(self, faults: Iterable[Fault]) -> None:
        for fault in faults:
            self.add(fault)

    def _check(self, fault: Fault) -> None:
        if fault.kind in FRAME_KINDS:
            self.codebook[fault.target]   # raises a clear error for an unknown message
            if fault.kind == "bitflip" and not 0 <= fault.param < 64:
                raise ConfigError(f"fault {fault.describe()}: bit index must be 0..63")
            if fault.kind == "delay" and not fault.param > 0:
                raise ConfigError(f"fault {fault.describe()}: a delay needs PARAM > 0 s")
        elif fault.kind in NODE_KINDS:
            if fault.target not in self.codebook.nodes:
                raise ConfigError(f"fault {fault.describe()}: unknown node {fault.target!r}")
        elif fault.kind == "flood":
            try:
                int(fault.target, 0)
            except ValueError:
                raise ConfigError(f"fault {fault.describe()}: TARGET must be an identifier like 0x000") from None
            if not fault.param > 0:
                raise ConfigError(f"fault {fault.describe()}: PARAM must be frames per ms > 0")

    @property
    def any(self) -> bool:
        return bool(self.faults)

    # -- applied by stations ----------------------------------------------------------------------
    def babble(self, t: float, dt: float) -> list[tuple[int, bytes, bool]]:
        """Frames the babbling node and error-frame faults put on the bus this tick: (id, data, is_error)."""
        out: list[tuple[int, bytes, bool]] = []
        for fault in self.faults:
            if not fault.active(t):
                continue
            if fault.kind == "flood":
                count = max(1, round(fault.param * dt * 1000.0))
                out.extend((int(fault.target, 0), bytes(8), False) for _ in range(count))
            elif fault.kind == "error_frame":
                out.append((0, b"", True))
        return out

    def apply(self, t: float, frame_id: int, data: bytes) -> list[tuple[float, bytes]]:
        """The frames that go on the bus instead of `data`, each with its delay (0: now), s."""
        codec = self.codebook.by_id.get(frame_id)
        if codec is None:
            return [(0.0, data)]
        frames = [data]
        delay = 0.0
        for fault in self.faults:
            if not fault.active(t):
                continue
            kind = fault.kind
            if kind in NODE_KINDS:
                if fault.target in codec.senders:
                    return []
                continue
            if kind == "flood":
                if fault.param >= FLOOD_SATURATION and frame_id > int(fault.target, 0):
                    return []
                continue
            if kind not in FRAME_KINDS or fault.target != codec.name:
                continue
            if kind == "drop":
                return []
            if kind == "delay":
                delay = fault.param
                continue
            if kind == "duplicate":
                frames = frames + frames
                continue
            frames = [self._corrupt(fault, frame_id, bytearray(f)) for f in frames]
        return [(delay, f) for f in frames]

    def _corrupt(self, fault: Fault, frame_id: int, data: bytearray) -> bytes:
        kind = fault.kind
        if kind == "bitflip":
            bit = int(fault.param)
            data[bit // 8] ^= 1 << (bit % 8)
        elif kind in ("counter_freeze", "counter_jump"):
            counter = e2e.counter_of(data)
            if kind == "counter_freeze":
                if fault.frozen is None:
                    fault.frozen = counter
                counter = fault.frozen
            else:
                counter = (counter + int(fault.param)) % e2e.COUNTER_MODULO
            e2e.protect(frame_id, data, counter)          # a correct checksum over the wrong counter
        elif kind == "checksum_value":
            data[e2e.CHECKSUM_BYTE] = int(fault.param) & 0xFF
        elif kind == "checksum_freeze":
            if fault.frozen is None:
                fault.frozen = data[e2e.CHECKSUM_BYTE]
            data[e2e.CHECKSUM_BYTE] = fault.frozen
        elif kind == "checksum_random":
            data[e2e.CHECKSUM_BYTE] = self._rng.randrange(256)
        elif kind == "checksum_offset":
            data[e2e.CHECKSUM_BYTE] = (data[e2e.CHECKSUM_BYTE] + int(fault.param)) & 0xFF
        return bytes(data)
