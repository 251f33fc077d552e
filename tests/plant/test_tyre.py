"""Magic Formula tyre (plant/tyre.py, docs/spec/vehicles.md B): pure slip against the formula typed here, the peaks
docs/spec/vehicles.md states, the slope, and the combined-slip properties the module documents."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plant.braking_vehicle import DRY, WET, road_shape
from plant.tyre import CombinedSlipTyre, Shape, lateral_b


def mf(x: float, b: float, c: float, d: float, e: float) -> float:
    """docs/spec/vehicles.md B: D sin(C atan(B x - E (B x - atan(B x)))), typed independently of plant/tyre.py."""
    return d * math.sin(c * math.atan(b * x - e * (b * x - math.atan(b * x))))


DRY_BCDE = (10.0, 1.9, 1.0, 0.97)
WET_BCDE = (12.0, 2.3, 0.82, 1.0)
LATERAL = Shape(8.0, 1.3, -1.0)


@pytest.mark.parametrize("shape,bcde", [(DRY[0], DRY_BCDE), (WET[0], WET_BCDE)], ids=["dry", "wet"])
@pytest.mark.parametrize("slip", [-1.0, -0.5, -0.18, -0.05, 0.0, 0.01, 0.088, 0.18, 0.3, 1.0])
def test_pure_longitudinal_is_the_magic_formula(shape: Shape, bcde: tuple, slip: float) -> None:
    b, c, d, e = bcde
    tyre = CombinedSlipTyre(shape, LATERAL)
    fx, fy = tyre.forces(slip, 0.0, d * 4000.0)
    assert fx == pytest.approx(4000.0 * mf(slip, b, c, d, e), rel=1e-12, abs=1e-9)
    assert fy == 0.0


def test_peaks_where_vehicles_md_says() -> None:
    # docs/spec/vehicles.md B: dry peak at slip 0.18; the wet curve (B 12, C 2.3, E 1) peaks at 0.088
    assert DRY[0].peak() == pytest.approx(0.18, abs=0.001)
    assert WET[0].peak() == pytest.approx(0.0882, abs=0.001)
    scan = max(range(1, 5000), key=lambda i: mf(i / 10000, *DRY_BCDE))
    assert DRY[0].peak() == pytest.approx(scan / 10000, abs=2e-4)
    assert Shape(5.0, 0.9, 0.0).peak() == 1.0        # no peak below C = 1: saturating curve


@given(st.floats(-0.9, 0.9))
def test_slope_is_the_derivative(x: float) -> None:
    s, h = DRY[0], 1e-6
    assert s.slope(x) == pytest.approx((s.value(x + h) - s.value(x - h)) / (2 * h), rel=1e-5, abs=1e-5)


@settings(max_examples=200)
@given(kappa=st.floats(-1.0, 1.0), alpha=st.floats(-1.2, 1.2), fz=st.floats(100.0, 8000.0))
def test_combined_slip_stays_in_the_friction_ellipse(kappa: float, alpha: float, fz: float) -> None:
    tyre = CombinedSlipTyre(DRY[0], LATERAL)
    fx, fy = tyre.forces(kappa, alpha, fz)
    assert (fx / fz) ** 2 + (fy / fz) ** 2 <= 1.0 + 1e-9        # both peaks are D = 1 here
    assert math.copysign(1, fx) == math.copysign(1, kappa) or fx == 0.0
    assert math.copysign(1, fy) == math.copysign(1, alpha) or fy == 0.0
    # odd in each slip
    fx2, fy2 = tyre.forces(-kappa, -alpha, fz)
    assert fx2 == pytest.approx(-fx, abs=1e-9) and fy2 == pytest.approx(-fy, abs=1e-9)


def test_pure_lateral_and_locked_wheel() -> None:
    tyre = CombinedSlipTyre(DRY[0], LATERAL)
    fx, fy = tyre.forces(0.0, 0.05, 3000.0)
    assert fx == 0.0 and fy == pytest.approx(3000.0 * mf(0.05, 8.0, 1.3, 1.0, -1.0), rel=1e-12)
    # a locked wheel at a small slip angle keeps little side force (why ABS keeps the car steerable)
    _, fy_locked = tyre.forces(-1.0, math.radians(5), 3000.0)
    _, fy_rolling = tyre.forces(0.0, math.radians(5), 3000.0)
    assert abs(fy_locked) < 0.15 * abs(fy_rolling)


def test_lateral_b_gives_the_axle_cornering_stiffness() -> None:
    # docs/spec/vehicles.md B: C_f = 85 000 N/rad per axle; front static wheel load 1350 g 1.59 / 2.65 / 2
    fz = 1350 * 9.81 * 1.59 / 2.65 / 2
    b = lateral_b(85000.0, fz, 1.3)
    tyre = CombinedSlipTyre(DRY[0], Shape(b, 1.3, -1.0))
    a = 1e-5
    assert 2 * tyre.forces(0.0, a, fz)[1] / a == pytest.approx(85000.0, rel=1e-6)
    with pytest.raises(ValueError):
        lateral_b(0.0, fz, 1.3)


def test_road_shape_picks_the_set_by_mu() -> None:
    assert road_shape(1.0) is DRY[0] and road_shape(0.91) is DRY[0]
    assert road_shape(0.82) is WET[0] and road_shape(0.3) is WET[0]


@pytest.mark.parametrize("args", [(0.0, 1.9, 0.97), (10.0, -1.0, 0.0), (10.0, 1.9, 1.5), (10.0, 1.9, math.nan)])
def test_bad_shapes_are_refused(args: tuple) -> None:
    with pytest.raises(ValueError, match="Magic Formula"):
        Shape(*args)


@settings(max_examples=300, deadline=None)
@given(st.sampled_from([DRY[0], WET[0]]), st.floats(-1.5, 1.5), st.floats(-1.6, 1.6), st.floats(-10.0, 1e4))
def test_forces_and_slope_is_the_separate_calls_bit_for_bit(shape: Shape, kappa: float, alpha: float,
                                                            fz_mu: float) -> None:
    """The vehicle's one-call path (a cost cut) must give exactly what forces() and long_slope() give."""
    tyre = CombinedSlipTyre(shape, LATERAL)
    separate = (*tyre.forces(kappa, alpha, fz_mu), tyre.long_slope(kappa, fz_mu))
    assert repr(tyre.forces_and_slope(kappa, alpha, fz_mu)) == repr(separate)     # repr: -0.0 is not 0.0
