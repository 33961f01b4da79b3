"""HEADING, the heading part (paper, Fig. 3):

    facing (toward | away from) REF                                 cost 0
    facing Range(a, b) deg relative to REF                          cost 1
    facing Range(a, b) deg                                          cost 2

`facing toward REF`: W(e.heading, bearing(e -> REF)) <= delta2 (`away from`: bearing(REF -> e)): the cone test
with axis e.heading and v = +-(e - REF). `facing Range(a, b) deg relative to REF`: e.heading = REF.heading + alpha,
alpha in [a, b] (mod 360).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from fractions import Fraction
from typing import TYPE_CHECKING, Any

import numpy as np

from synth import intervals
from synth.config import SynthConfig
from synth.draws import HEADING as HEADING_FIELD
from synth.draws import REACH_SLACK, XY, Arc, Draws, Pose, Reach
from synth.geometry import (
    angular_difference,
    bearing,
    exact_cos_squared,
    exact_heading_vector,
    exact_offset,
    normalize,
    signed,
)
from synth.parts.base import Clause, Part
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


class HeadingClause(Clause):
    """What the heading clauses share: the checker's view of an entity's heading."""

    def observed(self, e: Entity) -> str:
        return f"heading {e.heading:.3f}"


@dataclass(frozen=True)
class FacingRelation(HeadingClause):
    """`facing toward | away from REF`: cost 0."""

    mode: str
    ref: str
    cost = 0
    text = "facing {c.words} {c.ref}"
    labels = FACING_NAMES
    label_field = "mode"
    drawn_as = "facing"

    @property
    def words(self) -> str:
        return FACINGS[self.mode]

    @property
    def sign(self) -> int:
        """toward: the cone test on REF - e; away: on e - REF."""
        return -1 if self.mode == "toward" else 1

    def holds(self, e: Entity, ref: Entity | None, config: SynthConfig) -> bool:
        if (e.x, e.y) == (ref.x, ref.y):
            return False
        if self.mode == "toward":
            target = bearing(e.x, e.y, ref.x, ref.y)
        else:
            target = bearing(ref.x, ref.y, e.x, e.y)
        return angular_difference(e.heading, target) <= config.delta2 + ANGLE_EPS

    def decide(self, e: Entity, ref: Entity | None, config: SynthConfig) -> bool | None:
        vx, vy = intervals.offset(ref, e)
        if self.mode == "toward":
            vx, vy = -vx, -vy
        return intervals.cone(vx, vy, e.heading, config.delta2)

    def formula(self, backend: ExactBackend, e: Entity, ref: Entity | None) -> Any:
        vx, vy = backend.offset(ref, e)
        if self.mode == "toward":
            vx, vy = -vx, -vy
        return backend.cone(vx, vy, e.heading, backend.config.delta2)

    def violations(self, backend: ExactBackend, e: Entity, ref: Entity | None) -> list[Any]:
        cfg = backend.config
        cx, cy = exact_offset(ref, e)
        vx, vy, cons = backend.perturbed_offset((self.sign * cx, self.sign * cy), radius_of(ref, e, cfg))
        return [backend.cone_fails(vx, vy, cons, e.heading, narrowed(cfg.delta2, bounds_of(e, cfg).heading))]

    def scenic(self, at: str) -> str:
        return f"dsl__facing_{'toward' if self.mode == 'toward' else 'away_from'}({self.ref}, {at})"

    def needs_own_position(self) -> bool:
        return True

    def draws(self, config: SynthConfig) -> FacingDraws:
        return FacingDraws(self.ref, (-config.delta2,), (config.delta2,), self.mode == "toward")


class AngleClause(HeadingClause):
    """`facing Range deg [relative to REF]`: e.heading = N(base + alpha), alpha in the Range, where base is REF's
    heading (0 without a reference)."""

    angle: Range

    def holds(self, e: Entity, ref: Entity | None, config: SynthConfig) -> bool:
        return _in_angle_range(e.heading, 0.0 if ref is None else ref.heading, self.angle)

    def decide(self, e: Entity, ref: Entity | None, config: SynthConfig) -> bool | None:
        # angle_in's question, whose terms are rationals of the floats and printed bounds: exact and cheap.
        lo, hi = printed(self.angle.lo), printed(self.angle.hi)
        gap = Fraction(e.heading) - Fraction(0.0 if ref is None else ref.heading)
        alpha = gap - 360 * ((gap - lo) // 360)
        return lo <= alpha <= hi

    def formula(self, backend: ExactBackend, e: Entity, ref: Entity | None) -> Any:
        return backend.angle_in(e.heading, 0.0 if ref is None else ref.heading, printed(self.angle.lo),
                                printed(self.angle.hi))

    def violations(self, backend: ExactBackend, e: Entity, ref: Entity | None) -> list[Any]:
        const, cfg = backend.constant, backend.config
        lo, hi = printed(self.angle.lo), printed(self.angle.hi)
        # The branch k that puts the observed offset just above lo (as angle_in): the perturbed offsets move
        # continuously by less than half a turn, so within the Range they stay on that branch.
        gap = Fraction(e.heading) - Fraction(ref.heading if ref else 0.0)
        alpha = gap - 360 * ((gap - lo) // 360)
        eta = Fraction(bounds_of(e, cfg).heading) + (Fraction(bounds_of(ref, cfg).heading) if ref else 0)
        turn = backend.var("theta")
        return [backend.And(-const(eta) <= turn, turn <= const(eta), bad)
                for bad in (const(alpha) + turn < const(lo), const(alpha) + turn > const(hi))]

    def draws(self, config: SynthConfig) -> AngleDraws:
        return AngleDraws(self.ref, (self.angle.lo,), (self.angle.hi,))

    def hull(self, mine: Range, theirs: Range) -> Range:
        """Angles are on a circle: `theirs` is first turned by whole turns to lie nearest `mine` (an offset near
        180 deg is measured as 179 in one frame and -179 in the next: one Range of 12 deg holds both, where the
        hull on a line would span the circle)."""
        turns = round(((mine.lo + mine.hi) - (theirs.lo + theirs.hi)) / 720.0)
        lo, hi = theirs.lo + 360.0 * turns, theirs.hi + 360.0 * turns
        return Range(min(mine.lo, lo), max(mine.hi, hi))


@dataclass(frozen=True)
class RelativeHeading(AngleClause):
    """`facing Range deg relative to REF`: cost 1."""

    angle: Range
    ref: str
    cost = 1
    text = "facing {c.angle} deg relative to {c.ref}"
    labels = ("relative heading",)
    drawn_as = "relative_heading"

    def scenic(self, at: str) -> str:
        return f"{self.ref}.heading + {self.angle} deg"


@dataclass(frozen=True)
class AbsoluteHeading(AngleClause):
    """`facing Range deg`: cost 2."""

    angle: Range
    cost = 2
    ref = None
    text = "facing {c.angle} deg"
    labels = ("absolute heading",)
    drawn_as = "absolute_heading"

    def scenic(self, at: str) -> str:
        return f"{self.angle} deg"


def _in_angle_range(heading: float, base: float, rng: Range) -> bool:
    """Is heading = N(base + alpha) for some alpha in rng? Measured as an offset past rng.lo, mod 360."""
    if rng.hi - rng.lo >= 360.0:
        return True
    past = normalize(heading - base - rng.lo)
    # Just below 360 means just below rng.lo: inside within rounding.
    return past <= (rng.hi - rng.lo) + ANGLE_EPS or past >= 360.0 - ANGLE_EPS


# ------------------------------------------------------------------------------------------- what Scenic draws

@dataclass(frozen=True)
class FacingDraws(Draws):
    """`facing toward | away from REF`: dsl__facing_* draws an offset in +-delta2 about the bearing."""

    toward: bool
    writes = HEADING_FIELD
    reads = (XY,)
    reads_own = (XY,)

    def _target(self, own: Pose, ref: Pose) -> float:
        if self.toward:
            return bearing(own.x, own.y, ref.x, ref.y)
        return bearing(ref.x, ref.y, own.x, own.y)

    def evaluate(self, p: Sequence[float], own: Pose, ref: Pose | None) -> None:
        own.heading = normalize(self._target(own, ref) + p[0])

    def invert(self, own: Pose, ref: Pose | None) -> tuple[float, ...]:
        return (signed(own.heading - self._target(own, ref)),)

    def reach(self, own: Reach, ref: Reach | None) -> Reach:
        d = math.hypot(own.x - ref.x, own.y - ref.y)
        spread = own.r + ref.r
        if d <= spread:
            return Reach(own.x, own.y, own.r, Arc(0.0, 180.0))
        centre = bearing(own.x, own.y, ref.x, ref.y) if self.toward else bearing(ref.x, ref.y, own.x, own.y)
        half = math.degrees(math.asin(spread / d)) + self.hi[0] + REACH_SLACK
        return Reach(own.x, own.y, own.r, Arc(centre, min(180.0, half)))


@dataclass(frozen=True)
class AngleDraws(Draws):
    """`facing Range(a, b) deg [relative to REF]`: the angle drawn, added to REF's heading where there is one."""

    writes = HEADING_FIELD

    @property
    def reads(self) -> tuple[str, ...]:
        return () if self.ref is None else (HEADING_FIELD,)

    def evaluate(self, p: Sequence[float], own: Pose, ref: Pose | None) -> None:
        own.heading = normalize(p[0] if ref is None else ref.heading + p[0])

    def invert(self, own: Pose, ref: Pose | None) -> tuple[float, ...]:
        offset = own.heading if ref is None else own.heading - ref.heading
        return (_angle_near(offset, self.lo[0], self.hi[0]),)

    def reach(self, own: Reach, ref: Reach | None) -> Reach:
        if ref is None:
            half = (self.hi[0] - self.lo[0]) / 2 + REACH_SLACK
            return Reach(own.x, own.y, own.r, Arc(normalize((self.lo[0] + self.hi[0]) / 2), min(180.0, half)))
        half = ref.heading.half + (self.hi[0] - self.lo[0]) / 2 + REACH_SLACK
        mid = ref.heading.mid + (self.lo[0] + self.hi[0]) / 2
        return Reach(own.x, own.y, own.r, Arc(normalize(mid), min(180.0, half)))


def _angle_near(angle: float, lo: float, hi: float) -> float:
    """The representative of `angle` (mod 360) in [lo, hi], or outside it the one nearest to it."""
    a = lo + normalize(angle - lo)
    return a if a <= hi or a - hi < (lo + 360.0) - a else a - 360.0


class HeadingPart(Part):
    name = "heading"
    relations = FACING_NAMES
    keyword = "facing"
    clauses = (FacingRelation, RelativeHeading, AbsoluteHeading)

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

    # ------------------------------------------------------------------------------- exact, without a solver
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

HEADING = HeadingPart()
