"""The mathematics of robust synthesis: relations and Ranges that hold for every scene within the measurement error.

Every entity but ego may be anywhere in a disc of radius rho around its recorded position and face anywhere
within eta degrees of its recorded heading (ego is the frame's origin, exact by construction, unless the scene
gives it a sigma). A relation is used only if it holds for all of them; every Range covers all of them.

Both relations are one question, "v lies within delta of the axis a": for direction relations v = e - r and the
axis is r.heading + phi (eta of the reference); for facing relations v = +-(e - r) and the axis is e.heading
(eta of the target). Two exact reductions turn "for every perturbation" into a question about one cone:

1. Headings. With s = the signed angle from v's bearing to the axis, "W(bearing, axis + theta) <= delta for every
   theta in [-eta, eta]" holds iff |s| <= delta - eta. (<=) |s + theta| <= |s| + eta <= delta < 180, so the
   folded difference is |s + theta| <= delta. (=>) take theta = eta * sign(s) (eta when s = 0): if |s| + eta <=
   180 the difference is |s| + eta, which must be <= delta; if |s| + eta > 180 some theta in between makes it
   exactly 180 > delta. So heading uncertainty narrows the cone to delta' = delta - eta; eta >= delta leaves
   no cone (we refuse cones narrower than MIN_CONE, which can only drop relations, never add one).
2. Positions. {p_e - p_r} over the two discs is the disc D(c, R), c = e - r, R = rho_e + rho_r (Minkowski
   sum of discs). A cone of half-angle delta' < 90 is the intersection of the two half-planes n_i . v >= 0
   whose unit normals n_i point inward from its edges (headings axis + delta' - 90 and axis - delta' + 90);
   a disc lies in a half-plane iff n . c >= R. So D(c, R) is inside the cone iff min_i n_i . c >= R
   (with R = 0 also c != 0, since v = 0 has no bearing). The floats decide that with a guard band.

The floats are a pre-filter only: outside the guard band they answer, inside it the solver decides the
existentially quantified violation (ExactBackend.robust_cone: is there a v in the disc outside the cone? unsat =
the relation holds), and the closed-form oracle answers "no" (conservative: a relation is never claimed that
might not hold). Ranges are computed from exact rationals and rounded outward to cents.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from synth.config import SynthConfig
from synth.geometry import exact_heading_vector, exact_offset
from synth.scene import Entity
from synth.syntax import Range
from synth.tables import GUARD

# Narrowest cone (degrees) a robust relation may use. Below it, cos^2 of the rounded constant no longer pins
# the angle to well inside the guard band, so such a relation is dropped (conservative).
MIN_CONE = 0.01
_CENT = Fraction(1, 100)


@dataclass(frozen=True)
class Bounds:
    """How far one entity may be from its record: pos metres (disc radius), heading degrees (each side), speed m/s
    (each side, never below 0)."""

    pos: float = 0.0
    heading: float = 0.0
    speed: float = 0.0


def bounds_of(e: Entity, config: SynthConfig) -> Bounds:
    """The entity's own sigma where it has one, else the configured uncertainty (ego: 0, it is the origin; its
    speed comes from odometry, far more precise than perception's). Speed bounds count only with motion on."""
    pos = e.pos_sigma if e.pos_sigma is not None else (0.0 if e.is_ego else config.pos_uncertainty)
    head = e.heading_sigma if e.heading_sigma is not None else (0.0 if e.is_ego else config.heading_uncertainty)
    speed = 0.0
    if config.motion:
        speed = e.speed_sigma if e.speed_sigma is not None else (0.0 if e.is_ego else config.speed_uncertainty)
    return Bounds(float(pos), float(head), float(speed))


def speed_box(e: Entity, config: SynthConfig) -> tuple[Fraction, Fraction]:
    """Every speed e may have had, exactly: [max(0, s - sigma), s + sigma] (a speed is a magnitude)."""
    s, sigma = Fraction(e.speed), Fraction(bounds_of(e, config).speed)
    return max(Fraction(0), s - sigma), s + sigma


def narrowed(delta: float, eta: float) -> float | None:
    """delta' = delta - eta (reduction 1), or None when no cone is left to use."""
    d = delta - eta
    return d if d >= MIN_CONE else None


def narrowed_cones(delta: float, etas: np.ndarray) -> np.ndarray:
    """narrowed() elementwise, NaN where no cone is left (what disc_in_cone takes)."""
    return np.array([np.nan if (c := narrowed(delta, float(t))) is None else c for t in etas])


# ---------------------------------------------------------------------------------------------- floats


def disc_in_cone(vx, vy, radius, axis, cone) -> tuple[np.ndarray, np.ndarray]:
    """(holds, undecided) of reduction 2, elementwise; cone = delta' in degrees, NaN where there is none."""
    a = np.radians(axis)
    d = np.radians(np.nan_to_num(cone, nan=0.0))
    # Inward normals of the two edges (headings axis + d - 90 and axis - d + 90); heading h has (-sin h, cos h).
    n1 = vx * -np.sin(a + d - np.pi / 2) + vy * np.cos(a + d - np.pi / 2)
    n2 = vx * -np.sin(a - d + np.pi / 2) + vy * np.cos(a - d + np.pi / 2)
    margin = np.minimum(n1, n2) - radius
    scale = np.hypot(vx, vy) + radius
    usable = ~np.isnan(cone) & (scale > 0.0)
    tol = GUARD * np.where(scale > 0.0, scale, 1.0)
    return usable & (margin > tol), usable & (np.abs(margin) <= tol)


