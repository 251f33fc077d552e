"""The run log's writer: one MCAP file per run, openable as is in Foxglove (format: bench.log.format).

JSON keeps the recorder pure Python yet fast enough for a busy bus (>= 20 000 frames/s, each with its decoded
message): the records are written through mcap's public `Writer`, and through bench.log.mcapfast's packing into
that writer when the installed mcap is one it was checked against (the same bytes).

Chunks are zstd-compressed (mcap's default, and the best ratio for JSON) and finalised at least
every `flush_interval` s of wall time (checked on every write; `math.inf`: only by `flush()`) or
when `chunk_size` bytes are pending; the file is flushed to the OS after each, so a run killed with SIGKILL leaves a log
readable up to its last chunk (`bench.log.logread` reads such a file). The DBC files are attached
at open, so even a log killed early says which databases it was recorded with.
"""

from __future__ import annotations

import atexit
import bisect
import json
import math
import mimetypes
import os
import platform
import threading
import time
from collections.abc import Iterable, Mapping, Sequence
from datetime import UTC, datetime
from io import BufferedIOBase
from pathlib import Path
from types import TracebackType
from typing import IO, Any, Protocol, SupportsFloat, cast

import cantools
from cantools.database.namedsignalvalue import NamedSignalValue
from mcap.writer import CompressionType, Writer

from bench import canid
from bench import version as bench_version
from bench.errors import BenchError, LogError
from bench.log import mcapfast
from bench.log.format import (
    BENCH_METADATA,
    CLOCK_METADATA,
    COUNTS_METADATA,
    DECIMAL,
    DECODED_PREFIX,
    DIAG_PREFIX,
    DIAG_SCHEMA,
    DIAG_SCHEMA_NAME,
    ENCODING,
    EXACT_T,
    FRAME_HEAD,
    FRAME_SCHEMA,
    FRAME_SCHEMA_NAME,
    FRAME_TAIL,
    FRAMES_TOPIC,
    LIBRARY,
    LOG_SCHEMA,
    LOG_SCHEMA_NAME,
    MAX_DATA,
    PAD,
    SCHEMA_ENCODING,
    STEPS_TOPIC,
    decoded_template,
    extra_fields,
    log_ns,
    message_schema,
    step_text,
)
from bench.log.mcapfast import RECORD_OVERHEAD, record_ends, records_size

COMPRESSION = CompressionType.ZSTD
CHUNK_BYTES = 1 << 20

_TEXT_CACHE = 1 << 14   # distinct frames whose record texts `Recorder.frames` keeps (then it starts again)
_PLAIN_NUMBERS = frozenset((int, float))
_ENCODER = json.JSONEncoder(allow_nan=False, separators=(",", ":"), default=lambda o: o.value)
_PLAIN_ENCODER = json.JSONEncoder(allow_nan=False, separators=(",", ":"))   # one, not one per call of json.dumps


class Decoder(Protocol):
    """What `Recorder.frames` needs of a message's codec (bench.database.codec.MessageCodec is one)."""

    @property
    def name(self) -> str: ...

    def decode(self, data: bytes) -> Mapping[str, float | int | str]: ...


def _number(value: object, choices: Mapping[str, int]) -> int | float | None:
    """A signal value as a JSON number: choice names to their value, non-finite floats to None."""
    if isinstance(value, NamedSignalValue):
        value = value.value
    elif isinstance(value, str):
        if value not in choices:
            raise ValueError(f"{value!r} is neither a number nor one of the signal's choices")
        return choices[value]
    if isinstance(value, int):
        return int(value)  # also makes bools numbers
    if isinstance(value, float):
        number = value
    elif isinstance(value, SupportsFloat):   # numpy scalars, Decimal ...
        number = float(value)
    else:
        raise TypeError(f"a {type(value).__name__} is not a number")
    return number if math.isfinite(number) else None


