"""HEADING, the heading part (paper, Fig. 3):

    facing (toward | away from) REF                                 cost 0
    facing Range(a, b) deg relative to REF                          cost 1
    facing Range(a, b) deg                                          cost 2

`facing toward REF`: W(e.heading, bearing(e -> REF)) <= delta2 (`away from`: bearing(REF -> e)): the cone test
with axis e.heading and v = +-(e - REF). `facing Range(a, b) deg relative to REF`: e.heading = REF.heading + alpha,
alpha in [a, b] (mod 360).
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction
from typing import TYPE_CHECKING, Any

import numpy as np

from synth import intervals
from synth.config import SynthConfig
from synth.geometry import (
    angular_difference,
    bearing,
    exact_cos_squared,
    exact_heading_vector,
    exact_offset,
    normalize,
    signed,
)
from synth.parts.base import Clause, ClauseKind, Part
from synth.perturbation import Bounds, angle_range, bounds_of, disc_in_cone, narrowed, narrowed_cones, radius_of
from synth.ranges import centred
from synth.scene import Entity
from synth.syntax import Line, Range, printed
from synth.tables import NONE, SceneArrays, exact_within, mark, no_self_witness, unit_vectors, within

if TYPE_CHECKING:
    from synth.smt.backend import ExactBackend, SolverBackend

FACINGS: dict[str, str] = {"toward": "toward", "away": "away from"}
FACING_NAMES = ("toward", "away")  # index = code in the tables
ANGLE_EPS = 1e-9


@dataclass(frozen=True)
class FacingRelation:
    """`facing toward | away from REF`: cost 0."""

    mode: str
    ref: str
    cost = 0

    def __str__(self) -> str:
        return f"facing {FACINGS[self.mode]} {self.ref}"


@dataclass(frozen=True)
class RelativeHeading:
    """`facing Range deg relative to REF`: cost 1."""

    angle: Range
    ref: str
    cost = 1

    def __str__(self) -> str:
        return f"facing {self.angle} deg relative to {self.ref}"


@dataclass(frozen=True)
class AbsoluteHeading:
    """`facing Range deg`: cost 2."""

    angle: Range
    cost = 2
    ref = None

    def __str__(self) -> str:
        return f"facing {self.angle} deg"


def _in_angle_range(heading: float, base: float, rng: Range) -> bool:
    """Is heading = N(base + alpha) for some alpha in rng? Measured as an offset past rng.lo, mod 360."""
    if rng.hi - rng.lo >= 360.0:
        return True
    past = normalize(heading - base - rng.lo)
    # Just below 360 means just below rng.lo: inside within rounding.
    return past <= (rng.hi - rng.lo) + ANGLE_EPS or past >= 360.0 - ANGLE_EPS


class HeadingPart(Part):
    name = "heading"
    relations = FACING_NAMES
    keyword = "facing"
    clause_kinds = (
        *(ClauseKind(mode, FacingRelation, "facing", ("mode", mode)) for mode in FACING_NAMES),
        ClauseKind("relative heading", RelativeHeading, "relative_heading"),
        ClauseKind("absolute heading", AbsoluteHeading, "absolute_heading"),
    )

    def perturbed(self, b: Bounds) -> bool:
        return b.pos != 0.0 or b.heading != 0.0

    # ------------------------------------------------------------------------------- float table, exact
    def closed_form(self, arrays: SceneArrays, config: SynthConfig) -> np.ndarray:
        x, y = arrays.x, arrays.y
        dx = x[None, :] - x[:, None]  # [r, e] = e - r
        dy = y[None, :] - y[:, None]
        dist = np.hypot(dx, dy)
        cos2 = float(np.cos(np.radians(config.delta2)))
        codes = np.full(dx.shape, NONE, dtype=np.int8)
        hx, hy = unit_vectors(arrays.heading)
        # toward r: e's heading vector against (r - e); away: against (e - r).
        toward = -(dx * hx[None, :] + dy * hy[None, :])
        for code, dot in enumerate((toward, -toward)):
            mark(codes, code, *within(dot, dist, cos2))
        return no_self_witness(codes)

    def robust_closed_form(self, arrays: SceneArrays, bounds: list[Bounds], config: SynthConfig) -> np.ndarray:
        x, y, h = arrays.x, arrays.y, arrays.heading
        rho = np.array([b.pos for b in bounds])
        eta = np.array([b.heading for b in bounds])
        dx = x[None, :] - x[:, None]
        dy = y[None, :] - y[:, None]
        radius = rho[:, None] + rho[None, :]
        codes = np.full(dx.shape, NONE, dtype=np.int8)
        cone = narrowed_cones(config.delta2, eta)[None, :] + np.zeros_like(dx)  # the target's heading is perturbed
        axis = h[None, :] + np.zeros_like(dx)
        for code, sign in enumerate((-1.0, 1.0)):  # toward: v = r - e; away: v = e - r
            mark(codes, code, *disc_in_cone(sign * dx, sign * dy, radius, axis, cone))
        return no_self_witness(codes)

    def exact(self, code: int, ref: Entity, e: Entity, config: SynthConfig) -> bool:
        vx, vy = exact_offset(ref, e)
        if FACING_NAMES[code] == "toward":
            vx, vy = -vx, -vy
        return exact_within(vx, vy, exact_heading_vector(e.heading), exact_cos_squared(config.delta2))

    # ------------------------------------------------------------------------------- SMT
    def relation(self, backend: SolverBackend, code: int, ref: Entity, e: Entity) -> bool:
        vx, vy = backend.offset(ref, e)
        if FACING_NAMES[code] == "toward":
            vx, vy = -vx, -vy
        return backend.check(backend.cone(vx, vy, e.heading, backend.config.delta2))

    def robust_relation(self, backend: ExactBackend, code: int, ref: Entity, e: Entity) -> bool:
        cfg = backend.config
        cx, cy = exact_offset(ref, e)
        sign = -1 if FACING_NAMES[code] == "toward" else 1
        cone = narrowed(cfg.delta2, bounds_of(e, cfg).heading)
        return backend.robust_cone((sign * cx, sign * cy), radius_of(ref, e, cfg), e.heading, cone)

    def any_relation(self, backend: ExactBackend, ref: Entity, e: Entity) -> Any:
        vx, vy = backend.offset(ref, e)
        delta = backend.config.delta2
        return backend.Or(backend.cone(-vx, -vy, e.heading, delta), backend.cone(vx, vy, e.heading, delta))

    def measure_terms(self, backend: ExactBackend, quantity: str, target: Entity, ref: Entity) -> tuple[list, list]:
        base = ref.heading if quantity == "angle" else 0.0
        # The offset in (-180, 180]: headings are in [0, 360), so one of three turns fits.
        gap = Fraction(target.heading) - Fraction(base)
        alpha = backend.var("alpha")
        turns = backend.Or(*(alpha == backend.constant(gap - 360 * k) for k in (-1, 0, 1)))
        return [alpha > -180, alpha <= 180, turns], [alpha]

    def formula(self, backend: ExactBackend, clause: Clause, e: Entity, ref: Entity | None) -> Any:
        if isinstance(clause, AbsoluteHeading):
            return backend.angle_in(e.heading, 0.0, printed(clause.angle.lo), printed(clause.angle.hi))
        if isinstance(clause, RelativeHeading):
            return backend.angle_in(e.heading, ref.heading, printed(clause.angle.lo), printed(clause.angle.hi))
        vx, vy = backend.offset(ref, e)
        if clause.mode == "toward":
            vx, vy = -vx, -vy
        return backend.cone(vx, vy, e.heading, backend.config.delta2)

    def violations(self, backend: ExactBackend, clause: Clause, e: Entity, ref: Entity | None) -> list[Any]:
        const, cfg = backend.constant, backend.config
        if isinstance(clause, FacingRelation):
            sign = -1 if clause.mode == "toward" else 1
            cx, cy = exact_offset(ref, e)
            vx, vy, cons = backend.perturbed_offset((sign * cx, sign * cy), radius_of(ref, e, cfg))
            return [backend.cone_fails(vx, vy, cons, e.heading, narrowed(cfg.delta2, bounds_of(e, cfg).heading))]
        lo, hi = printed(clause.angle.lo), printed(clause.angle.hi)
        # The branch k that puts the observed offset just above lo (as angle_in): the perturbed offsets move
        # continuously by less than half a turn, so within the Range they stay on that branch.
        gap = Fraction(e.heading) - Fraction(ref.heading if ref else 0.0)
        alpha = gap - 360 * ((gap - lo) // 360)
        eta = Fraction(bounds_of(e, cfg).heading) + (Fraction(bounds_of(ref, cfg).heading) if ref else 0)
        turn = backend.var("theta")
        return [backend.And(-const(eta) <= turn, turn <= const(eta), bad)
                for bad in (const(alpha) + turn < const(lo), const(alpha) + turn > const(hi))]

    # ------------------------------------------------------------------------------- exact, without a solver
    def decide(self, clause: Clause, e: Entity, ref: Entity | None, config: SynthConfig) -> bool | None:
        if isinstance(clause, FacingRelation):
            vx, vy = intervals.offset(ref, e)
            if clause.mode == "toward":
                vx, vy = -vx, -vy
            return intervals.cone(vx, vy, e.heading, config.delta2)
        # angle_in's question, whose terms are rationals of the floats and printed bounds: exact and cheap.
        lo, hi = printed(clause.angle.lo), printed(clause.angle.hi)
        gap = Fraction(e.heading) - Fraction(ref.heading if isinstance(clause, RelativeHeading) else 0.0)
        alpha = gap - 360 * ((gap - lo) // 360)
        return lo <= alpha <= hi

    def exact_measure(self, quantity: str, target: Entity, ref: Entity) -> tuple[Fraction, ...]:
        base = ref.heading if quantity == "angle" else 0.0
        gap = Fraction(target.heading) - Fraction(base)
        # The one of gap, gap +- 360 in (-180, 180], as measure_terms has the solver find it.
        return (next(a for a in (gap + 360, gap, gap - 360) if -180 < a <= 180),)

    # ------------------------------------------------------------------------------- Alg. 4
    def quantity(self, code: int) -> str | None:
        return None if code != NONE else "angle"

    def float_measure(self, quantity: str, target: Entity, ref: Entity) -> tuple[Fraction, ...]:
        base = ref.heading if quantity == "angle" else 0.0
        return (Fraction(signed(target.heading - base)),)

    def clause(self, code: int, ref_id: str, values: tuple[Fraction, ...], config: SynthConfig) -> Clause:
        if code != NONE:
            return FacingRelation(FACING_NAMES[code], ref_id)
        return RelativeHeading(centred(values[0], config.c_head), ref_id)

    def robust_clause(self, code: int, target: Entity, ref: Entity, config: SynthConfig) -> Clause:
        if code != NONE:
            return FacingRelation(FACING_NAMES[code], ref.id)
        angle = angle_range(target, ref, bounds_of(target, config).heading, bounds_of(ref, config).heading,
                            config.c_head)
        return RelativeHeading(angle, ref.id)

    # ------------------------------------------------------------------------------- semantics
    def holds(self, clause: Clause, e: Entity, ref: Entity | None, config: SynthConfig) -> bool:
        if isinstance(clause, AbsoluteHeading):
            return _in_angle_range(e.heading, 0.0, clause.angle)
        assert ref is not None
        if isinstance(clause, RelativeHeading):
            return _in_angle_range(e.heading, ref.heading, clause.angle)
        if isinstance(clause, FacingRelation):
            if (e.x, e.y) == (ref.x, ref.y):
                return False
            if clause.mode == "toward":
                target = bearing(e.x, e.y, ref.x, ref.y)
            else:
                target = bearing(ref.x, ref.y, e.x, e.y)
            return angular_difference(e.heading, target) <= config.delta2 + ANGLE_EPS
        raise TypeError(f"not a heading: {clause!r}")

    def observed(self, e: Entity) -> str:
        return f"heading {e.heading:.3f}"

    # ------------------------------------------------------------------------------- syntax
    def parse(self, ln: Line, declared: set[str]) -> Clause:
        ln.take(text="facing")
        if ln.accept("toward"):
            return FacingRelation("toward", ln.reference(declared))
        if ln.accept("away"):
            ln.take(text="from")
            return FacingRelation("away", ln.reference(declared))
        angle = ln.range_()
        ln.take(text="deg")
        if ln.accept("relative"):
            ln.take(text="to")
            return RelativeHeading(angle, ln.reference(declared))
        return AbsoluteHeading(angle)

    # ------------------------------------------------------------------------------- Scenic
    def scenic(self, clause: Clause, at: str) -> str:
        if isinstance(clause, FacingRelation):
            return f"dsl__facing_{'toward' if clause.mode == 'toward' else 'away_from'}({clause.ref}, {at})"
        if isinstance(clause, RelativeHeading):
            return f"{clause.ref}.heading + {clause.angle} deg"
        if isinstance(clause, AbsoluteHeading):
            return f"{clause.angle} deg"
        raise TypeError(f"not a DSL heading: {clause!r}")

    def needs_own_position(self, clause: Clause) -> bool:
        return isinstance(clause, FacingRelation)

    # ------------------------------------------------------------------------------- report

HEADING = HeadingPart()
