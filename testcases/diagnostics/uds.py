"""What the diagnostic cases share: each node's vehicle, raw requests, and the NRC of a refused request.

A node is judged on the vehicle whose network it is on (docs/spec/vehicles.md), so that its monitors run: the
4WIS EV carries the VCU, the wheel modules and the IMU; the A-class car the SBW, its ABS variant the ABS.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pytest
from udsoncan.client import Client
from udsoncan.exceptions import NegativeResponseException, TimeoutException

from bench.case import Case
from testcases.limits import limit_value, limits_file, load_limits
from testcases.stimulus import STIMULUS

LIMITS_FILE = limits_file(__file__)
LIMITS = load_limits(LIMITS_FILE, "diagnostics")


def limit(name: str) -> float:
    """One limit of testcases/diagnostics/limits.toml [diagnostics] (its source is cited there)."""
    return limit_value(LIMITS, name, LIMITS_FILE, "diagnostics")

VEHICLE = {"VCU": "EV4WIS", "WHL_FL": "EV4WIS", "WHL_FR": "EV4WIS", "WHL_RL": "EV4WIS", "WHL_RR": "EV4WIS",
           "IMU": "EV4WIS", "SBW": "ACLASS", "ABS": "ACLASS_ABS"}
NODES = tuple(VEHICLE)
PREFIX = {"VCU": "VCU", "WHL_FL": "WHL", "WHL_FR": "WHL", "WHL_RL": "WHL", "WHL_RR": "WHL", "IMU": "IMU",
          "SBW": "SBW", "ABS": "ABS"}
#: the node document's requirement of its routine and of its live values
ROUTINE_REQ = {"VCU": "VCU-DIAG-03", "WHL": "WHL-DIAG-02", "SBW": "SBW-DIAG-03", "ABS": "ABS-DIAG-02",
               "IMU": "IMU-DIAG-02"}
LIVE_REQ = {"VCU": "VCU-DIAG-04", "WHL": "WHL-DIAG-03", "SBW": "SBW-DIAG-04", "ABS": "ABS-DIAG-03",
            "IMU": "IMU-DIAG-03"}
DEFAULT, EXTENDED = 0x01, 0x03
RESPONSE_PENDING = 0x78


def nodes(*requirements: str, only: tuple[str, ...] = NODES) -> list[Any]:
    """One parameter per node, judging that node, with its requirement ids (`{P}`: its document's prefix,
    `{routine}` / `{live}`: its document's requirement of its routine / live values)."""
    def ids(node: str) -> list[str]:
        prefix = PREFIX[node]
        return [r.format(P=prefix, routine=ROUTINE_REQ[prefix], live=LIVE_REQ[prefix]) for r in requirements]

    return [pytest.param(node, id=node, marks=[pytest.mark.dut(node), pytest.mark.req(*ids(node))])
            for node in only]


def start(bench: Case, node: str) -> Client:
    """The node's vehicle at rest (its monitors run), and a client to the node in the default session (a node is
    never reset between cases: the last case may have left it in another)."""
    vehicle = VEHICLE[node]
    bench.start_scenario(Vehicle=vehicle, stimulus=STIMULUS[vehicle])
    bench.run(0.3)
    client = bench.diag(node)
    client.change_session(DEFAULT)
    return client


def nrc(call: Callable[[], object]) -> int | str:
    """The NRC a request is refused with; "positive" or "no response" otherwise."""
    try:
        call()
    except NegativeResponseException as exc:
        return int(exc.response.code)
    except TimeoutException:
        return "no response"
    return "positive"


def raw(client: Client, payload: bytes, timeout: float = 0.1) -> bytes | None:
    """Send any bytes as a request (also malformed ones udsoncan would not build) and return the final response
    (after any 0x78), or None when none came within `timeout` s (P2 plus the tester's margin by default)."""
    conn = client.conn
    conn.empty_rxqueue()
    conn.send(payload)
    while True:
        response = conn.wait_frame(timeout=timeout)
        if response is None or not (len(response) >= 3 and response[0] == 0x7F and response[2] == RESPONSE_PENDING):
            return response
        timeout = 2.5   # P2* + margin after a 0x78


def negative(response: bytes | None, sid: int) -> int | str:
    """The NRC of a negative response to `sid`, else what came instead."""
    if response is None:
        return "no response"
    if len(response) == 3 and response[0] == 0x7F and response[1] == sid:
        return response[2]
    return f"[{response.hex(' ').upper()}]"


def run_in_session(bench: Case, client: Client, seconds: float) -> None:
    """Let `seconds` s pass keeping the node's session: TesterPresent at least every 2 s (well within S3)."""
    end = bench.now + seconds
    while bench.now < end - 1e-9:
        bench.run(min(2.0, end - bench.now))
        client.tester_present()


def unlock(client: Client) -> None:
    client.change_session(EXTENDED)
    client.unlock_security_access(1)


def _shown(answer: int | str) -> str:
    return f"NRC 0x{answer:02X}" if isinstance(answer, int) else answer


def expect_answer(bench: Case, name: str, answer: int | str, expected: int | str) -> bool:
    """One step: the answer to a request (an NRC, "positive", "no response") against the contract's."""
    return bench.expect_true(name, answer == expected, measured=_shown(answer), expected=_shown(expected))