def _finalise_chunk(writer: Writer, file: IO[bytes]) -> None:
    """Write the open chunk and hand the file's buffer to the OS, so SIGKILL cannot lose it."""
    writer.flush()  # type: ignore[no-untyped-call]   # mcap's Writer.flush carries no annotations
    file.flush()


class _Decoded:
    """What `Recorder.decoded` needs of one message, looked up once per call."""

    __slots__ = ("channel_id", "names", "choices", "schema", "order", "template", "letters")

    def __init__(self, message: cantools.database.can.Message) -> None:
        self.channel_id = 0
        self.names = frozenset(signal.name for signal in message.signals)
        # The fast path of `decoded`: every signal in DBC order, each an int or float, from one %-format (a
        # non-finite value adds an "n" to the text and sends the values the careful way).
        self.order = tuple(signal.name for signal in message.signals)
        self.template = decoded_template(self.order)
        self.letters = self.template.count("n")
        self.choices = {
            signal.name: {str(name): int(value) for value, name in (signal.choices or {}).items()}
            for signal in message.signals
        }
        self.schema = json.dumps(message_schema(message), indent=1).encode()


class Recorder:
    """Writes one run's MCAP log. Thread-safe; `close()` is idempotent and may run from atexit or a signal handler."""

    def __init__(
        self,
        path: Path | IO[bytes] | BufferedIOBase,
        databases: Sequence[cantools.database.can.Database],
        attachments: Sequence[Path] = (),
        *,
        flush_interval: float = 0.5,
        profile: str = "",
        chunk_size: int = CHUNK_BYTES,
    ) -> None:
        if not flush_interval > 0:
            raise LogError(f"run log {path}: flush interval must be > 0 s, not {flush_interval!r}")
        stream: IO[bytes] | None = None
        if isinstance(path, (str, os.PathLike)):
            self.path = Path(path)
        else:   # a binary file object (python-can's writers hand over theirs)
            stream = cast("IO[bytes]", path)
            self.path = Path(str(getattr(stream, "name", "<stream>")))
        self._interval = float(flush_interval)
        self._origin_ns = 0   # log time of bench time 0 (set_origin); 0: log times are bench times
        self._chunk_bytes = int(chunk_size)
        # Everything that can fail on bad input happens before the file exists.
        self._decoded: dict[str, _Decoded] = {}
        for database in databases:
            for message in database.messages:
                entry = _Decoded(message)
                known = self._decoded.setdefault(message.name, entry)
                if known.schema != entry.schema:
                    raise LogError(f"run log {path}: message {message.name} differs between two databases")
        blobs: list[tuple[Path, bytes, int]] = []
        for attachment in map(Path, attachments):
            try:
                blobs.append((attachment, attachment.read_bytes(), attachment.stat().st_mtime_ns))
            except OSError as exc:
                raise LogError(f"run log {path}: cannot attach {attachment}: {exc.strerror}") from None
        try:
            self._file: IO[bytes] = stream if stream is not None else open(self.path, "wb")  # noqa: SIM115 - closed by close()
        except OSError as exc:
            raise LogError(f"run log {path}: cannot create: {exc.strerror}") from None

        try:
            self._start(blobs, profile)
        except BaseException as exc:
            self._file.close()
            if isinstance(exc, OSError):
                raise LogError(f"run log {path}: cannot write: {exc.strerror}") from None
            raise

        self._quoted: dict[str, str] = {}  # channel name -> its JSON string
        self._diag_channels: dict[str, int] = {}   # message -> its `/diag/` channel, made with its first record
        self._diag_schema = 0
        self._texts: dict[tuple[int, bytes, str, bool, str, str], tuple[bytes, int, bytes | None, str]] = {}
        self._lock = threading.RLock()
        self._busy = False  # a write is under way on the thread holding the lock
        self._broken = False  # a write was interrupted: the open chunk may be garbage, later writes are dropped
        self._closed = False
        self._close_pending = False
        self._pending = 0
        self._invalid = 0     # invalid frames written: COUNTS_METADATA at close
        self._deadline = time.monotonic() + self._interval
        atexit.register(self.close)

    def frame(
        self, t: float, arbitration_id: int, data: bytes, *, channel: str, direction: str,
        is_extended: bool = False, is_error: bool = False, is_remote: bool = False, valid: bool = True, error: str = "",
        is_fd: bool = False, bitrate_switch: bool = False, error_state_indicator: bool = False, dlc: int | None = None,
        channel_number: int | None = None,
    ) -> None:
        """Log one raw frame on `/can/frames` (bad input raises LogError and writes nothing).

        `dlc`, a remote frame's requested length: its record then carries that many zero bytes (else
        `data` as given); `channel_number`, the channel when the bus named it by a number (python-can's
        int channels), so a reader gets it back."""
        try:
            ns = log_ns(t) + self._origin_ns
        except (TypeError, ValueError) as exc:
            raise LogError(f"run log {self.path}: bad frame {arbitration_id!r} on {channel!r}: {exc}") from None
        tail = self._frame_tail(arbitration_id, data, channel, direction, is_extended, is_error, is_remote, valid,
                                error, is_fd, bitrate_switch, error_state_indicator, dlc, channel_number)
        self._write(self._frames_id, ns, FRAME_HEAD % (ns // 1_000_000_000, ns % 1_000_000_000, tail))
        if not valid:
            self._invalid += 1

    def _frame_tail(
        self, arbitration_id: int, data: bytes, channel: str, direction: str, is_extended: bool, is_error: bool,
        is_remote: bool, valid: bool, error: str, is_fd: bool, bitrate_switch: bool, error_state_indicator: bool,
        dlc: int | None, channel_number: int | None,
    ) -> bytes:
        """A frame record's bytes after its time stamp (they depend on the frame only, not on its time)."""
        try:
            quoted = self._quoted.get(channel)
            if quoted is None:
                if not isinstance(channel, str):
                    raise TypeError(f"channel must be a str, not {type(channel).__name__}")
                quoted = self._quoted[channel] = json.dumps(channel)
            if direction != "rx" and direction != "tx":
                raise ValueError(f"direction must be 'rx' or 'tx', not {direction!r}")
            if not isinstance(arbitration_id, int) or not 0 <= arbitration_id <= 0x1FFFFFFF:
                raise ValueError(f"arbitration id {arbitration_id!r} is not an int in [0, 0x1FFFFFFF]")
            if is_remote and dlc is not None:
                if not isinstance(dlc, int) or not 0 <= dlc <= MAX_DATA:
                    raise ValueError(f"dlc {dlc!r} is not an int in [0, {MAX_DATA}]")
                data = bytes(dlc)   # a remote frame has no payload; its length is what it asks for
            data = bytes(data)
            size = len(data)
            if size < 8:
                data += PAD[size]
            elif size > MAX_DATA:
                raise ValueError(f"{size} data bytes, at most {MAX_DATA}")
            extra = ""
            if is_fd or bitrate_switch or error_state_indicator or channel_number is not None:
                extra = extra_fields(is_fd, bitrate_switch, error_state_indicator, channel_number)
            return (FRAME_TAIL % (
                quoted, arbitration_id,
                "true" if is_remote else "false", "true" if is_extended else "false", "true" if is_error else "false",
                size, ",".join([DECIMAL[b] for b in data]), quoted, direction,
                "true" if valid else "false", json.dumps(str(error)) if error else '""', extra,
            )).encode()
        except (TypeError, ValueError) as exc:
            raise LogError(f"run log {self.path}: bad frame {arbitration_id!r} on {channel!r}: {exc}") from None

    def decoded(self, t: float, message: str, signals: Mapping[str, float | int | str]) -> None:
        """Log one decoded message on `/can/decoded/<message>`: numbers, NaN/inf as null, choice names as their
        value."""
        channel_id, payload = self._decoded_payload(message, signals)
        try:
            ns = log_ns(t) + self._origin_ns
        except (TypeError, ValueError) as exc:
            raise LogError(f"run log {self.path}: bad decoded {message}: {exc}") from None
        self._write(channel_id, ns, payload)

    def _decoded_payload(self, message: str, signals: Mapping[str, float | int | str]) -> tuple[int, bytes]:
        """The channel and the record bytes of a decoded message (they depend on its values only)."""
        entry = self._decoded.get(message)
        if entry is None:
            raise LogError(f"run log {self.path}: unknown message {message!r}: "
                           "it is in none of the recorder's databases")
        if tuple(signals) == entry.order:
            values = tuple(signals.values())
            if _PLAIN_NUMBERS.issuperset(map(type, values)):
                text = entry.template % values
                if text.count("n") == entry.letters:
                    return entry.channel_id, text.encode()
        try:
            if not signals.keys() <= entry.names:
                raise ValueError(f"no signal(s) {', '.join(sorted(signals.keys() - entry.names))} in the message")
        except (TypeError, ValueError, AttributeError) as exc:
            raise LogError(f"run log {self.path}: bad decoded {message}: {exc}") from None
        try:
            payload = _ENCODER.encode(signals)
            if payload.count('"') != 2 * len(signals):  # a str value: needs a choice lookup
                raise ValueError
        except (TypeError, ValueError, AttributeError):  # non-finite, str or odd values: the slow, careful way
            payload = self._clean(entry, message, signals)
        return entry.channel_id, payload.encode()

    def frames(self, frames: Iterable[Sequence[Any]], *, channel: str, codecs: Mapping[int, Decoder]) -> list[str]:
        """Log a batch of frames `(t, frame_id, data, direction, valid, error)` on `/can/frames` (`frame_id`: the
        identifier with its format and kind, bench.canid), each valid
        one whose id has a codec also decoded on `/can/decoded/<codec.name>`: the same records, in the same order
        and chunks, as `frame()` then `decoded()` per frame, at about half the CPU (bench.log.logproc, issue 18).

        Why cheaper: a frame's record texts depend on the frame, not on its time, and most frames of a run repeat an
        earlier one (a PIVOT run: 17 % distinct), so each distinct frame is validated, decoded and written as
        text once (up to _TEXT_CACHE of them) and later ones only get their time stamp; the records are framed for
        the chunk in one pass per batch. Returns why each record not written was refused (a bad frame writes
        nothing; a frame that does not decode writes its frame record only), as `frame()`/`decoded()` would raise.
        """
        texts = self._texts
        head = FRAME_HEAD
        origin = self._origin_ns
        frames_id = self._frames_id
        problems: list[str] = []
        nss: list[int] = []
        channels: list[int] = []
        payloads: list[bytes] = []
        add_ns, add_channel, add_payload = nss.append, channels.append, payloads.append
        invalid = 0
        for t, frame_id, data, direction, valid, error in frames:
            if type(data) is not bytes:
                data = bytes(data)
            key = (frame_id, data, direction, valid, error, channel)
            known = texts.get(key)
            try:
                # log_ns(t) inline for a bench time (the call was a tenth of the cost of a repeated frame)
                ns = (int(t * 1e9 + 0.5) if type(t) is float and 0.0 <= t < EXACT_T else log_ns(t)) + origin
                if known is None:
                    known = self._frame_texts(key, codecs)
            except (LogError, ValueError, TypeError) as exc:   # LogError: the frame; the others: its time
                problems.append(str(exc) if isinstance(exc, LogError)
                                else f"run log {self.path}: bad frame {frame_id!r} on {channel!r}: {exc}")
                continue
            tail, decoded_id, decoded, problem = known
            sec, nsec = divmod(ns, 1_000_000_000)   # a plain tuple below, not one built from an unpacked one
            add_ns(ns)
            add_channel(frames_id)
            add_payload(head % (sec, nsec, tail))
            if not valid:
                invalid += 1
            if decoded is not None:
                add_ns(ns)
                add_channel(decoded_id)
                add_payload(decoded)
            elif problem:
                problems.append(problem)
        if payloads:
            self._write_many(channels, nss, payloads)
            self._invalid += invalid
        return problems

    def _frame_texts(self, key: tuple[int, bytes, str, bool, str, str], codecs: Mapping[int, Decoder]
                     ) -> tuple[bytes, int, bytes | None, str]:
        """A distinct frame's record tail, its decoded channel and record (None: none), and why none when it
        failed; kept for the frames that repeat it unless the decode failed (each such frame is reported)."""
        frame_id, data, direction, valid, error, channel = key
        wrong = canid.problem(frame_id)
        if wrong is not None:
            raise LogError(f"run log {self.path}: bad frame {frame_id!r} on {channel!r}: {wrong}")
        tail = self._frame_tail(canid.arbitration_id(frame_id), data, channel, direction, canid.is_extended(frame_id),
                                canid.is_error(frame_id), canid.is_remote(frame_id), valid, error,
                                canid.is_fd(frame_id), bool(frame_id & canid.BRS), bool(frame_id & canid.ESI),
                                None, None)
        codec = codecs.get(frame_id & canid.IDENTITY) if valid else None
        if codec is None:
            known: tuple[bytes, int, bytes | None, str] = (tail, 0, None, "")
        else:
            try:
                decoded_id, decoded = self._decoded_payload(codec.name, codec.decode(data))
            except (BenchError, ValueError, TypeError) as exc:
                return tail, 0, None, str(exc)
            known = (tail, decoded_id, decoded, "")
        if len(self._texts) >= _TEXT_CACHE:
            self._texts.clear()
        self._texts[key] = known
        return known

    def diagnostic(self, t: float, message: str, record: Mapping[str, object]) -> None:
        """Log one whole diagnostic message (format.DIAG_SCHEMA's fields) on `/diag/<message>`, the DBC message of
        its frames. Its channel is registered with its first record, so a log without diagnostics has none."""
        if message not in self._decoded:
            raise LogError(f"run log {self.path}: unknown message {message!r}: it is in none of the recorder's "
                           "databases")
        try:
            ns = log_ns(t) + self._origin_ns
            payload = _PLAIN_ENCODER.encode(dict(record)).encode()
        except (TypeError, ValueError) as exc:
            raise LogError(f"run log {self.path}: bad diagnostic {message}: {exc}") from None
        with self._lock:
            channel_id = self._diag_channels.get(message)
            if channel_id is None:
                if self._closed or self._broken:
                    return
                self._broken = True   # as in _write: a failed registration leaves the log at its last chunk
                if not self._diag_schema:
                    self._diag_schema = self._writer.register_schema(DIAG_SCHEMA_NAME, SCHEMA_ENCODING,
                                                                     json.dumps(DIAG_SCHEMA).encode())
                channel_id = self._writer.register_channel(DIAG_PREFIX + message, ENCODING, self._diag_schema)
                self._diag_channels[message] = channel_id
                self._broken = False
            self._write(channel_id, ns, payload)

    def step(self, t: float, level: int, name: str, message: str, file: str = "", line: int = 0) -> None:
        """Log a test step or verdict on `/bench/steps` (level 1 DEBUG .. 5 FATAL, as foxglove.Log)."""
        try:
            ns = log_ns(t) + self._origin_ns
            if level not in range(6) or not isinstance(line, int) or line < 0:
                raise ValueError(f"level {level!r} not in 0..5 or line {line!r} not an int >= 0")
            payload = step_text(ns, level, name, message, file, line)
        except (TypeError, ValueError) as exc:
            raise LogError(f"run log {self.path}: bad step {name!r}: {exc}") from None
        self._write(self._steps_id, ns, payload.encode())

    def set_origin(self, epoch_ns: int, time_mode: str = "") -> None:
        """From now on log time = `epoch_ns` + bench time, so viewers show the date of the run; a metadata
        record `bench.sim.clock` (`origin_ns`) lets readers give bench time back (bench.log.logread)."""
        if not isinstance(epoch_ns, int) or not 0 <= epoch_ns < 2**62:   # to 2116; + bench time fits uint64
            raise LogError(f"run log {self.path}: bad time origin {epoch_ns!r} ns")
        self.metadata(CLOCK_METADATA, {"origin_ns": str(epoch_ns), "time_mode": str(time_mode),
                                       "origin": datetime.fromtimestamp(epoch_ns / 1e9, UTC).isoformat()})
        self._origin_ns = epoch_ns

    def metadata(self, name: str, data: Mapping[str, str]) -> None:
        """A metadata record (name and string pairs), written at once outside the chunks."""
        with self._lock:
            if self._closed or self._broken:
                return
            self._writer.add_metadata(str(name), {str(k): str(v) for k, v in data.items()})

    def flush(self) -> None:
        """Finalise the open chunk now (e.g. after a verdict) rather than at the next interval."""
        with self._lock:
            if not (self._closed or self._busy or self._broken):
                self._broken = True
                self._finish_chunk()
                self._broken = False

    def close(self) -> None:
        """Write the summary and footer and close the file. Idempotent; safe from atexit and signal handlers.

        From a signal handler that interrupted a write on this thread, the close is deferred
        to the end of that write, so the open chunk is never written half-built.
        """
        with self._lock:
            if self._busy:
                self._close_pending = True
            else:
                self._close_locked()

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None) -> None:
        self.close()

    def _start(self, blobs: list[tuple[Path, bytes, int]], profile: str) -> None:
        """Header, attachments and metadata straight to disk; schemas and channels into the first chunk."""
        self._writer = Writer(self._file, chunk_size=4 * self._chunk_bytes, compression=COMPRESSION)
        self._add = mcapfast.fast_adder(self._writer) or self._add_slowly
        self._add_many = mcapfast.fast_bulk_adder(self._writer) or self._add_one_by_one
        self._writer.start(profile="", library=f"{LIBRARY}/{bench_version()}")
        for attachment, data, mtime_ns in blobs:
            dbc = attachment.suffix.lower() == ".dbc"
            media = "application/x-dbc" if dbc else mimetypes.guess_type(attachment.name)[0]
            self._writer.add_attachment(mtime_ns, 0, attachment.name, media or "application/octet-stream", data)
        self._writer.add_metadata(BENCH_METADATA, {
            "profile": profile,
            "created": datetime.now(UTC).isoformat(timespec="seconds"),
            "host": platform.node(),
            "python": platform.python_version(),
            "bench": bench_version(),
            "attachments": ", ".join(attachment.name for attachment, _, _ in blobs),
            "compression": COMPRESSION.name.lower(),
        })
        _finalise_chunk(self._writer, self._file)  # header, attachments and metadata on disk now

        frame_schema = self._writer.register_schema(FRAME_SCHEMA_NAME, SCHEMA_ENCODING,
                                                    json.dumps(FRAME_SCHEMA).encode())
        self._frames_id = self._writer.register_channel(FRAMES_TOPIC, ENCODING, frame_schema)
        log_schema = self._writer.register_schema(LOG_SCHEMA_NAME, SCHEMA_ENCODING,
                                                  json.dumps(LOG_SCHEMA).encode())
        self._steps_id = self._writer.register_channel(STEPS_TOPIC, ENCODING, log_schema)
        for name, entry in self._decoded.items():
            if not entry.channel_id:
                schema = self._writer.register_schema(name, SCHEMA_ENCODING, entry.schema)
                entry.channel_id = self._writer.register_channel(DECODED_PREFIX + name, ENCODING, schema)

    def _write(self, channel_id: int, ns: int, payload: bytes) -> None:
        with self._lock:
            self._busy = True
            try:
                if self._closed or self._broken:  # a late frame from a receive thread after close(): dropped
                    return
                self._broken = True  # until the writer's state is whole again (KeyboardInterrupt, disk full)
                self._add(channel_id, ns, payload)
                self._pending += len(payload) + RECORD_OVERHEAD
                # flush_interval=math.inf: the caller flushes (bench.log.logproc), and no write reads the clock
                if self._pending >= self._chunk_bytes or (self._deadline != math.inf
                                                          and time.monotonic() >= self._deadline):
                    self._finish_chunk()
                self._broken = False
            finally:
                self._busy = False
                if self._close_pending:
                    self._close_locked()

    def _write_many(self, channels: list[int], nss: list[int], payloads: list[bytes]) -> None:
        """`_write` of each record in turn, the same chunks (one ends after the record that fills it), framed in
        one pass per chunk."""
        with self._lock:
            self._busy = True
            try:
                if self._closed or self._broken:
                    return
                self._broken = True
                total = records_size(payloads)
                if self._pending + total < self._chunk_bytes:   # the batch ends no chunk: no split to find
                    self._add_many(channels, nss, payloads)
                    self._pending += total
                else:
                    self._add_in_chunks(channels, nss, payloads)
                if self._deadline != math.inf and time.monotonic() >= self._deadline:
                    self._finish_chunk()
                self._broken = False
            finally:
                self._busy = False
                if self._close_pending:
                    self._close_locked()

    def _add_in_chunks(self, channels: list[int], nss: list[int], payloads: list[bytes]) -> None:
        """Add a batch that fills the open chunk: finish each chunk after the record that fills it."""
        ends = record_ends(payloads)
        start = 0
        while start < len(payloads):
            base = ends[start - 1] if start else 0
            # the first record after which the chunk holds chunk_bytes (as _write checks after each)
            stop = bisect.bisect_left(ends, self._chunk_bytes - self._pending + base, start) + 1
            stop = min(stop, len(payloads))
            self._add_many(channels[start:stop], nss[start:stop], payloads[start:stop])
            self._pending += ends[stop - 1] - base
            if self._pending >= self._chunk_bytes:
                self._finish_chunk()
            start = stop

    def _add_one_by_one(self, channels: list[int], nss: list[int], payloads: list[bytes]) -> None:
        for channel_id, ns, payload in zip(channels, nss, payloads):
            self._add(channel_id, ns, payload)

    def _add_slowly(self, channel_id: int, ns: int, payload: bytes) -> None:
        self._writer.add_message(channel_id, ns, payload, ns)

    def _finish_chunk(self) -> None:
        _finalise_chunk(self._writer, self._file)
        self._pending = 0
        self._deadline = time.monotonic() + self._interval

    def _close_locked(self) -> None:
        if self._closed:
            return
        self._closed = True
        atexit.unregister(self.close)
        try:
            if not self._broken:  # else leave the file ending at its last whole chunk: still readable
                self._writer.add_metadata(COUNTS_METADATA, {"invalid_frames": str(self._invalid)})
                self._writer.finish()  # type: ignore[no-untyped-call]   # mcap's Writer.finish carries no annotations
        finally:
            self._file.close()

    def _clean(self, entry: _Decoded, message: str, signals: Mapping[str, object]) -> str:
        clean: dict[str, int | float | None] = {}
        for name, value in signals.items():
            try:
                clean[name] = _number(value, entry.choices[name])
            except (TypeError, ValueError) as exc:
                raise LogError(f"run log {self.path}: bad value of {message}.{name}: {exc}") from None
        return json.dumps(clean, separators=(",", ":"), allow_nan=False)

