"""Angles and bearings of the ego-centric frame, in one place.

Frame: metres, +x right, +y forward; headings in degrees, counter-clockwise from +y, in [0, 360).
Everything here is the paper's N, W and beta, plus the exact (rational) unit vectors the oracles share so
that float and solver decisions use the very same constants.
"""

from __future__ import annotations

import math
from fractions import Fraction
from functools import lru_cache


def normalize(angle: float) -> float:
    """N(alpha): the same direction in [0, 360)."""
    a = math.fmod(angle, 360.0)
    if a < 0.0:
        a += 360.0
    # fmod of a tiny negative number plus 360 rounds to 360.0 exactly.
    return 0.0 if a >= 360.0 else a


def signed(angle: float) -> float:
    """The same direction in (-180, 180]."""
    a = normalize(angle)
    return a - 360.0 if a > 180.0 else a


def angular_difference(u: float, v: float) -> float:
    """W(u, v): the unsigned difference of two directions, in [0, 180]."""
    d = abs(normalize(u) - normalize(v))
    return 360.0 - d if d > 180.0 else d


def bearing(from_x: float, from_y: float, to_x: float, to_y: float) -> float:
    """beta: the heading of the ray from (from_x, from_y) to (to_x, to_y), in [0, 360).

    atan2 measures from +x; headings start at +y, hence the -90 degrees.
    """
    return normalize(math.degrees(math.atan2(to_y - from_y, to_x - from_x)) - 90.0)


def heading_vector(heading: float) -> tuple[float, float]:
    """Unit vector of a heading (0 deg = +y, counter-clockwise)."""
    r = math.radians(normalize(heading))
    return (-math.sin(r), math.cos(r))


@lru_cache(maxsize=65536)
def exact_heading_vector(heading: float) -> tuple[Fraction, Fraction]:
    """heading_vector as exact rationals of its float components.

    Trigonometry has no exact rational value; the oracles agree to take the correctly rounded float as the
    constant and then reason exactly about it, so closed form and SMT answer the same question.
    """
    ux, uy = heading_vector(heading)
    return (Fraction(ux), Fraction(uy))


@lru_cache(maxsize=64)
def exact_cos_squared(delta: float) -> Fraction:
    """cos^2(delta) of a tolerance, as the exact rational of the float."""
    c = Fraction(math.cos(math.radians(delta)))
    return c * c


def exact_offset(ref, e) -> tuple[Fraction, Fraction]:
    """e - ref (anything with x and y) in exact rationals of the floats."""
    return Fraction(e.x) - Fraction(ref.x), Fraction(e.y) - Fraction(ref.y)


def sqrt_rational(s: Fraction, digits: int = 15) -> Fraction:
    """sqrt(s) of a rational s >= 0: exact where it is rational, else rounded down to `digits` decimals."""
    p, q = s.numerator, s.denominator
    rp, rq = math.isqrt(p), math.isqrt(q)
    if rp * rp == p and rq * rq == q:
        return Fraction(rp, rq)
    scale = 10**digits
    # floor(sqrt(x)) == isqrt(floor(x)) for real x >= 0.
    return Fraction(math.isqrt(p * scale * scale // q), scale)


def to_local(dx: float, dy: float, ref_heading: float) -> tuple[float, float]:
    """(dx, dy) in a reference's frame: lateral lx (+ = the reference's right), forward ly.

    The paper's lx = dx cos t + dy sin t, ly = dy cos t - dx sin t, with t the reference heading.
    """
    t = math.radians(ref_heading)
    c, s = math.cos(t), math.sin(t)
    return (dx * c + dy * s, dy * c - dx * s)
