"""Every node's UDS services as docs/contract/diagnostics.md specifies them, judged with udsoncan's client.

Expected values come from the contract and the declaration (dbc/diagnostics.toml, read through
`bench.diagnostics(node)`): identification lengths, P2/P2*, S3, the seed/key algorithm (DIAG-SEC-01, computed
here from its formula, not taken from the bench), the attempt count and delay, each NRC of DIAG-NRC-02 with the
request that must cause it, routines with responsePending, coding and its persistence, live DIDs against the bus.
"""

from __future__ import annotations

import pytest
from udsoncan.client import Client

from bench.case import Case
from testcases.diagnostics.uds import (
    EXTENDED,
    expect_answer,
    limit,
    negative,
    nodes,
    nrc,
    raw,
    run_in_session,
    start,
    unlock,
)

DEFAULT = 0x01
CODED = ("SBW", "VCU")  # the nodes with coding DIDs (DIAG-COD-01)


def _key(seed: bytes, constant: int) -> bytes:
    """DIAG-SEC-01: key = rotl32(seed XOR C, 7) XOR 0xA5A5A5A5, 4 bytes big-endian."""
    x = (int.from_bytes(seed, "big") ^ constant) & 0xFFFFFFFF
    return ((((x << 7) | (x >> 25)) & 0xFFFFFFFF) ^ 0xA5A5A5A5).to_bytes(4, "big")


def _response_times(client: Client) -> list[float]:
    """Bench time from each request to its first response (the tester's record of the exchange)."""
    times, sent = [], None
    for t, direction, _ in client.conn.exchanges:
        if direction == "request":
            sent = t
        elif sent is not None:
            times.append(t - sent)
            sent = None
    return times


@pytest.mark.parametrize(
    "node", nodes("DIAG-ID-01", "DIAG-TP-01", "DIAG-TP-02", "DIAG-TP-03", "DIAG-SVC-02", "{P}-DIAG-01")
)
def test_identification(bench: Case, node: str) -> None:
    """The four identification DIDs in one request: a segmented response, each DID its length of printable
    ASCII; the ISO-TP framing of the exchange clean (the bench's monitor checks every frame)."""
    client = start(bench, node)
    declared = bench.diagnostics(node)
    ids = [0xF187, 0xF18C, 0xF190, 0xF195]
    values = client.read_data_by_identifier(ids).service_data.values
    for did_id in ids:
        did = declared.did(did_id)
        text = str(values.get(did_id, ""))
        raw_text = did.encode(text) if did_id in values else b""
        bench.expect_true(
            f"0x{did_id:04X} {did.name}: {did.length} bytes of printable ASCII",
            did_id in values and len(raw_text) == did.length and all(0x20 <= b <= 0x7E for b in raw_text),
            measured=repr(text),
            expected=f"{did.length} printable characters",
        )
    diag_frames = [f for f in bench.invalid_log() if f.message.startswith("DIAG_")]
    bench.expect(
        "invalid diagnostic frames (ISO-TP framing)",
        len(diag_frames),
        0,
        detail="; ".join(f.reason for f in diag_frames[:3]),
    )


@pytest.mark.parametrize("node", nodes("DIAG-SES-01", "DIAG-SES-02", "DIAG-SES-03", "DIAG-SVC-01"))
def test_sessions_timing_and_s3(bench: Case, node: str) -> None:
    """10 03 gives P2 and P2* as declared; every response within P2; the extended session kept by TesterPresent
    and left after S3 without a request (SecurityAccess then refused with 0x7F)."""
    client = start(bench, node)
    protocol = bench.diagnostic_protocol
    data = client.change_session(EXTENDED).service_data
    bench.expect("P2 in the positive response", data.p2_server_max, protocol.p2, abs_tol=0.0005, unit="s")
    bench.expect("P2* in the positive response", data.p2_star_server_max, protocol.p2_star, abs_tol=0.005, unit="s")
    expect_answer(bench, "requestSeed allowed in the extended session", nrc(lambda: client.request_seed(1)), "positive")
    for _ in range(3):  # TesterPresent keeps it for longer than S3
        bench.run(protocol.s3 * limit("tester_present_every"))
        client.tester_present()
    expect_answer(
        bench,
        "still extended after TesterPresent every 0.6 × S3",
        nrc(lambda: client.request_seed(1)) == "positive",
        True,
    )
    bench.run(protocol.s3 + 0.2)
    expect_answer(
        bench,
        "back to the default session after S3 without a request: requestSeed refused",
        nrc(lambda: client.request_seed(1)),
        0x7F,
    )
    worst = max(_response_times(client))
    bench.expect_between("slowest response of the case", worst, 0.0, protocol.p2, unit="s")


