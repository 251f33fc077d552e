"""Magic Formula tyre (docs/spec/vehicles.md B): longitudinal and lateral pure slip, combined by normalised slip.

Pure slip (Pacejka's Magic Formula, per unit of normal load and friction):

    f(x) = sin(C atan(B x - E (B x - atan(B x))))          force = D * Fz * f(x), D = road friction

Longitudinal x = slip ratio kappa = (omega R - V) / V (braking: kappa < 0). docs/spec/vehicles.md B gives the dry
set B = 10, C = 1.9, E = 0.97, D = mu = 1.0 (peak at kappa = 0.18) and the wet set B = 12, C = 2.3,
E = 1.0, D = 0.82 (peak at kappa = 0.088). Lateral x = slip angle alpha (rad): shape C_y, E_y (chosen,
plant/vehicles/abs.toml) and B_y per axle such that B_y C_y D Fz_static equals the axle cornering
stiffness of docs/spec/vehicles.md B split over its two wheels, so the linear range is the car of
docs/spec/vehicles.md B.

Combined slip (documented choice, a "normalised slip" weighting, not Pacejka's full G-functions):
each slip is normalised by the slip at its own peak, s_x = kappa / kappa_peak, s_y = alpha / alpha_peak,
s = hypot(s_x, s_y), and

    Fx = (s_x / s) D Fz f_x(s kappa_peak)        Fy = (s_y / s) D Fz f_y(s alpha_peak)

Pure slip is reproduced exactly; the resultant stays inside the ellipse of the two peak forces; a locked
wheel (kappa = -1) keeps only a small lateral force (about sin(alpha) of the sliding force), which is what
makes a locked front axle unsteerable and what an ABS preserves.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

_atan, _sin, _cos, _sqrt = math.atan, math.sin, math.cos, math.sqrt


@dataclass(frozen=True, slots=True)
class Shape:
    """B, C, E of one Magic Formula curve (D, the friction, is applied by the caller)."""

    b: float
    c: float
    e: float

    def __post_init__(self) -> None:
        if not (self.b > 0.0 and self.c > 0.0 and self.e <= 1.0 and math.isfinite(self.e)):
            raise ValueError(f"Magic Formula shape needs B > 0, C > 0, finite E <= 1; got {self}")

    def value(self, x: float) -> float:
        """f(x) for D = 1 (odd in x)."""
        bx = self.b * x
        return _sin(self.c * _atan(bx - self.e * (bx - _atan(bx))))

    def slope(self, x: float) -> float:
        """df/dx (for the implicit wheel-spin integration)."""
        b, c, e = self.b, self.c, self.e
        bx = b * x
        inner = bx - e * (bx - _atan(bx))
        dinner = b - e * (b - b / (1.0 + bx * bx))
        return c * _cos(c * _atan(inner)) * dinner / (1.0 + inner * inner)

    def peak(self) -> float:
        """x > 0 of the peak: C atan(inner) = pi/2. A curve without a peak (C <= 1) saturates: 1.0."""
        if self.c <= 1.0:
            return 1.0
        target = math.tan(math.pi / (2.0 * self.c))
        lo, hi = 0.0, 1.0
        while self.b * hi - self.e * (self.b * hi - _atan(self.b * hi)) < target:
            hi *= 2.0
            if hi > 1e6:
                return 1.0
        for _ in range(80):
            mid = 0.5 * (lo + hi)
            bx = self.b * mid
            if bx - self.e * (bx - _atan(bx)) < target:
                lo = mid
            else:
                hi = mid
        return 0.5 * (lo + hi)


class CombinedSlipTyre:
    """One tyre: pure longitudinal and lateral Magic Formula curves and their combination (module doc)."""

    __slots__ = ("long", "lat", "kappa_peak", "alpha_peak", "_bce")

    def __init__(self, longitudinal: Shape, lateral: Shape) -> None:
        self.long = longitudinal
        self.lat = lateral
        self.kappa_peak = longitudinal.peak()
        self.alpha_peak = lateral.peak()
        self._bce = (longitudinal.b, longitudinal.c, longitudinal.e, lateral.b, lateral.c, lateral.e)

    def forces(self, kappa: float, alpha: float, fz_mu: float) -> tuple[float, float]:
        """(Fx, Fy) in the wheel frame, N, for slip ratio kappa, slip angle alpha (rad) and fz_mu = D * Fz.

        Fx has the sign of kappa (traction positive); Fy has the sign of alpha (the caller negates it to
        oppose the lateral sliding)."""
        if fz_mu <= 0.0:
            return 0.0, 0.0
        kp, ap = self.kappa_peak, self.alpha_peak
        sx = kappa / kp
        sy = alpha / ap
        s = math.sqrt(sx * sx + sy * sy)
        if s < 1e-12:
            return 0.0, 0.0
        fx = sx / s * fz_mu * self.long.value(s * kp)
        fy = sy / s * fz_mu * self.lat.value(s * ap)
        return fx, fy

    def forces_and_slope(self, kappa: float, alpha: float, fz_mu: float) -> tuple[float, float, float]:
        """(`forces`..., `long_slope`) in one call: the vehicle's wheel loop needs all three every tick. The same
        expressions as Shape.value and Shape.slope written out (the results are bit for bit those of the
        separate calls; tests/plant/test_tyre.py checks it)."""
        bl, cl, el, by, cy, ey = self._bce
        bx = bl * kappa
        inner = bx - el * (bx - _atan(bx))
        slope = fz_mu * (cl * _cos(cl * _atan(inner)) * (bl - el * (bl - bl / (1.0 + bx * bx))) / (1.0 + inner * inner))
        if fz_mu <= 0.0:
            return 0.0, 0.0, slope
        kp, ap = self.kappa_peak, self.alpha_peak
        sx = kappa / kp
        sy = alpha / ap
        s = _sqrt(sx * sx + sy * sy)
        if s < 1e-12:
            return 0.0, 0.0, slope
        bx = bl * (s * kp)
        fx = sx / s * fz_mu * _sin(cl * _atan(bx - el * (bx - _atan(bx))))
        bx = by * (s * ap)
        fy = sy / s * fz_mu * _sin(cy * _atan(bx - ey * (bx - _atan(bx))))
        return fx, fy, slope

    def long_slope(self, kappa: float, fz_mu: float) -> float:
        """dFx/dkappa of the pure longitudinal curve, N per unit slip (>= 0 is used for stiffness)."""
        return fz_mu * self.long.slope(kappa)


def lateral_b(axle_cornering_stiffness: float, static_wheel_load: float, c: float) -> float:
    """B_y such that one wheel's cornering stiffness B C D Fz (D = 1 at mu = 1) is half the axle's
    (docs/spec/vehicles.md B gives C_f, C_r per axle)."""
    if not (axle_cornering_stiffness > 0.0 and static_wheel_load > 0.0 and c > 0.0):
        raise ValueError("lateral_b needs a positive cornering stiffness, wheel load and C")
    return axle_cornering_stiffness / 2.0 / (c * static_wheel_load)
