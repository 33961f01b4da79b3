"""Range synthesis: fixed widths (C_dist, C_head), centred on the observed value, printed with 2 decimals.

Centring leaves half a width of slack on each side, far more than the 0.005 that rounding to 2 decimals can
move a bound, so the printed program still contains the scene (the solver certifies the printed bounds).
"""

from __future__ import annotations

from fractions import Fraction
from functools import lru_cache

from synth.syntax import Range

_CENT = Fraction(1, 100)


@lru_cache(maxsize=64)
def _cents(width: float) -> int:
    """A width in whole cents."""
    return round(Fraction(width) / _CENT)


def centred(value: Fraction | float, width: float, clamp_at_zero: bool = False) -> Range:
    """Range(a, a + width) with a = value - width / 2 rounded to cents (half to even, as round() does) and >= 0
    for distances. In whole cents: a = round(100 value - W / 2) for a width of W cents, in integers."""
    w = _cents(width)
    v = Fraction(value)
    # 100 v - w / 2 = (200 p - w q) / (2 q) for v = p / q; round() of a Fraction rounds half to even.
    lo = round(Fraction(200 * v.numerator - w * v.denominator, 2 * v.denominator))
    if clamp_at_zero and lo < 0:
        lo = 0
    return Range(float(Fraction(lo, 100)), float(Fraction(lo + w, 100)))
