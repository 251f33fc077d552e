"""The stimulus messages each vehicle's network reads (besides BENCH_Control, which every scenario sends).

A scenario sends only these (`bench.start_scenario(stimulus=STIMULUS[vehicle])`): a 4WIS EV's bus carries no
steering-robot or ABS stimulus. Derived, not kept by hand: the plant of this project (bench.toml [bench] plant)
declares what each vehicle's behaviours read, and the bench's public `bench.plugins.plant_stimulus` passes it
on, so test cases never import the plant.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from functools import cache
from pathlib import Path

from bench.config import find_config, load_config
from bench.plugins import plant_stimulus, plant_vehicles


@cache
def _plant() -> str:
    """The plant of the project these cases belong to (the bench.toml above this folder)."""
    return load_config(find_config(Path(__file__).resolve().parent)).plant


class _Stimulus(Mapping[str, tuple[str, ...]]):
    """vehicle name -> its stimulus messages, asked of the plant when first needed."""

    def __getitem__(self, vehicle: str) -> tuple[str, ...]:
        if vehicle not in plant_vehicles(_plant()):
            raise KeyError(vehicle)
        return plant_stimulus(_plant(), vehicle)

    def __iter__(self) -> Iterator[str]:
        return iter(plant_vehicles(_plant()))

    def __len__(self) -> int:
        return len(plant_vehicles(_plant()))


STIMULUS: Mapping[str, tuple[str, ...]] = _Stimulus()
