"""The run log's format in one place: its topics, schemas and the JSON text of its records.

Why MCAP with JSON messages and JSON schemas: Foxglove shows them without plugins (Raw Messages, Plot, Log
panels), and JSON keeps the log pure Python. Channels:

- `/can/frames`: every raw frame (`bench.CanFrame`, ROS `can_msgs/Frame` fields plus bench fields);
- `/can/decoded/<Message>`: the decoded signals of each DBC message (numbers; a non-finite value is null);
- `/bench/steps`: test steps and verdicts as `foxglove.Log`;
- `/diag/<Message>`: each whole diagnostic message (UDS on ISO-TP) whose frames are the DBC message's, reassembled
  and described in a line (`bench.DiagMessage`, bench.log.diaglog); a channel appears with its first message;
- metadata `bench.sim.clock` (`origin_ns`: the log time of bench time 0) and `bench` (who wrote the log).

The writer (bench.log.recorder) builds the records from the templates below, the reader (bench.log.logread)
parses them; a frame's text is %-formatted rather than built by the json module because most frames of a run
repeat an earlier one and the tail of its text is kept (docs/performance.md, issue 18).
"""

from __future__ import annotations

import json
from typing import Any

import cantools

from bench import canid

FRAMES_TOPIC = "/can/frames"
CLOCK_METADATA = "bench.clock"   # origin_ns: the log time of bench time 0
BENCH_METADATA = "bench"         # profile, host, python, bench version, attachments, compression
COUNTS_METADATA = "bench.counts"  # invalid_frames: written at close, so that a summary needs no frame read
STEPS_TOPIC = "/bench/steps"
DECODED_PREFIX = "/can/decoded/"
DIAG_PREFIX = "/diag/"
DIAG_SCHEMA_NAME = "bench.DiagMessage"
FRAME_SCHEMA_NAME = "bench.CanFrame"
LOG_SCHEMA_NAME = "foxglove.Log"
ENCODING = "json"                # the message encoding of every channel
SCHEMA_ENCODING = "jsonschema"
LIBRARY = "chassis-hil-bench"    # the header's library, followed by "/" and the bench's version
MAGIC = b"\x89MCAP0\r\n"         # MCAP's magic, at the start and (of a closed file) the end
MAX_DATA = 64  # CAN FD

MAX_T = 1.8e10  # s: log times are uint64 ns (~584 years)
EXACT_T = 2.0 ** 22  # s: below it t * 1e9 < 2**53, an exact float product

# A frame record: FRAME_HEAD % (sec, nsec, tail), the tail FRAME_TAIL % (frame_id, id, is_rtr, is_extended,
# is_error, dlc, data, channel, direction, valid, error, extra_fields(...)); FRAME_JSON is the whole as one format.
DECIMAL = [str(i) for i in range(256)]
PAD = [bytes(8 - n) for n in range(8)]
FRAME_HEAD = b'{"header":{"stamp":{"sec":%d,"nsec":%d},%b'   # a frame record: its stamp, then its tail
FRAME_TAIL = (
    '"frame_id":%s},"id":%d,"is_rtr":%s,"is_extended":%s,'
    '"is_error":%s,"dlc":%d,"data":[%s],"channel":%s,"direction":"%s","valid":%s,"error":%s%s}'
)
FRAME_JSON = FRAME_HEAD.decode().replace("%b", "") + FRAME_TAIL   # the whole record as one %-format
VALID_TRUE, VALID_FALSE = b'"valid":true', b'"valid":false'   # as the compact text of a frame record holds them

TIME_SCHEMA: dict[str, Any] = {
    "type": "object",
    "title": "Time",
    "properties": {
        "sec": {"type": "integer", "minimum": 0},
        "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999},
    },
}
BOOL_SCHEMA = {"type": "boolean"}
FRAME_SCHEMA: dict[str, Any] = {
    "title": FRAME_SCHEMA_NAME,
    "description": "A raw CAN frame seen (rx) or sent (tx) by the bench: ROS can_msgs/Frame fields plus bench fields",
    "type": "object",
    "properties": {
        "header": {
            "type": "object",
            "properties": {"stamp": TIME_SCHEMA, "frame_id": {"type": "string", "description": "Bus channel"}},
        },
        "id": {"type": "integer", "minimum": 0, "maximum": 0x1FFFFFFF, "description": "Arbitration id, no flag bits"},
        "is_rtr": BOOL_SCHEMA,
        "is_extended": BOOL_SCHEMA,
        "is_error": BOOL_SCHEMA,
        "dlc": {"type": "integer", "minimum": 0, "maximum": MAX_DATA,
                "description": "Number of data bytes; of a remote frame, the length it requests"},
        "data": {
            "type": "array",
            "items": {"type": "integer", "minimum": 0, "maximum": 255},
            "minItems": 8,
            "maxItems": MAX_DATA,
            "description": "Payload, padded with zeros to 8 bytes; dlc is the frame's length",
        },
        "channel": {"type": "string", "description": "Bus channel"},
        "direction": {"type": "string", "enum": ["rx", "tx"]},
        "valid": {"type": "boolean",
                  "description": "False when the bench did not apply the frame for a fault of its sender (its "
                                 "length, its E2E status or state, a value out of range: see error). True also for "
                                 "a frame not applied for no fault of its sender: the first frame a receiver judges "
                                 "and one in sequence while the E2E state machine is still INIT (docs/spec/e2e.md)"},
        "error": {"type": "string", "description": "Why the frame is invalid (status and state); empty when valid"},
        # Written only when true (or set): a classic frame's record stays as it was.
        "is_fd": {"type": "boolean", "description": "CAN FD frame (absent: FD when more than 8 data bytes)"},
        "bitrate_switch": {"type": "boolean", "description": "CAN FD: data phase at the higher bit rate (BRS)"},
        "error_state_indicator": {"type": "boolean", "description": "CAN FD: sender error-passive (ESI)"},
        "channel_number": {"type": "integer", "description": "The channel when the bus named it by a number "
                           "(python-can); channel is then its decimal text"},
    },
    "required": ["header", "id", "is_rtr", "is_extended", "is_error", "dlc", "data", "channel", "direction", "valid",
                 "error"],
}
# The shape of Foxglove's published foxglove.Log JSON schema, so the Log panel shows the steps.
LOG_SCHEMA: dict[str, Any] = {
    "title": LOG_SCHEMA_NAME,
    "description": "A log message",
    "type": "object",
    "properties": {
        "timestamp": {**TIME_SCHEMA, "description": "Timestamp of log message"},
        "level": {
            "title": "LogLevel: Log level",
            "description": "Log level",
            "oneOf": [
                {"title": title, "const": value}
                for value, title in enumerate(("UNKNOWN", "DEBUG", "INFO", "WARNING", "ERROR", "FATAL"))
            ],
        },
        "message": {"type": "string", "description": "Log message"},
        "name": {"type": "string", "description": "Process or node name"},
        "file": {"type": "string", "description": "Filename"},
        "line": {"type": "integer", "minimum": 0, "description": "Line number in the file"},
    },
}


