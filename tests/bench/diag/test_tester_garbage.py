"""An external ECU that answers garbage fails its case with one line naming what came and the rule it broke, and
the bench never hangs on it: every wait of the tester (bench/diag/tester.py) has a limit in bench time.

SBW is declared external and played by `GarbageEcu`, a listener (bench.sim.station.Station.listen) on the plant's
station of the same virtual-time session, the way a simulated node's UDS server listens: it takes the frames of
SBW's request identifier and answers each request with the next of its scripted answers, sent with
`Station.send_now`. The answers (`GARBAGE`) are a positive response of another service, a first frame and then
nothing, a consecutive frame out of sequence, an answer on another node's response identifier, silence, and a
plain refusal. Each is asked through `Case.diag` (udsoncan's `read_data_by_identifier`), as a case asks, and must
raise the matching `DiagnosticError` (udsoncan's own exception too) within P2 (or N_Cr once a multi-frame
response started); the framing violations are also on the runner's monitor as the SBW's invalid frames. The last
test runs cases as a user does (`bench run --external SBW`, the ECU added by a pytest plugin as
tests/fixtures/doc_sbw.py adds its SBW) and reads the console and junit.xml.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from collections import deque
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
from udsoncan.exceptions import InvalidResponseException, NegativeResponseException, TimeoutException

from bench.case import Case
from bench.checks.steps import StepLog
from bench.config import RunSettings, load_config
from bench.diag.tester import P2_MARGIN, BadResponse, DiagnosticError, NoResponse, Refused
from bench.results.model import CaseResult
from bench.session import BenchSession
from bench.sim.station import Station
from tests.repo import ROOT

NODE = "SBW"            # has diagnostics (dbc/diagnostics.toml [nodes.SBW]); declared external here
OTHER = "ABS"           # whose response identifier the garbage ECU answers on once
DID = 0xF187            # SparePartNumber: 10 ASCII bytes, so a right answer would be a multi-frame one
ASKED = "ReadDataByIdentifier [22 F1 87]"
ANSWER_DELAY = 0.005    # s of bench time between a request and the garbage ECU's answer (well within P2)
WALL_LIMIT = 30.0       # s of wall time any one request may take at most (virtual time: far less)
OWN, ELSEWHERE = "own", "elsewhere"   # which response identifier a scripted frame goes out on


@dataclass(frozen=True)
class Answer:
    """What the garbage ECU sends for one request: `first` (after ANSWER_DELAY), `after_fc` when the tester's flow
    control came. Each frame is (OWN or ELSEWHERE, its bytes in hex), padded to 8 bytes as the protocol says."""

    first: tuple[tuple[str, str], ...] = ()
    after_fc: tuple[tuple[str, str], ...] = ()


#: the garbage, in the order the ECU answers it (one answer per request, then silence)
GARBAGE: dict[str, Answer] = {
    # (1) a positive response of ReadMemoryByAddress (0x63) to a ReadDataByIdentifier (0x22)
    "wrong SID": Answer(first=((OWN, "04 63 F1 87 00"),)),
    # (2) a first frame announcing 20 bytes, then no consecutive frame: the tester's N_Cr runs out
    "truncated": Answer(first=((OWN, "10 14 62 F1 87 53 42 57"),)),
    # (3) a first frame, then after the flow control a consecutive frame with SN 2 where 1 is due
    "mis-sequenced": Answer(first=((OWN, "10 14 62 F1 87 53 42 57"),), after_fc=((OWN, "22 2D 30 30 30 30 30 31"),)),
    # (4) an answer to SBW's request, but on another node's (ABS's) response identifier
    "another node's": Answer(first=((ELSEWHERE, "07 62 F1 87 53 42 57 2D"),)),
    # (5) nothing at all
    "silent": Answer(),
    # (6) a plain refusal: NRC 0x31 requestOutOfRange
    "refusal": Answer(first=((OWN, "03 7F 22 31"),)),
}
#: a right answer: SparePartNumber "SBW-000001" in a first frame and one consecutive frame
RIGHT = Answer(first=((OWN, "10 0D 62 F1 87 53 42 57"),), after_fc=((OWN, "21 2D 30 30 30 30 30 31"),))


class GarbageEcu:
    """A station listener (bench.sim.station.FrameListener) on SBW's request identifier that answers every single
    frame with the next of `answers` and the tester's flow control with that answer's `after_fc`."""

    def __init__(self, station: Station, request: int, response: int, elsewhere: int, padding: int | None,
                 answers: list[Answer]) -> None:
        self.station = station
        self.frame_ids: tuple[int, ...] = (request,)
        self.ids = {OWN: response, ELSEWHERE: elsewhere}
        self.padding = padding
        self.answers = deque(answers)
        self.answer = Answer()
        self.requests: list[bytes] = []
        self.sent: list[tuple[float, int, bytes]] = []
        self._due: deque[tuple[float, int, bytes]] = deque()

    @property
    def busy(self) -> bool:
        return bool(self._due)

    def on_frame(self, t: float, frame_id: int, data: bytes) -> None:
        kind = data[0] >> 4
        if kind == 0:                                   # a request (a single frame)
            self.requests.append(bytes(data))
            self.answer = self.answers.popleft() if self.answers else Answer()
            self._queue(t + ANSWER_DELAY, self.answer.first)
        elif kind == 3:                                 # the tester's flow control for our first frame
            self._queue(t + ANSWER_DELAY, self.answer.after_fc)

    def _queue(self, due: float, frames: tuple[tuple[str, str], ...]) -> None:
        for where, text in frames:
            data = bytes.fromhex(text)
            if self.padding is not None:
                data = data.ljust(8, bytes([self.padding]))
            self._due.append((due, self.ids[where], data))

    def poll(self, t: float) -> None:
        while self._due and self._due[0][0] <= t + 1e-9:
            _, frame_id, data = self._due.popleft()
            self.sent.append((t, frame_id, data))
            self.station.send_now(frame_id, data)


def add_garbage_ecu(session: BenchSession, answers: list[Answer]) -> GarbageEcu:
    """The garbage ECU as SBW's diagnostic side, listening on the plant's station (another station of the session
    than the runner's, whose tester asks)."""
    declaration, plant = session.declaration, session.plant
    assert declaration is not None and plant is not None and NODE in session.external
    node = declaration.node(NODE)
    ecu = GarbageEcu(plant, node.request, node.response, declaration.node(OTHER).response,
                     declaration.protocol.padding, answers)
    plant.listen(ecu)
    return ecu


def install_on_every_session(answers: list[Answer]) -> None:
    """For a pytest plugin in `bench run`'s process: BenchSession.__init__, then the garbage ECU when SBW is
    external (tests/fixtures/doc_sbw.py's way)."""
    original = BenchSession.__init__

    def init(self: BenchSession, *args: object, **kwargs: object) -> None:
        original(self, *args, **kwargs)   # type: ignore[arg-type]
        if NODE in self.external and not self.clock.realtime:
            add_garbage_ecu(self, answers)

    BenchSession.__init__ = init   # type: ignore[method-assign]


# -- a virtual-time session and a Case, as tests/bench/test_case_api.py builds them (SBW external) -----------------
def _session(answers: list[Answer]) -> Iterator[tuple[BenchSession, Case, GarbageEcu]]:
    session = BenchSession(load_config(), RunSettings(external=[NODE]))
    ecu = add_garbage_ecu(session, answers)
    session.start()
    try:
        steps = StepLog(session.now)
        result = CaseResult(nodeid="t", name="t", outcome="passed", steps=steps.steps)   # as bench.run does
        yield session, Case(session, result, steps), ecu
    finally:
        session.close()


def _ask(session: BenchSession, case: Case) -> tuple[DiagnosticError, float]:
    """read_data_by_identifier(DID) through the case's tester: the error it raised and the bench time it took."""
    t0, wall0 = session.now(), time.monotonic()
    with pytest.raises(DiagnosticError) as raised:
        case.diag(NODE).read_data_by_identifier(DID)
    assert time.monotonic() - wall0 < WALL_LIMIT
    return raised.value, session.now() - t0


def _bound(session: BenchSession, n_cr: bool) -> float:
    """The longest a request may take in bench time: the tester's P2 (the server's plus its margin), and N_Cr more
    once a multi-frame response started; plus two ticks (the bench notices a deadline at the next tick)."""
    declaration = session.declaration
    assert declaration is not None
    protocol = declaration.protocol
    return protocol.p2 + P2_MARGIN + (protocol.n_cr if n_cr else 0.0) + 0.002


def _framing(session: BenchSession) -> list[tuple[str, str]]:
    """(message, reason) of every ISO-TP problem on the runner's monitor (its N_Cr / N_Bs timeouts recorded first)."""
    monitor = session.runner.monitor   # type: ignore[union-attr]
    monitor.check_timeouts(session.now())
    return [(f.message, f.reason) for f in monitor.invalid_log if f.reason.startswith("ISO-TP ")]


@dataclass(frozen=True)
class Expected:
    kind: type[DiagnosticError]
    udsoncan: type[Exception]
    says: tuple[str, ...]         # in the one line, besides the node and the request
    n_cr: bool = False            # the response started (a first frame came): the wait may last N_Cr more
    rule: str = ""                # the ISO-TP rule the monitor names, on the SBW's response message


EXPECTED = {
    "wrong SID": Expected(BadResponse, InvalidResponseException,
                          ("with positive ReadMemoryByAddress [63 F1 87 00", "Received=0x63, Expected=0x62")),
    "truncated": Expected(NoResponse, TimeoutException,
                          ("ISO-TP N_Cr timeout", "0x70D [10 14 62 F1 87 53 42 57]", "6 of 20 bytes"),
                          n_cr=True, rule="ISO-TP N_Cr timeout: "),
    "mis-sequenced": Expected(NoResponse, TimeoutException,
                              ("ISO-TP sequence number", "0x70D [22 2D 30 30 30 30 30 31]", "SN 2 where 1 was due"),
                              rule="ISO-TP sequence number: "),
    "another node's": Expected(NoResponse, TimeoutException, ("no DIAG_SBW_Resp", "in 0.1 s")),
    "silent": Expected(NoResponse, TimeoutException, ("no DIAG_SBW_Resp", "in 0.1 s")),
    "refusal": Expected(Refused, NegativeResponseException,
                        ("refused", "negative ReadDataByIdentifier: RequestOutOfRange (0x31)")),
}


def _check(name: str, session: BenchSession, error: DiagnosticError, spent: float) -> None:
    expected = EXPECTED[name]
    text = str(error)
    assert type(error) is expected.kind and isinstance(error, expected.udsoncan), (name, type(error), text)
    assert "\n" not in text and "the external SBW" in text and ASKED in text, text
    for part in expected.says:
        assert part in text, (name, part, text)
    bound = _bound(session, expected.n_cr)
    assert 0.0 < spent <= bound, (name, spent, bound)
    framing = _framing(session)
    if expected.rule:
        assert [m for m, r in framing if r.startswith(expected.rule)] == ["DIAG_SBW_Resp"], framing
    else:
        assert framing == [], framing


@pytest.mark.parametrize("name", list(GARBAGE))
def test_garbage_fails_in_one_line_within_a_bench_time_limit(name: str) -> None:
    for session, case, ecu in _session([GARBAGE[name]]):
        error, spent = _ask(session, case)
        assert ecu.requests == [bytes.fromhex("03 22 F1 87 CC CC CC CC")]
        assert len(ecu.sent) == len(GARBAGE[name].first) + len(GARBAGE[name].after_fc)
        _check(name, session, error, spent)
        if EXPECTED[name].rule:       # the framing violation is the SBW's invalid frame: it fails the DUT's case
            case.result.duts = [NODE]
            assert not case.expect_clean_bus()
            [failed] = case.result.failed_steps
            assert failed.name == "no invalid frame on the bus (range, E2E, length)"
            assert "DIAG_SBW_Resp" in failed.detail and EXPECTED[name].rule.strip(": ") in failed.detail


def test_in_turn_to_one_tester_then_a_right_answer_is_read() -> None:
    """The six answers one after the other to one tester (a dropped message leaves its endpoint ready for the next
    request), each failing as alone; then a right answer is read as usual."""
    for session, case, _ in _session([*GARBAGE.values(), RIGHT]):
        for name, expected in EXPECTED.items():
            seen = len(_framing(session))
            error, spent = _ask(session, case)
            text = str(error)
            assert type(error) is expected.kind and "\n" not in text and ASKED in text, (name, text)
            assert all(part in text for part in expected.says), (name, text)
            assert spent <= _bound(session, expected.n_cr), (name, spent)
            rules = [reason.split(":")[0] + ": " for _, reason in _framing(session)[seen:]]
            assert rules == ([expected.rule] if expected.rule else []), (name, rules)
        response = case.diag(NODE).read_data_by_identifier(DID)
        assert response.service_data.values[DID].strip() == "SBW-000001"
        assert len(_framing(session)) == 2                                  # (2) and (3) only: the answer is clean


# -- as a user sees it: `bench run` ------------------------------------------------------------------------------
PLUGIN = """\
from tests.bench.diag.test_tester_garbage import GARBAGE, install_on_every_session


def pytest_configure(config):
    install_on_every_session(list(GARBAGE.values()))
"""

CASES = "import pytest\n" + "".join(f'''

@pytest.mark.dut("SBW")
def test_{i}(bench):
    bench.diag("SBW").read_data_by_identifier(0xF187)   # {name}
''' for i, name in enumerate(GARBAGE, 1))


def test_bench_run_shows_each_failure_as_one_line(tmp_path: Path) -> None:
    (tmp_path / "garbage_sbw.py").write_text(PLUGIN, encoding="utf-8")
    (tmp_path / "test_garbage.py").write_text(CASES, encoding="utf-8")
    env = {**os.environ, "PYTEST_ADDOPTS": "-p garbage_sbw", "PYTHONPATH": os.pathsep.join([str(ROOT), str(tmp_path)])}
    wall0 = time.monotonic()
    run = subprocess.run([sys.executable, "-m", "bench", "run", str(tmp_path / "test_garbage.py"), "--external", NODE,
                          "--out", str(tmp_path / "out")], cwd=ROOT, env=env, capture_output=True, text=True,
                         timeout=120)
    assert time.monotonic() - wall0 < 60
    output = run.stdout + run.stderr
    assert run.returncode == 1, output
    assert "Traceback" not in output
    lines = run.stdout.splitlines()
    suite = ET.parse(tmp_path / "out" / "junit.xml").getroot().find("testsuite")
    assert suite is not None
    for i, name in enumerate(GARBAGE, 1):
        [at] = [n for n, line in enumerate(lines) if line.endswith(")") and f"test_garbage.py::test_{i} " in line]
        assert lines[at].split()[2] == "failed", lines[at]
        message = lines[at + 1]       # the failure: one line, then the next case's line (or the verdict)
        assert ASKED in message and "the external SBW" in message, (name, message)
        assert all(part in message for part in EXPECTED[name].says), (name, message)
        following = f"[{i + 1:>3}/{len(GARBAGE)}] " if i < len(GARBAGE) else "bench run: FAIL"
        assert lines[at + 2].startswith(following), (name, lines[at:at + 3])
        failure = suite.find(f"testcase[@name='test_{i}']/failure")
        assert failure is not None, name
        assert failure.get("message") == message and (failure.text or "").strip() == message, (name, failure.text)
