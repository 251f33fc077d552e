"""The fault kinds: what each does to frames, what its TARGET and PARAM are, and how they are checked.

One class per kind, registered in the one table `KINDS` at the end of this module. Everything else is
derived from that table: parsing and checking `--fault` specs and applying them (bench/faults/plan.py), the
`--fault` help of the command line (`help_text`) and the table in docs/reliability.md (`markdown_table`;
`python -m bench.faults.kinds docs/reliability.md` rewrites it, tests/bench/faults/test_faults.py checks it). Adding a
kind = one class here and one entry in `KINDS` (docs/architecture.md "Adding a fault kind").

Faults act on the frames a station sends, after the restbus built them (so they look like a real broken
sender: a wrong counter carries a correct checksum unless the checksum is the fault).
"""

from __future__ import annotations

import random
import re
import sys
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, ClassVar

from bench import canid
from bench.database.codec import Codebook, MessageCodec
from bench.e2e import Protection
from bench.errors import did_you_mean

if TYPE_CHECKING:
    from bench.faults.plan import Fault

#: Babbling frames per ms from which lower-priority frames never win arbitration (500 kbit/s carries about
#: 4.3 eight-byte frames per ms). The virtual-time bus has no arbitration: `flood` models it.
FLOOD_SATURATION = 4.0
#: The most frames per ms a flood may send: about what a classic CAN bus at 500 kbit/s carries at most (a frame
#: without data is 47 bits with its intermission, 10.6 per ms; an eight-byte one 111 to 135 bits, 3.7 to 4.5 per
#: ms). A higher RATE asks for more than the bus carries, and its frames per tick only cost memory and time
#: (issue 27: `flood:0x000:1e9` built 10^9 frames per 1 ms tick, 7.9 GB, and ignored Ctrl-C while it did).
FLOOD_MAX_RATE = 8.0

# What TARGET names (the word shown in specs, help and docs).
MESSAGE, NODE, IDENTIFIER, BUS = "MESSAGE", "NODE", "IDENTIFIER", "BUS"


@dataclass
class Outgoing:
    """The frames that go on the bus instead of one sent frame; the active kinds change it in turn."""

    frame_id: int
    frames: list[bytes]
    rng: random.Random
    protection: Protection | None = None   # the message's E2E protection (what counter and CRC kinds act on)
    delay: float = 0.0                   # s, 0: now
    dropped: bool = False                # no frame goes on the bus


class FaultKind:
    """One kind of fault. Subclasses set the class attributes and override what the kind does."""

    name: ClassVar[str]
    target: ClassVar[str] = MESSAGE      # MESSAGE, NODE, IDENTIFIER or BUS
    param: ClassVar[str] = ""            # PARAM's name in the spec pattern, e.g. SECONDS ("" = none)
    param_doc: ClassVar[str] = ""        # its unit and range
    summary: ClassVar[str]               # what the kind does, one line (help and docs)

    def check_param(self, value: float, codec: MessageCodec | None = None) -> str | None:
        """Why PARAM does not fit this kind (None: it fits); `codec`: the target message, when it is one."""
        return None

    def check_target(self, target: str, codebook: Codebook) -> str | None:
        """Why TARGET does not fit this kind and the databases (None: it fits)."""
        if self.target == MESSAGE and target not in codebook.by_name:
            return f"unknown message {target!r}{did_you_mean(target, codebook.by_name)} (in none of the databases)"
        if self.target == NODE and target not in codebook.nodes:
            return f"unknown node {target!r}{did_you_mean(target, codebook.nodes)} (nodes: {', '.join(codebook.nodes)})"
        if self.target == IDENTIFIER:
            try:
                canid.parse(target)
            except ValueError:
                return ("TARGET must be an identifier like 0x000 (11-bit) or 0x18FEF100 (29-bit: above 0x7FF or "
                        "eight hex digits)")
        return None

    def check_reach(self, target: str, codebook: Codebook, simulated: frozenset[str]) -> str | None:
        """Why a process that simulates the nodes `simulated` cannot inject this fault (None: it can): a fault
        changes only frames the bench sends, so a message's sender or the node must be one of them."""
        why = f"(this process simulates {', '.join(sorted(simulated)) or 'nothing'}; a fault changes only frames " \
              f"the bench sends)"
        if self.target == MESSAGE:
            senders = codebook.by_name[target].senders
            if not set(senders) & simulated:
                sent_by = " / ".join(senders) or "no node"
                return f"{target} is sent by {sent_by}, which the bench does not simulate {why}"
        if self.target == NODE and target not in simulated:
            return f"{target} is a node the bench does not simulate {why}"
        return None

    def applies(self, fault: Fault, frame_id: int, codec: MessageCodec) -> bool:
        """Whether the fault acts on this frame of the message `codec` (it then counts the frame)."""
        return self.target == MESSAGE and fault.target == codec.name

    def act(self, fault: Fault, out: Outgoing) -> None:
        """Change the outgoing frames (only called when `applies`)."""

    def babble(self, fault: Fault, dt: float) -> list[tuple[int, bytes]]:
        """Frames the fault itself puts on the bus in a tick of `dt` s: (frame_id, data), bench.canid."""
        return []

    def spec(self) -> str:
        """The spec pattern of this kind, e.g. `delay:MESSAGE:SECONDS`."""
        param = f":{self.param}" if self.param else ""
        return f"{self.name}:{self.target}{param}"


