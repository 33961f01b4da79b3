"""Range synthesis: fixed widths (C_dist, C_head), centred on the observed value, printed with 2 decimals.

Centring leaves half a width of slack on each side, far more than the 0.005 that rounding to 2 decimals can
move a bound, so the printed program still contains the scene (the solver certifies the printed bounds).
"""

from __future__ import annotations

from fractions import Fraction

from synth.syntax import Range

_CENT = Fraction(1, 100)


def _round_cents(v: Fraction) -> Fraction:
    return Fraction(round(v / _CENT)) * _CENT


def centred(value: Fraction | float, width: float, clamp_at_zero: bool = False) -> Range:
    """Range(a, a + width) with a = value - width / 2 rounded to cents (and >= 0 for distances)."""
    w = _round_cents(Fraction(width))
    lo = _round_cents(Fraction(value) - w / 2)
    if clamp_at_zero and lo < 0:
        lo = Fraction(0)
    return Range(float(lo), float(lo + w))
