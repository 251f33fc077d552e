"""One line of text for a UDS message: service and sub-function by name, NRC by name, the bytes in hex.

What the report's diagnostic table and the log show beside the steps; the names are udsoncan's (ISO 14229-1's).
"""

from __future__ import annotations

from functools import cache

from udsoncan.BaseService import BaseService
from udsoncan.Response import Response

from bench.diag.declaration import NodeDiagnostics, dtc_code

#: services whose first byte after the SID is a sub-function (bit 7: suppressPosRspMsgIndicationBit)
SUBFUNCTION_SERVICES = {0x10, 0x11, 0x19, 0x27, 0x31, 0x3E, 0x85, 0x28}


@cache   # udsoncan finds a service by walking its classes (~40 us), and the run log names every UDS message
def service_name(sid: int) -> str:
    service = BaseService.from_request_id(sid) or BaseService.from_response_id(sid)
    return service.get_name() if service is not None else f"service 0x{sid:02X}"


def describe(payload: bytes, node: NodeDiagnostics | None = None) -> str:
    """E.g. "ReadDTCInformation 0x02 mask 0xFF", "positive ReadDTCInformation: C1A01-1C status 0x2F",
    "negative SecurityAccess: InvalidKey (0x35)"."""
    if not payload:
        return "(empty)"
    data = payload.hex(" ").upper()
    sid = payload[0]
    if sid == 0x7F and len(payload) >= 3:
        return f"negative {service_name(payload[1])}: {_nrc_name(payload[2])} (0x{payload[2]:02X})"
    if sid & 0x40 and _is_response(sid):
        text = f"positive {service_name(sid)}"
        if sid == 0x59 and len(payload) >= 3 and payload[1] in (0x02, 0x04, 0x06):
            dtcs = payload[3:] if payload[1] == 0x02 else payload[2:6]
            found = [(int.from_bytes(dtcs[i:i + 3], "big"), dtcs[i + 3]) for i in range(0, len(dtcs) - 3, 4)]
            names = [f"{dtc_code(n)}{_dtc_name(node, n)} status 0x{s:02X}" for n, s in found[:8]]
            text += ": " + (", ".join(names) if names else "no DTC") + (" ..." if len(found) > 8 else "")
        return f"{text} [{data}]"
    text = service_name(sid)
    if sid in SUBFUNCTION_SERVICES and len(payload) >= 2:
        text += f" 0x{payload[1] & 0x7F:02X}" + (" (no positive response)" if payload[1] & 0x80 else "")
    return f"{text} [{data}]"


@cache
def _is_response(sid: int) -> bool:
    return BaseService.from_response_id(sid) is not None


@cache   # udsoncan reads the NRC's name from the class's members (inspect), ~40 us
def _nrc_name(code: int) -> str:
    return Response.Code.get_name(code)


def _dtc_name(node: NodeDiagnostics | None, number: int) -> str:
    if node is None:
        return ""
    for dtc in node.dtcs:
        if dtc.number == number:
            return f" {dtc.name}"
    return ""