# ---------------------------------------------------------------------------------------------- exact Ranges


def _sqrt_bracket(x: Fraction, digits: int = 15) -> tuple[Fraction, Fraction]:
    """lo <= sqrt(x) <= hi with hi - lo = 10^-digits, from integer square roots (exact)."""
    scale = 10**digits
    scaled = x * scale * scale
    root = math.isqrt(math.floor(scaled))
    exact = root * root == scaled  # a perfect square (3-4-5 offsets): no need to round up
    return Fraction(root, scale), Fraction(root if exact else root + 1, scale)


def _floor_cents(v: Fraction) -> Fraction:
    return Fraction(math.floor(v / _CENT)) * _CENT


def _ceil_cents(v: Fraction) -> Fraction:
    return Fraction(math.ceil(v / _CENT)) * _CENT


def covering(lo_needed: Fraction, hi_needed: Fraction, width: float, clamp_at_zero: bool = False) -> Range:
    """The narrowest cent-aligned Range, at least `width` wide (C_dist, C_head), around [lo_needed, hi_needed].

    When the observed interval is narrower than the width, the Range is centred on it, as plain synthesis
    centres on the observed value; otherwise it is the interval rounded outward to cents.
    """
    w = Fraction(round(Fraction(width) / _CENT)) * _CENT
    mid = (lo_needed + hi_needed) / 2
    lo = Fraction(round((mid - w / 2) / _CENT)) * _CENT
    if clamp_at_zero and lo < 0:
        lo = Fraction(0)
    if lo <= lo_needed and lo + w >= hi_needed:
        return Range(float(lo), float(lo + w))
    lo, hi = _floor_cents(lo_needed), _ceil_cents(hi_needed)
    if clamp_at_zero and lo < 0:
        lo = Fraction(0)
    return Range(float(lo), float(max(hi, lo + w)))


def _rotation_up(eta: float) -> Fraction:
    """Upper bound of |Rot(theta) a - a| / |a| = sqrt(2 (1 - cos theta)) over the rotations the solver allows.

    The solver encodes theta in [-eta, eta] as cos theta >= K with K the rational of the float cos(eta); the
    bound uses that same K, so what is widened here is exactly what certification checks.
    """
    if eta == 0.0:
        return Fraction(0)
    k = Fraction(math.cos(math.radians(eta)))
    return _sqrt_bracket(2 * (1 - k))[1]


def distance_range(target: Entity, ref: Entity, radius: Fraction, width: float) -> Range:
    """`by Range`: every centre distance |p_e - p_r| in [d - R, d + R] (and >= 0)."""
    vx, vy = exact_offset(ref, target)
    d_lo, d_hi = _sqrt_bracket(vx * vx + vy * vy)
    return covering(max(d_lo - radius, Fraction(0)), d_hi + radius, width, clamp_at_zero=True)


def local_ranges(target: Entity, ref: Entity, radius: Fraction, eta_ref: float, width: float) -> tuple[Range, Range]:
    """`on Range @ Range relative to ref`: the perturbed local vector is within s of the observed one, with
    s = |u| (R + |c| rot(eta)): the offset moves by at most R, the reference's frame turns it by at most rot."""
    vx, vy = exact_offset(ref, target)
    ux, uy = exact_heading_vector(ref.heading)
    # The solver's local frame (cos t = uy, sin t = -ux) is the rational u, |u| within 1e-16 of 1: bound it.
    u_up = (1 + ux * ux + uy * uy) / 2  # >= |u| (AM-GM)
    c_up = _sqrt_bracket(vx * vx + vy * vy)[1]
    spread = u_up * (radius + c_up * _rotation_up(eta_ref))
    lateral, forward = vx * uy - vy * ux, vy * uy + vx * ux
    return (covering(lateral - spread, lateral + spread, width), covering(forward - spread, forward + spread, width))


def observed_angle(heading: float, base: float) -> Fraction:
    """The heading offset in (-180, 180], exactly."""
    gap = Fraction(heading) - Fraction(base)
    alpha = gap - 360 * math.floor(gap / 360)  # [0, 360)
    return alpha - 360 if alpha > 180 else alpha


def angle_range(target: Entity, ref: Entity, eta_target: float, eta_ref: float, width: float) -> Range:
    """`facing Range deg relative to ref`: the offset moves by at most eta_e + eta_r (linear, exact)."""
    alpha = observed_angle(target.heading, ref.heading)
    spread = Fraction(eta_target) + Fraction(eta_ref)
    return covering(alpha - spread, alpha + spread, width)


def radius_of(a: Entity, b: Entity, config: SynthConfig) -> Fraction:
    """R = rho_a + rho_b, exactly (a float sum could round below the true one)."""
    return Fraction(bounds_of(a, config).pos) + Fraction(bounds_of(b, config).pos)
