"""Shared fixtures of the bench's own tests."""

from __future__ import annotations

import pytest

from bench.codec import Codebook, load_codebook
from bench.paths import BENCH_DBC, CHASSIS_DBC


@pytest.fixture(scope="session")
def codebook() -> Codebook:
    return load_codebook([CHASSIS_DBC, BENCH_DBC])