class _Corruption(FaultKind):
    """A kind that changes the bytes of every outgoing frame."""

    def act(self, fault: Fault, out: Outgoing) -> None:
        out.frames = [self.corrupt(fault, out, bytearray(frame)) for frame in out.frames]

    def corrupt(self, fault: Fault, out: Outgoing, data: bytearray) -> bytes:
        raise NotImplementedError


class _E2ECorruption(_Corruption):
    """A kind that acts on the E2E counter or CRC field of a protected message, as its profile places them."""

    def check_target(self, target: str, codebook: Codebook) -> str | None:
        problem = super().check_target(target, codebook)
        if problem is None and codebook.by_name[target].protection is None:
            return f"{target} is not E2E-protected: {self.name} acts on its profile's counter or CRC"
        return problem

    def act(self, fault: Fault, out: Outgoing) -> None:
        if out.protection is not None:
            super().act(fault, out)

    @staticmethod
    def protection(out: Outgoing) -> Protection:
        assert out.protection is not None   # act() runs only for a protected message
        return out.protection


# -- frame kinds (TARGET: a message) --------------------------------------------------------------------
class Drop(FaultKind):
    name, summary = "drop", "the message's frames are not sent"

    def act(self, fault: Fault, out: Outgoing) -> None:
        out.dropped = True


class Delay(FaultKind):
    name, param, param_doc = "delay", "SECONDS", "s, > 0"
    summary = "the message's frames are sent SECONDS late"

    def check_param(self, value: float, codec: MessageCodec | None = None) -> str | None:
        return None if value > 0 else "a delay needs PARAM > 0 s"

    def act(self, fault: Fault, out: Outgoing) -> None:
        out.delay = fault.param


class Duplicate(FaultKind):
    name, summary = "duplicate", "every frame of the message is sent twice"

    def act(self, fault: Fault, out: Outgoing) -> None:
        out.frames = out.frames + out.frames


