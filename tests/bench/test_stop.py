"""bench/stop.py: a stopped run's exit code follows the shell's convention (the run itself: tests/integration/
test_stop_signals.py, real time)."""

from __future__ import annotations

import signal

import pytest

from bench.stop import StopRequests


@pytest.mark.parametrize("signum, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_exit_code_is_128_plus_the_signal(signum: signal.Signals, code: int) -> None:
    stop = StopRequests()
    assert stop.exit_code() == 130                  # a KeyboardInterrupt without a signal: as Ctrl-C
    with stop.finishing():                          # the report is being written: the signal raises nothing
        stop._handle(signum, None)
    assert stop.requested and stop.exit_code() == code


def test_a_signal_while_the_cases_run_raises_keyboard_interrupt() -> None:
    stop = StopRequests()
    with pytest.raises(KeyboardInterrupt, match="SIGTERM"):
        stop._handle(signal.SIGTERM, None)
    assert stop.exit_code() == 143