TEXT_SCHEMA = {"type": "string"}
DIAG_SCHEMA: dict[str, Any] = {
    "title": DIAG_SCHEMA_NAME,
    "description": "A whole diagnostic message (UDS on ISO-TP) as a bus observer reassembles it from the frames of "
                   "one DBC message; log time: the frame that completed it",
    "type": "object",
    "properties": {
        "node": {**TEXT_SCHEMA, "description": "The node whose connection it is; empty for a functional request"},
        "direction": {"type": "string", "enum": ["request", "response", "functional"]},
        "service": {**TEXT_SCHEMA, "description": "UDS service (of a negative response: the refused one)"},
        "text": {**TEXT_SCHEMA, "description": "The message in one line: sub-function, NRC and DTCs by name"},
        "data": {**TEXT_SCHEMA, "description": "The payload in hex, e.g. 19 02 FF"},
        "length": {"type": "integer", "minimum": 1, "description": "Payload bytes (the ISO-TP length)"},
    },
    "required": ["node", "direction", "service", "text", "data", "length"],
}


def message_schema(message: cantools.database.can.Message) -> dict[str, Any]:
    """The JSON schema of a decoded DBC message: one number per signal, described from the DBC."""
    properties: dict[str, Any] = {}
    for signal in message.signals:
        parts = [signal.comment or signal.name]
        if signal.unit:
            parts.append(f"[{signal.unit}]")
        if signal.choices:
            parts.append("choices: " + ", ".join(f"{value} = {name}" for value, name in signal.choices.items()))
        properties[signal.name] = {"type": "number", "description": " ".join(parts)}
    about = f"{message.comment}; " if message.comment else ""
    ident = canid.text(canid.of(message.frame_id, message.is_extended_frame))
    return {
        "title": message.name,
        "description": f"{about}CAN id {ident}, decoded by the bench; null marks a non-finite value",
        "type": "object",
        "properties": properties,
    }


def decoded_template(names: tuple[str, ...]) -> str:
    """A decoded record as one %-format of its values (each %r) in this order: the JSON the json module writes
    for int and float values (repr of an int or a float is its JSON; a non-finite float's repr, nan or inf,
    is not JSON, and adds an "n" to the text: the writer counts them to notice)."""
    return "{" + ",".join(json.dumps(name).replace("%", "%%") + ":%r" for name in names) + "}"


def step_text(ns: int, level: int, name: str, message: str, file: str, line: int) -> str:
    """A step record: foxglove.Log's fields as JSON."""
    return json.dumps({
        "timestamp": {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}, "level": int(level),
        "message": str(message), "name": str(name), "file": str(file), "line": line,
    }, separators=(",", ":"))


def log_ns(t: float) -> int:
    """Bench time (s) to integer ns, rounded: log_time is a uint64, so reject what does not fit."""
    if not 0.0 <= t <= MAX_T:  # also false for NaN
        raise ValueError(f"time {t!r} s is not in [0, {MAX_T:g}]")
    if t < EXACT_T:
        return int(t * 1e9 + 0.5)
    seconds = int(t)    # wall-clock times: t * 1e9 is past 2**53, so split off the exact fraction first
    return seconds * 1_000_000_000 + int((t - seconds) * 1e9 + 0.5)



def extra_fields(is_fd: bool, bitrate_switch: bool, error_state_indicator: bool, channel_number: int | None) -> str:
    """The optional fields of a frame record (CAN FD flags, a numbered channel), each only when set."""
    extra = ""
    if is_fd:
        extra += ',"is_fd":true'
    if bitrate_switch:
        extra += ',"bitrate_switch":true'
    if error_state_indicator:
        extra += ',"error_state_indicator":true'
    if channel_number is not None:
        if isinstance(channel_number, bool) or not isinstance(channel_number, int):
            raise ValueError(f"channel number {channel_number!r} is not an int")
        extra += f',"channel_number":{channel_number}'
    return extra