class Bitflip(_Corruption):
    name, param, param_doc = "bitflip", "BIT", "0..63 (a CAN FD frame: up to 8 × its length - 1)"
    summary = "bit BIT of the payload is inverted (bit BIT % 8 of byte BIT // 8)"

    def check_param(self, value: float, codec: MessageCodec | None = None) -> str | None:
        bits = 8 * (codec.length if codec is not None else 64)
        if 0 <= value < bits and value == int(value):
            return None
        return f"bit index must be 0..{bits - 1}" + (f" ({codec.name} has {codec.length} bytes)" if codec else "")

    def corrupt(self, fault: Fault, out: Outgoing, data: bytearray) -> bytes:
        bit = int(fault.param)
        data[bit // 8] ^= 1 << (bit % 8)
        return bytes(data)


class CounterFreeze(_E2ECorruption):
    name, summary = "counter_freeze", "the E2E counter keeps its value at the fault's start (CRC right)"

    def corrupt(self, fault: Fault, out: Outgoing, data: bytearray) -> bytes:
        protection = self.protection(out)
        if fault.frozen is None:
            fault.frozen = protection.counter_of(data)
        protection.protect(data, fault.frozen)      # a correct CRC over the wrong counter
        return bytes(data)


class CounterJump(_E2ECorruption):
    name, param, param_doc = "counter_jump", "STEP", "counter values"
    summary = "the E2E counter is STEP ahead (modulo its profile's range; CRC right)"

    def corrupt(self, fault: Fault, out: Outgoing, data: bytearray) -> bytes:
        protection = self.protection(out)
        protection.protect(data, protection.counter_of(data) + int(fault.param))   # a correct CRC, wrong counter
        return bytes(data)


class ChecksumValue(_E2ECorruption):
    name, param, param_doc = "checksum_value", "VALUE", "0..255 (P05: 0..65535)"
    summary = "the E2E CRC is VALUE"

    def corrupt(self, fault: Fault, out: Outgoing, data: bytearray) -> bytes:
        self.protection(out).set_checksum(data, int(fault.param))
        return bytes(data)


class ChecksumFreeze(_E2ECorruption):
    name, summary = "checksum_freeze", "the E2E CRC keeps its value at the fault's start"

    def corrupt(self, fault: Fault, out: Outgoing, data: bytearray) -> bytes:
        protection = self.protection(out)
        if fault.frozen is None:
            fault.frozen = protection.checksum_of(data)
        protection.set_checksum(data, fault.frozen)
        return bytes(data)


class ChecksumRandom(_E2ECorruption):
    name, summary = "checksum_random", "the E2E CRC is a random number (the same sequence on every run)"

    def corrupt(self, fault: Fault, out: Outgoing, data: bytearray) -> bytes:
        protection = self.protection(out)
        protection.set_checksum(data, out.rng.randrange(1 << protection.crc.length))
        return bytes(data)


class ChecksumOffset(_E2ECorruption):
    name, param, param_doc = "checksum_offset", "OFFSET", "added modulo the CRC's range"
    summary = "OFFSET is added to the E2E CRC the sender computed"

    def corrupt(self, fault: Fault, out: Outgoing, data: bytearray) -> bytes:
        protection = self.protection(out)
        protection.set_checksum(data, protection.checksum_of(data) + int(fault.param))
        return bytes(data)


# -- node kinds (TARGET: a node) -------------------------------------------------------------------------
class Silence(FaultKind):
    name, target, summary = "silence", NODE, "the node sends nothing"

    def applies(self, fault: Fault, frame_id: int, codec: MessageCodec) -> bool:
        return fault.target in codec.senders

    def act(self, fault: Fault, out: Outgoing) -> None:
        out.dropped = True


class BusOff(Silence):
    name, summary = "bus_off", "the node is bus-off: it sends nothing"


# -- bus kinds ---------------------------------------------------------------------------------------------
class Flood(FaultKind):
    name, target, param = "flood", IDENTIFIER, "RATE"
    param_doc = f"frames per ms, > 0 and at most {FLOOD_MAX_RATE:g}: a classic CAN bus at 500 kbit/s carries about that"
    summary = (f"a babbling node sends RATE all-zero frames per ms at IDENTIFIER (e.g. 0x000); from "
               f"{FLOOD_SATURATION:g} per ms on, every frame of a lower priority (higher identifier) is lost")

    def check_param(self, value: float, codec: MessageCodec | None = None) -> str | None:
        if value > FLOOD_MAX_RATE:
            return (f"RATE is frames per ms, at most {FLOOD_MAX_RATE:g} (about what a classic CAN bus at 500 kbit/s "
                    f"carries), not {value:g}")
        return None if value > 0 else "PARAM must be frames per ms > 0"

    def applies(self, fault: Fault, frame_id: int, codec: MessageCodec) -> bool:
        # No arbitration on the virtual-time bus: a saturating flood wins against every lower priority.
        return fault.param >= FLOOD_SATURATION and canid.priority(frame_id) > canid.priority(canid.parse(fault.target))

    def act(self, fault: Fault, out: Outgoing) -> None:
        out.dropped = True

    def babble(self, fault: Fault, dt: float) -> list[tuple[int, bytes]]:
        count = max(1, round(fault.param * dt * 1000.0))
        frame = (canid.parse(fault.target), bytes(8))
        return [frame] * count


class ErrorFrame(FaultKind):
    name, target, summary = "error_frame", BUS, "an error frame on the bus every tick (TARGET: any word, e.g. bus)"

    def applies(self, fault: Fault, frame_id: int, codec: MessageCodec) -> bool:
        return False

    def babble(self, fault: Fault, dt: float) -> list[tuple[int, bytes]]:
        return [(canid.ERR, b"")]


def _table(*kinds: FaultKind) -> Mapping[str, FaultKind]:
    table = {kind.name: kind for kind in kinds}
    assert len(table) == len(kinds), "two fault kinds with one name"
    return table


#: THE registry: kind name -> kind. Its order is the order of the help and the docs.
KINDS: Mapping[str, FaultKind] = _table(
    Drop(), Delay(), Duplicate(), Bitflip(), CounterFreeze(), CounterJump(), ChecksumValue(), ChecksumFreeze(),
    ChecksumRandom(), ChecksumOffset(), Silence(), BusOff(), Flood(), ErrorFrame())


def kinds_with_target(target: str) -> tuple[str, ...]:
    return tuple(name for name, kind in KINDS.items() if kind.target == target)


def help_text() -> str:
    """The kinds for `--fault`'s help: each spec pattern with its PARAM's unit and range, one line."""
    return "kinds: " + ", ".join(kind.spec() + (f" ({kind.param}: {kind.param_doc})" if kind.param else "")
                                 for kind in KINDS.values())


DOC_BEGIN = "<!-- fault kinds: generated from bench/faults/kinds.py by `python -m bench.faults.kinds FILE` -->"
DOC_END = "<!-- end of fault kinds -->"


def markdown_table() -> str:
    """The kinds as the markdown table of docs/reliability.md (between DOC_BEGIN and DOC_END)."""
    rows = ["| kind | TARGET | PARAM | what it does |", "|---|---|---|---|"]
    for kind in KINDS.values():
        param = f"{kind.param} ({kind.param_doc})" if kind.param else "–"
        rows.append(f"| `{kind.name}` | {kind.target} | {param} | {kind.summary} |")
    return "\n".join(rows)


_BLOCK = re.compile(re.escape(DOC_BEGIN) + r"\n.*?\n" + re.escape(DOC_END), re.S)


def documented_table(text: str) -> str | None:
    """The generated table as it stands in a document (None: the document has no such block)."""
    found = _BLOCK.search(text)
    return None if found is None else found.group(0)[len(DOC_BEGIN) + 1:-len(DOC_END) - 1]


def rewrite(path: Path) -> bool:
    """Replace the block in `path` by the registry's table; True when the file changed."""
    text = path.read_text(encoding="utf-8")
    if documented_table(text) is None:
        raise SystemExit(f"{path}: no block {DOC_BEGIN!r} ... {DOC_END!r}")
    new = _BLOCK.sub(lambda _: f"{DOC_BEGIN}\n{markdown_table()}\n{DOC_END}", text)
    if new != text:
        path.write_text(new, encoding="utf-8")
    return new != text


def main(argv: list[str]) -> int:
    """`python -m bench.faults.kinds [FILE ...]`: print the table, or rewrite it in each FILE."""
    if not argv:
        print(markdown_table())
    for name in argv:
        print(f"{name}: {'rewritten' if rewrite(Path(name)) else 'up to date'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
