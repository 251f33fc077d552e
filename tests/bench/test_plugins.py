"""`bench.plugins.prepare_plant`: what a case may ask of the plant is asked once, before real time (the session
calls it): the plant's import and the tables it builds when first asked must not land in a case."""

from __future__ import annotations

import sys
import textwrap
from pathlib import Path

import pytest

from bench.plugins import plant_module, plant_stimulus, plant_vehicles, prepare_plant

PLANT = textwrap.dedent("""
    ASKED = []

    def build(external, vehicle):
        return []

    def vehicles():
        ASKED.append("vehicles")
        return ("CAR", "TRUCK")

    def stimulus(vehicle):
        ASKED.append(vehicle)
        return ("DRV_" + vehicle,)
""")


def test_the_plant_is_asked_once_and_then_costs_nothing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    (tmp_path / "counting_plant.py").write_text(PLANT)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, "counting_plant", raising=False)
    name = "counting_plant:build"
    prepare_plant(name)
    module = plant_module(name)
    assert module.ASKED == ["vehicles", "CAR", "TRUCK"]
    assert plant_module(name) is module                      # looked up once per process
    assert plant_stimulus(name, "TRUCK") == ("DRV_TRUCK",) and plant_vehicles(name) == ("CAR", "TRUCK")


def test_a_plant_without_stimulus_is_prepared_without_asking(tmp_path: Path,
                                                             monkeypatch: pytest.MonkeyPatch) -> None:
    (tmp_path / "bare_plant.py").write_text("def build(external, vehicle):\n    return []\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    prepare_plant("bare_plant:build")                          # no stimulus(): nothing to ask, no error
    assert plant_vehicles("bare_plant:build") == ()
