"""The run log's diagnostic topics (bench.log.diaglog): a UDS exchange on the bus becomes one JSON record per whole
message on `/diag/<Message>`, written by the log process and read back here with mcap's own reader."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from mcap.reader import make_reader

from bench.log.format import DIAG_PREFIX, DIAG_SCHEMA_NAME
from bench.log.logproc import LogProcess
from tests.repo import BENCH_DBC, CHASSIS_DBC, DBC_DIR

DIAGNOSTICS = DBC_DIR / "diagnostics.toml"
REQUEST, RESPONSE, FUNCTIONAL = 0x700, 0x708, 0x7DF      # the VCU's connection, the functional request
#: ReadDTCInformation 0x02: three DTCs (C1C01-64 0x2F, C1C02-64 0x09, C1C05-87 0x2F), 15 bytes: FF + 2 CFs
DTCS = bytes.fromhex("5902FF" "5C01642F" "5C026409" "5C05872F")
OTHER = 0x100   # a frame of no diagnostic message between them (decoded as usual)


def exchange() -> list[tuple[float, int, bytes, str, bool, str]]:
    """The frames as the runner's monitor hands them over (frames written from ISO 15765-2 here)."""
    cc = b"\xcc"
    frames = [
        (1.000, REQUEST, b"\x03\x19\x02\xff" + cc * 4, "tx"),
        (1.002, OTHER, bytes(8), "rx"),
        (1.005, RESPONSE, b"\x10\x0f" + DTCS[:6], "rx"),
        (1.006, REQUEST, b"\x30\x00\x00" + cc * 5, "tx"),
        (1.007, RESPONSE, b"\x21" + DTCS[6:13], "rx"),
        (1.008, RESPONSE, b"\x22" + DTCS[13:] + cc * 5, "rx"),
        (2.000, FUNCTIONAL, b"\x02\x3e\x80" + cc * 5, "tx"),
        (2.100, REQUEST, b"\x02\x27\x01" + cc * 5, "tx"),
        (2.110, RESPONSE, b"\x03\x7f\x27\x37" + cc * 4, "rx"),
    ]
    return [(t, i, d, direction, True, "") for t, i, d, direction in frames]


def write(path: Path, diagnostics: Path | None) -> None:
    log = LogProcess(path, [CHASSIS_DBC, BENCH_DBC], "bench", diagnostics=diagnostics)
    for frame in exchange():
        log.frame(*frame)
    log.close()


def diag_records(path: Path) -> list[tuple[str, int, dict[str, Any]]]:
    """(topic, log time, record) of every diagnostic message, in log-time order, by mcap's reader alone."""
    with path.open("rb") as file:
        reader = make_reader(file)
        return [(channel.topic, message.log_time, json.loads(message.data))
                for schema, channel, message in reader.iter_messages()
                if channel.topic.startswith(DIAG_PREFIX) and schema is not None and schema.name == DIAG_SCHEMA_NAME]


def test_a_uds_exchange_becomes_diag_records(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    write(path, DIAGNOSTICS)
    records = diag_records(path)
    dtcs = DTCS.hex(" ").upper()
    assert records == [
        ("/diag/DIAG_VCU_Req", 1_000_000_000, {
            "node": "VCU", "direction": "request", "service": "ReadDTCInformation",
            "text": "ReadDTCInformation 0x02 [19 02 FF]", "data": "19 02 FF", "length": 3}),
        ("/diag/DIAG_VCU_Resp", 1_008_000_000, {
            "node": "VCU", "direction": "response", "service": "ReadDTCInformation",
            "text": "positive ReadDTCInformation: C1C01-64 CENTRE_AT_ORIGIN status 0x2F, C1C02-64 CENTRE_ON_WHEEL "
                    f"status 0x09, C1C05-87 REQUEST_TIMEOUT status 0x2F [{dtcs}]", "data": dtcs, "length": 15}),
        ("/diag/DIAG_Functional", 2_000_000_000, {
            "node": "", "direction": "functional", "service": "TesterPresent",
            "text": "TesterPresent 0x00 (no positive response) [3E 80]", "data": "3E 80", "length": 2}),
        ("/diag/DIAG_VCU_Req", 2_100_000_000, {
            "node": "VCU", "direction": "request", "service": "SecurityAccess",
            "text": "SecurityAccess 0x01 [27 01]", "data": "27 01", "length": 2}),
        ("/diag/DIAG_VCU_Resp", 2_110_000_000, {
            "node": "VCU", "direction": "response", "service": "SecurityAccess",
            "text": "negative SecurityAccess: RequiredTimeDelayNotExpired (0x37)", "data": "7F 27 37",
            "length": 3}),
    ]
    with path.open("rb") as file:   # the raw frames are all there too, each once, and the log is whole
        summary = make_reader(file).get_summary()
    assert summary is not None and summary.statistics is not None
    topics = {channel.id: channel.topic for channel in summary.channels.values()}
    counts = {topics[i]: n for i, n in summary.statistics.channel_message_counts.items()}
    assert counts["/can/frames"] == len(exchange())
    assert {t: n for t, n in counts.items() if t.startswith(DIAG_PREFIX)} == {
        "/diag/DIAG_VCU_Req": 2, "/diag/DIAG_VCU_Resp": 2, "/diag/DIAG_Functional": 1}


def test_the_records_match_their_schema(tmp_path: Path) -> None:
    jsonschema = pytest.importorskip("jsonschema")
    path = tmp_path / "run.mcap"
    write(path, DIAGNOSTICS)
    with path.open("rb") as file:
        reader = make_reader(file)
        checked = 0
        for schema, channel, message in reader.iter_messages():
            if channel.topic.startswith(DIAG_PREFIX):
                assert schema is not None
                jsonschema.validate(json.loads(message.data), json.loads(schema.data))
                checked += 1
    assert checked == 5


def test_without_the_declaration_the_databases_give_the_connections(tmp_path: Path) -> None:
    """No [diagnostics] file: the request pairs with the response 8 above it, the node is that response's sender,
    DTCs come as codes without their names, and 0x7DF (no response of its own) is a request alone."""
    path = tmp_path / "run.mcap"
    write(path, None)
    records = diag_records(path)
    assert [(topic, record["node"], record["direction"]) for topic, _, record in records] == [
        ("/diag/DIAG_VCU_Req", "VCU", "request"), ("/diag/DIAG_VCU_Resp", "VCU", "response"),
        ("/diag/DIAG_Functional", "", "request"), ("/diag/DIAG_VCU_Req", "VCU", "request"),
        ("/diag/DIAG_VCU_Resp", "VCU", "response")]
    assert records[1][2]["text"].startswith("positive ReadDTCInformation: C1C01-64 status 0x2F, C1C02-64 status")
    assert records[1][2]["length"] == 15