@pytest.mark.parametrize("node", nodes("DIAG-SEC-01", "DIAG-SEC-02", "DIAG-RST-02"))
def test_security_access(bench: Case, node: str) -> None:
    """The documented key unlocks; three wrong keys give 0x35, 0x35, 0x36, then requestSeed 0x37 until the delay
    has passed; an ECUReset ends a running delay."""
    client = start(bench, node)
    declared, protocol = bench.diagnostics(node), bench.diagnostic_protocol
    client.change_session(EXTENDED)
    seed = client.request_seed(1).service_data.seed
    bench.expect_true("seed: 4 bytes, not 0", len(seed) == 4 and seed != b"\0\0\0\0", measured=seed.hex())
    expect_answer(
        bench,
        "the documented key unlocks",
        nrc(lambda: client.send_key(2, _key(seed, declared.security_constant))),
        "positive",
    )
    zero = client.request_seed(1).service_data.seed.hex()
    bench.expect_true("seed 0 while unlocked", zero == "00000000", measured=zero, expected="00000000")
    client.change_session(EXTENDED)  # a session change locks again
    answers = []
    for _ in range(protocol.security_attempts):
        seed = client.request_seed(1).service_data.seed
        wrong = bytes(b ^ 0xFF for b in _key(seed, declared.security_constant))
        answers.append(nrc(lambda wrong=wrong: client.send_key(2, wrong)))
    expected = [0x35] * (protocol.security_attempts - 1) + [0x36]
    bench.expect_true(
        "wrong keys: 0x35 until the last attempt, then 0x36",
        answers == expected,
        measured=", ".join(map(str, answers)),
        expected=", ".join(map(str, expected)),
    )
    expect_answer(bench, "requestSeed during the delay", nrc(lambda: client.request_seed(1)), 0x37)
    run_in_session(bench, client, protocol.security_delay * 0.9)
    expect_answer(bench, "requestSeed still refused at 90 % of the delay", nrc(lambda: client.request_seed(1)), 0x37)
    run_in_session(bench, client, protocol.security_delay * 0.1 + 0.1)
    expect_answer(bench, "a seed after the delay", nrc(lambda: client.request_seed(1)), "positive")
    for _ in range(protocol.security_attempts):  # a second delay, ended by an ECUReset
        seed = client.request_seed(1).service_data.seed
        nrc(lambda seed=seed: client.send_key(2, bytes(b ^ 0xFF for b in _key(seed, declared.security_constant))))
    client.ecu_reset(1)
    bench.run(limit("reset_silence_max"))
    client.change_session(EXTENDED)
    expect_answer(bench, "after an ECUReset the delay is over", nrc(lambda: client.request_seed(1)), "positive")


@pytest.mark.parametrize("node", nodes("DIAG-NRC-01", "DIAG-NRC-02", "DIAG-SVC-01", "DIAG-DTC-06", "DIAG-DTC-07"))
def test_negative_responses(bench: Case, node: str) -> None:
    """Each NRC with a request that must cause it, in the order of the checks (DIAG-NRC-01)."""
    client = start(bench, node)
    declared = bench.diagnostics(node)
    routine = declared.routines[0].id.to_bytes(2, "big")
    coding = [d for d in declared.dids if d.write]
    # a coding DID needs security (0x33); a node without coding refuses every write as no coding DID (0x31)
    locked_write = (
        b"\x2e" + coding[0].id.to_bytes(2, "big") + coding[0].encode(coding[0].default)
        if coding
        else b"\x2e\xf1\x90" + b" " * 17
    )
    cases = [
        ("unknown service 0xBA", b"\xba\x01", 0xBA, 0x11),
        ("ControlDTCSetting (not in the service table)", b"\x85\x01", 0x85, 0x11),
        ("SecurityAccess in the default session", b"\x27\x01", 0x27, 0x7F),
        ("WriteDataByIdentifier in the default session", b"\x2e\xf1\x90" + b" " * 17, 0x2E, 0x7F),
        ("DiagnosticSessionControl without a sub-function", b"\x10", 0x10, 0x13),
        ("programming session 0x02", b"\x10\x02", 0x10, 0x12),
        ("TesterPresent 0x01", b"\x3e\x01", 0x3E, 0x12),
        ("TesterPresent with an extra byte", b"\x3e\x00\x00", 0x3E, 0x13),
        ("ReadDTCInformation 0x0A", b"\x19\x0a", 0x19, 0x12),
        ("ReadDTCInformation 0x02 without a mask", b"\x19\x02", 0x19, 0x13),
        ("ReadDTCInformation 0x04 of a DTC the node does not have", b"\x19\x04\x3f\xff\xff\x01", 0x19, 0x31),
        ("ReadDataByIdentifier of an even length", b"\x22\xf1\x90\x00", 0x22, 0x13),
        ("ReadDataByIdentifier of an unknown DID", b"\x22\xbe\xef", 0x22, 0x31),
        ("ClearDiagnosticInformation of another group", b"\x14\xff\xff\x33", 0x14, 0x31),
        ("ClearDiagnosticInformation of 3 bytes", b"\x14\xff\xff", 0x14, 0x13),
        ("sendKey without a seed (extended)", None, 0x27, 0x24),
        ("RoutineControl while locked (extended)", b"\x31\x01" + routine, 0x31, 0x33),
        ("WriteDataByIdentifier while locked (extended)", locked_write, 0x2E, 0x33 if coding else 0x31),
        ("RoutineControl of an unknown routine (extended)", b"\x31\x01\xee\xee", 0x31, 0x31),
        ("stopRoutine (extended)", b"\x31\x02" + routine, 0x31, 0x12),
    ]
    for name, payload, sid, expected in cases:
        if name.endswith("(extended)"):
            client.change_session(EXTENDED)
        request = payload if payload is not None else b"\x27\x02\x00\x00\x00\x00"
        expect_answer(
            bench, f"NRC for {name} [{request.hex(' ').upper()}]", negative(raw(client, request), sid), expected
        )
    client.unlock_security_access(1)
    expect_answer(
        bench,
        "WriteDataByIdentifier of an identification DID (unlocked)",
        negative(raw(client, b"\x2e\xf1\x90" + b" " * 17), 0x2E),
        0x31,
    )
    expect_answer(
        bench,
        "requestRoutineResults before a start in this cycle",
        negative(raw(client, b"\x31\x03" + routine), 0x31),
        0x24,
    )


