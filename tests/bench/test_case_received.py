"""`bench.received`: the history of a message a case cannot be judged without, or the end of the case in one line
naming the message and its sender (issue 25: a case of a silent external SBW ended in an IndexError of the
case's own arithmetic on empty arrays)."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from bench.case import Case
from bench.checks.steps import StepLog
from bench.config import RunSettings, load_config
from bench.results.model import CaseResult
from bench.session import BenchSession

MESSAGE, SIGNAL, NODE = "WHL_Status_FL", "SteerAngle", "WHL_FL"


@pytest.fixture
def case() -> Iterator[Case]:
    session = BenchSession(load_config(), RunSettings())
    session.start()
    try:
        steps = StepLog(session.now)
        bench = Case(session, CaseResult(nodeid="t", name="t", outcome="passed", steps=steps.steps), steps)
        bench.start_scenario(Vehicle="EV4WIS")
        yield bench
    finally:
        session.close()


def test_a_message_with_frames_is_its_history(case: Case) -> None:
    case.run(0.1)
    t, v = case.received(MESSAGE, SIGNAL)
    history = case.history(MESSAGE, SIGNAL)
    assert len(t) >= 5 and (t == history[0]).all() and (v == history[1]).all()
    assert case.result.steps == []   # records no step


def test_a_message_without_frames_ends_the_case_in_one_line(case: Case) -> None:
    case.run(0.1)
    fault = case.inject("drop", MESSAGE)
    case.run(0.5)
    last = case.history(MESSAGE, SIGNAL)[0][-1]
    with pytest.raises(pytest.fail.Exception) as ended:
        case.received(MESSAGE, SIGNAL, case.now - 0.2)
    line = str(ended.value)
    assert line == (f"no {MESSAGE} from the simulated {NODE} in 0.2 s (the last at {last:.3f} s) "
                     f"(injected meanwhile: {fault.describe()})")
    assert "\n" not in line and not ended.value.pytrace   # pytest shows the line, no traceback


def test_silent_since_the_case_started_counts_from_there(case: Case) -> None:
    """Asked for the last 0.2 s of a message that never came in the case: the line says the whole case."""
    case.inject("drop", MESSAGE)
    case.run(0.5)
    with pytest.raises(pytest.fail.Exception, match=rf"^no {MESSAGE} from the simulated {NODE} in 0\.5 s \("):
        case.received(MESSAGE, SIGNAL, case.now - 0.2)


def test_the_line_names_an_external_sender() -> None:
    session = BenchSession(load_config(), RunSettings(external=[NODE]))
    session.start()
    try:
        steps = StepLog(session.now)
        case = Case(session, CaseResult(nodeid="t", name="t", outcome="passed", steps=steps.steps), steps)
        case.run(2.0)
        with pytest.raises(pytest.fail.Exception, match=rf"^no {MESSAGE} from the external {NODE} in 2\.0 s$"):
            case.received(MESSAGE, SIGNAL)
    finally:
        session.close()
