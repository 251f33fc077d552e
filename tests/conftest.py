"""Shared fixtures of the bench's own tests."""

from __future__ import annotations

import signal

import pytest

from bench.database.codec import Codebook, load_codebook
from tests.repo import BENCH_DBC, CHASSIS_DBC


@pytest.fixture(scope="session")
def codebook() -> Codebook:
    return load_codebook([CHASSIS_DBC, BENCH_DBC])

# Test-case folders used as input by the integration tests; never collected on their own.
collect_ignore = ["fixtures"]


# A shell without job control starts a background job (`pytest ... &`, a CI step sent to the background) with
# SIGINT ignored, and an ignored signal stays ignored through fork and exec: every child a test stops with
# Ctrl-C (SIGINT) then ignored it (python-can's logger in test_canio ran on after the test; `bench run` in the
# SIGINT test would have run its 100000 s case). With a handler here, exec gives each child the default again.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)