@pytest.mark.parametrize("node", nodes("DIAG-TP-04", "DIAG-NRC-03"))
def test_functional_requests(bench: Case, node: str) -> None:
    """On the functional address: TesterPresent with the suppress bit gets no answer; an unsupported service and a
    sub-function are refused silently; a session change is answered on the node's physical response id."""
    start(bench, node)
    functional = bench.diag(node, functional=True)
    bench.expect("3E 80 (suppressed) on 0x7DF: no response", raw(functional, b"\x3e\x80") is None, True)
    bench.expect("unsupported service on 0x7DF: no 0x11", raw(functional, b"\xba\x01") is None, True)
    bench.expect("unsupported sub-function on 0x7DF: no 0x12", raw(functional, b"\x10\x02") is None, True)
    response = raw(functional, b"\x10\x03")
    bench.expect_true(
        "10 03 on 0x7DF answered 50 03 by the node",
        response is not None and response[:2] == b"\x50\x03",
        measured=response.hex(" ").upper() if response else "none",
    )
    bench.expect("10 81 on 0x7DF: back to default, no response", raw(functional, b"\x10\x81") is None, True)
    physical = bench.diag(node)
    expect_answer(
        bench, "the node is in the default session (requestSeed refused)", nrc(lambda: physical.request_seed(1)), 0x7F
    )


@pytest.mark.parametrize("node", nodes("DIAG-SVC-03", "DIAG-SES-02", "DIAG-NRC-02", "{routine}"))
def test_routine(bench: Case, node: str) -> None:
    """startRoutine: 0x78 at once and at most every 1 s, the positive response after the routine's duration; a
    request meanwhile gets 0x21; requestRoutineResults afterwards."""
    client = start(bench, node)
    routine = bench.diagnostics(node).routines[0]
    protocol = bench.diagnostic_protocol
    unlock(client)
    conn = client.conn
    conn.empty_rxqueue()
    t0 = bench.now
    conn.send(b"\x31\x01" + routine.id.to_bytes(2, "big"))
    answers: list[tuple[float, bytes]] = []
    busy: bytes | None = None
    while True:
        response = conn.wait_frame(timeout=protocol.p2_star + 0.5)
        if response is None:
            break
        answers.append((bench.now, response))
        if response[:1] == b"\x7f" and response[1:2] == b"\x22":
            busy = response
        elif response[:3] == b"\x7f\x31\x78":
            if busy is None and bench.now - t0 + 0.1 < routine.duration:
                conn.send(b"\x22\xf1\x90")  # a request while it runs
        else:
            break
    final = answers[-1][1] if answers else b""
    bench.expect_true(
        "positive response 71 01 with the routine id",
        final == b"\x71\x01" + routine.id.to_bytes(2, "big"),
        measured=final.hex(" ").upper() or "none",
    )
    pending = [t for t, r in answers if r[:3] == b"\x7f\x31\x78"]
    bench.expect_true(
        "0x78 first, within P2",
        bool(pending) and pending[0] - t0 <= protocol.p2,
        measured=f"{(pending[0] - t0) * 1000:.1f} ms" if pending else "none",
    )
    ends = [t0, *pending, answers[-1][0] if answers else t0]
    bench.expect_between(
        "longest gap between 0x78s and the final response",
        max(b - a for a, b in zip(ends, ends[1:])),
        0.0,
        limit("pending_gap_max"),
        unit="s",
    )
    bench.expect_between(
        "the routine's duration to its positive response",
        (answers[-1][0] if answers else t0) - t0,
        routine.duration,
        routine.duration + protocol.p2,
        unit="s",
    )
    if routine.duration > 0.1:
        expect_answer(bench, "ReadDataByIdentifier while the routine runs", negative(busy, 0x22), 0x21)
    expect_answer(
        bench, "requestRoutineResults after it ran", nrc(lambda: client.get_routine_result(routine.id)), "positive"
    )


