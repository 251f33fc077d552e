"""A short soak for CI (the 10-minute one is `python benchmarks/soak.py --seconds 600`, docs/reliability.md):
plant and runner over udp_multicast in real time lose no frame, keep their cycle times and the plant's
memory does not grow."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

from tests.repo import ROOT


def _soak_module():
    spec = importlib.util.spec_from_file_location("soak", ROOT / "benchmarks" / "soak.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.realtime
def test_short_soak(tmp_path: Path) -> None:
    result = _soak_module().soak(20.0, tmp_path, sample_every=2.0)
    assert result["runner_exit"] == 0, result["runner_tail"]
    assert result["plant_exit"] == 0
    assert result["frames_received_from_plant"] > 20 * 1000
    assert result["frames_lost"] == 0, result["lost_by_id"]
    assert result["rss_growth_plant_pct"] < 10.0
