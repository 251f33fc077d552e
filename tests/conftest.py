"""Shared fixtures of the bench's own tests."""

from __future__ import annotations

import pytest

from bench.codec import Codebook, load_codebook
from tests.repo import BENCH_DBC, CHASSIS_DBC


@pytest.fixture(scope="session")
def codebook() -> Codebook:
    return load_codebook([CHASSIS_DBC, BENCH_DBC])

# Test-case folders used as input by the integration tests; never collected on their own.
collect_ignore = ["fixtures"]