@pytest.mark.parametrize("node", nodes("DIAG-COD-01", "DIAG-RST-01", "DIAG-RST-02", "{P}-DIAG-02", only=CODED))
def test_coding_persists(bench: Case, node: str) -> None:
    """Each coding DID: a value other than its default written, read back, kept across an ECUReset; out of range
    refused (0x31) with nothing changed; the default written back at the end (the coding outlives the case). A value
    that selects an optional function the node does not have may be refused (0x31): the next one is tried."""
    client = start(bench, node)
    coding = [d for d in bench.diagnostics(node).dids if d.write]
    unlock(client)
    written: dict[int, float] = {}
    for did in coding:
        if did.values:
            candidates = [float(v) for v in sorted(did.values.values()) if v != did.default]
        else:
            middle = round((did.minimum + did.maximum) / 2 / did.scale) * did.scale
            candidates = [middle if abs(middle - did.default) > did.scale else did.minimum]
        for value in candidates:
            if nrc(lambda value=value, did=did: client.write_data_by_identifier(did.id, value)) == "positive":
                written[did.id] = value
                break
        if did.id not in written:
            bench.note(f"{did.name}: the node accepts only its default (every other value refused with 0x31)")
            continue
        expect_answer(bench, f"{did.name} = {written[did.id]:g} written", "positive", "positive")
        bench.expect(
            f"{did.name} reads back as written",
            client.read_data_by_identifier_first(did.id),
            written[did.id],
            abs_tol=did.scale / 2,
        )
        choices = sorted(did.values.values())
        beyond = (max(choices) + 1) if choices else did.maximum + 10 * did.scale
        raw_value = int(beyond) if choices else round((beyond - did.offset) / did.scale)
        request = b"\x2e" + did.id.to_bytes(2, "big") + raw_value.to_bytes(did.length, "big", signed=False)
        expect_answer(bench, f"{did.name} = {beyond:g} (out of range)", negative(raw(client, request), 0x2E), 0x31)
    response = client.ecu_reset(1)
    bench.expect("ECUReset hardReset answered 51 01", response.service_data.reset_type_echo, 1)
    bench.run(limit("reset_silence_max"))
    expect_answer(
        bench, "default session after the reset (requestSeed refused)", nrc(lambda: client.request_seed(1)), 0x7F
    )
    for did in coding:
        if did.id in written:
            bench.expect(
                f"{did.name} kept across the ECUReset",
                client.read_data_by_identifier_first(did.id),
                written[did.id],
                abs_tol=did.scale / 2,
            )
    unlock(client)
    for did in coding:
        client.write_data_by_identifier(did.id, did.default)
        bench.expect(
            f"{did.name} back to its default",
            client.read_data_by_identifier_first(did.id),
            did.default,
            abs_tol=did.scale / 2,
        )


@pytest.mark.parametrize("node", nodes("DIAG-SVC-02", "{live}"))
def test_live_values_equal_the_bus(bench: Case, node: str) -> None:
    """Each live DID that equals a signal the node sends reads what the node sent within one cycle of the
    response (DIAG-SVC-02), to the DID's resolution."""
    client = start(bench, node)
    bench.run(0.5)
    for did in bench.diagnostics(node).dids:
        if not did.signal:
            continue
        message, _, signal = did.signal.partition(".")
        before = bench.now
        value = client.read_data_by_identifier_first(did.id)
        t, values = bench.history(message, signal, before - 0.1)
        near = values[(t >= before - 0.06) & (t <= bench.now + 0.06)]
        low = float(near.min()) if len(near) else float("nan")
        high = float(near.max()) if len(near) else float("nan")
        bench.expect_between(
            f"0x{did.id:04X} {did.name} against {did.signal}",
            float(value),
            low - did.scale,
            high + did.scale,
            unit=did.unit,
        )
