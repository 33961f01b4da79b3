"""Ground facts decided by rigorous interval arithmetic: arb balls (python-flint), over the exact rationals of
the scene's floats.

A fact of certification ("this clause holds on the scene, its Range bounds as printed") is a sign condition on
polynomials in the scene's floats, the rationals of a few float constants (unit vectors, cos delta: the same
constants the solver is given, synth.geometry) and printed decimals. Every float becomes an exact ball (radius 0),
a printed decimal a ball that contains it, and every arb operation returns a ball that contains the exact result
(arb rounds outward). So when a ball lies wholly on one side of a boundary, the exact value does too, and the
fact is decided, as the solver would decide it; a ball that straddles the boundary (the exact value is within
rounding of it) decides nothing (None), and the caller asks the solver. No decision is ever taken on a rounded
value: this is not float geometry.
"""

from __future__ import annotations

from collections.abc import Callable
from fractions import Fraction

from flint import arb

from synth.geometry import exact_cos_squared, exact_heading_vector

Fact = bool | None  # decided true, decided false, or undecided


def ball(v: float | int | Fraction) -> arb:
    """A ball that contains v exactly (radius 0 for a float or an int)."""
    if isinstance(v, Fraction):
        return arb(v.numerator) / v.denominator
    return arb(v)


def offset(ref, e) -> tuple[arb, arb]:
    """e - ref (anything with x and y)."""
    return arb(e.x) - arb(ref.x), arb(e.y) - arb(ref.y)


def positive(x: arb) -> Fact:
    if x > 0:
        return True
    if x <= 0:
        return False
    return None


def nonnegative(x: arb) -> Fact:
    if x >= 0:
        return True
    if x < 0:
        return False
    return None


def all_of(*facts: Fact) -> Fact:
    """Conjunction: false if any is false, true if all are true, else undecided."""
    if any(f is False for f in facts):
        return False
    return True if all(facts) else None


def between(lo: Fraction, v: arb, hi: Fraction) -> Fact:
    """lo <= v <= hi."""
    return all_of(nonnegative(v - ball(lo)), nonnegative(ball(hi) - v))


def cone(vx: arb, vy: arb, axis_heading: float, delta: float) -> Fact:
    """v lies within delta of the axis: v.u > 0 and (v.u)^2 >= cos^2(delta) |v|^2 (synth.tables, the solver's
    encoding), u and cos^2(delta) the rationals of their floats."""
    ux, uy = (ball(c) for c in exact_heading_vector(axis_heading))
    dot = vx * ux + vy * uy
    ahead = positive(dot)
    if ahead is False:
        return False
    return all_of(ahead, nonnegative(dot * dot - ball(exact_cos_squared(delta)) * (vx * vx + vy * vy)))


def centring_value(b: arb, exact: Callable[[], Fraction]) -> Fraction:
    """A rational that centres a Range exactly as the exact value in the ball b does.

    Ranges have widths in cents and start at the centre minus half the width, rounded to cents (synth.ranges), so
    the Range changes only where the centre crosses a multiple of 1/200. When the ball lies strictly inside one
    such cell, so does the exact value, and the ball's midpoint (an exact dyadic rational) gives the same Range;
    otherwise (a ball on or across a multiple of 1/200) the exact value is computed.
    """
    t = b * 200
    cell = t.floor().unique_fmpz()
    if cell is None or not t > cell:
        return exact()
    m, e = b.mid().man_exp()
    m, e = int(m), int(e)
    return Fraction(m * 2**e) if e >= 0 else Fraction(m, 2**-e)
