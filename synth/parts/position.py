"""POS, the position part (paper, Fig. 3):

    (ahead of | behind | left of | right of) REF by Range(a, b)      cost 0
    on Range(a, b) @ Range(c, d) relative to REF                    cost 1
    on Range(a, b) @ Range(c, d)                                    cost 2

`dir REF by Range(a, b)`: centre distance to REF in [a, b] and W(bearing(REF -> e), REF.heading + phi) <= delta1
(phi = 0 ahead, 90 left, 180 behind, 270 right): the cone test with v = e - REF. `on ... relative to REF`:
lateral lx = dx cos t + dy sin t, forward ly = dy cos t - dx sin t with t = REF.heading.
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
from synth.draws import HEADING, REACH_SLACK, XY, Draws, Pose, Reach, disc_plus, rotated
from synth.geometry import (
    angular_difference,
    bearing,
    exact_cos_squared,
    exact_heading_vector,
    exact_offset,
    signed,
    sqrt_rational,
    to_local,
)
from synth.parts.base import Clause, Part
from synth.perturbation import (
    Bounds,
    bounds_of,
    disc_in_cone,
    distance_range,
    local_ranges,
    narrowed,
    narrowed_cones,
    radius_of,
)
from synth.ranges import centred
from synth.scene import Entity
from synth.syntax import DslError, Line, Range, fmt_number, printed
from synth.tables import NONE, SceneArrays, exact_within, mark, no_self_witness, unit_vectors, within

if TYPE_CHECKING:
    from synth.smt.backend import ExactBackend, SolverBackend

# Direction -> (printed words, phi in degrees, counter-clockwise from the reference's heading).
DIRECTIONS: dict[str, tuple[str, float]] = {
    "ahead": ("ahead of", 0.0),
    "left": ("left of", 90.0),
    "behind": ("behind", 180.0),
    "right": ("right of", 270.0),
}
DIRECTION_NAMES = tuple(DIRECTIONS)  # ahead, left, behind, right: index = code in the tables
MIN_DISTANCE = 0.05  # metres: a sector's distance is drawn from here at least (synth.scenic.emit says why)
LENGTH_EPS = 1e-9
ANGLE_EPS = 1e-9


class PositionClause(Clause):
    """What the position clauses share: the checker's view of where an entity is, and the Scenic `at`."""

    def observed(self, e: Entity) -> str:
        return f"({e.x:.3f}, {e.y:.3f})"

    @staticmethod
    def _outside(backend: ExactBackend, v: Any, rng: Range) -> list[Any]:
        const = backend.constant
        return [v < const(printed(rng.lo)), v > const(printed(rng.hi))]


@dataclass(frozen=True)
class DirectionPos(PositionClause):
    """`ahead of | behind | left of | right of REF by Range`: cost 0."""

    direction: str
    ref: str
    distance: Range
    cost = 0
    text = "{c.words} {c.ref} by {c.distance}"
    labels = ("ahead", "behind", "left", "right")
    label_field = "direction"
    drawn_as = "sector"

    @property
    def words(self) -> str:
        return DIRECTIONS[self.direction][0]

    @property
    def axis(self) -> float:
        """phi: the sector's axis, counter-clockwise from the reference's heading."""
        return DIRECTIONS[self.direction][1]

    def holds(self, e: Entity, ref: Entity | None, config: SynthConfig) -> bool:
        dist = math.hypot(e.x - ref.x, e.y - ref.y)
        if dist == 0.0 or not self.distance.contains(dist, LENGTH_EPS):
            return False
        axis = ref.heading + self.axis
        return angular_difference(bearing(ref.x, ref.y, e.x, e.y), axis) <= config.delta1 + ANGLE_EPS

    def decide(self, e: Entity, ref: Entity | None, config: SynthConfig) -> bool | None:
        vx, vy = intervals.offset(ref, e)
        lo, hi = max(printed(self.distance.lo), Fraction(0)), printed(self.distance.hi)
        sq = vx * vx + vy * vy
        return intervals.all_of(intervals.between(lo * lo, sq, hi * hi),
                                intervals.cone(vx, vy, ref.heading + self.axis, config.delta1))

    def formula(self, backend: ExactBackend, e: Entity, ref: Entity | None) -> Any:
        const = backend.constant
        vx, vy = backend.offset(ref, e)
        lo, hi = printed(self.distance.lo), printed(self.distance.hi)
        # lo <= |v| <= hi with 0 <= lo, squared: no square root, a ground formula.
        return backend.And(
            const(max(lo, Fraction(0)) ** 2) <= vx * vx + vy * vy, vx * vx + vy * vy <= const(hi * hi),
            backend.cone(vx, vy, ref.heading + self.axis, backend.config.delta1),
        )

    def violations(self, backend: ExactBackend, e: Entity, ref: Entity | None) -> list[Any]:
        """p_e - p_r ranges over the disc of radius rho_e + rho_r (Minkowski sum); the sector narrows by
        reduction 1."""
        const, cfg = backend.constant, backend.config
        vx, vy, cons = backend.perturbed_offset(exact_offset(ref, e), radius_of(ref, e, cfg))
        lo, hi = max(printed(self.distance.lo), Fraction(0)), printed(self.distance.hi)
        sq = vx * vx + vy * vy
        return [backend.And(*cons, sq < const(lo * lo)), backend.And(*cons, sq > const(hi * hi)),
                backend.cone_fails(vx, vy, cons, ref.heading + self.axis,
                                   narrowed(cfg.delta1, bounds_of(ref, cfg).heading))]

    def scenic(self, at: str) -> str:
        return f"dsl__sector_{self.direction}({self.ref}, {_scenic_distance(self.distance)})"

    def draws(self, config: SynthConfig) -> SectorDraws:
        d0, d1 = sampled_distance(self.distance)
        return SectorDraws(self.ref, (d0, -config.delta1), (d1, config.delta1), self.axis)


@dataclass(frozen=True)
class LocalXYPos(PositionClause):
    """`on Range @ Range relative to REF`: lateral @ forward in REF's frame, cost 1."""

    lateral: Range
    forward: Range
    ref: str
    cost = 1
    text = "on {c.lateral} @ {c.forward} relative to {c.ref}"
    labels = ("relative position",)
    drawn_as = "relative_xy"

    def holds(self, e: Entity, ref: Entity | None, config: SynthConfig) -> bool:
        lx, ly = to_local(e.x - ref.x, e.y - ref.y, ref.heading)
        return self.lateral.contains(lx, LENGTH_EPS) and self.forward.contains(ly, LENGTH_EPS)

    def decide(self, e: Entity, ref: Entity | None, config: SynthConfig) -> bool | None:
        vx, vy = intervals.offset(ref, e)
        ux, uy = (intervals.ball(c) for c in exact_heading_vector(ref.heading))
        lx, ly = vx * uy - vy * ux, vy * uy + vx * ux
        return intervals.all_of(intervals.between(printed(self.lateral.lo), lx, printed(self.lateral.hi)),
                                intervals.between(printed(self.forward.lo), ly, printed(self.forward.hi)))

    def formula(self, backend: ExactBackend, e: Entity, ref: Entity | None) -> Any:
        const = backend.constant
        vx, vy = backend.offset(ref, e)
        ux, uy = (const(c) for c in exact_heading_vector(ref.heading))
        lx, ly = vx * uy - vy * ux, vy * uy + vx * ux
        return backend.And(
            const(printed(self.lateral.lo)) <= lx, lx <= const(printed(self.lateral.hi)),
            const(printed(self.forward.lo)) <= ly, ly <= const(printed(self.forward.hi)),
        )

    def violations(self, backend: ExactBackend, e: Entity, ref: Entity | None) -> list[Any]:
        """The reference frame turns by (c, s) on the unit circle with c >= cos(eta), the rational of the float
        cos(eta) (the constant synth.perturbation widens by), and p_e - p_r moves in a disc.

        Rot(c, s) L_u (c0 + w) = Rot(c, s) a + b, where a = L_u c0 is the observed local vector and b =
        Rot(c, s) L_u w runs over the disc of radius |u| R (L_u is |u| times a rotation, and rotations map a disc
        about 0 onto itself). Same set, but no products of unknowns: nlsat takes ms here where the literal
        product of the turn and the disc took it up to a minute."""
        const, cfg = backend.constant, backend.config
        cx, cy = exact_offset(ref, e)
        ux, uy = exact_heading_vector(ref.heading)
        ax, ay = cx * uy - cy * ux, cy * uy + cx * ux
        lx, ly, cons = const(ax), const(ay), []
        eta = bounds_of(ref, cfg).heading
        if eta > 0:
            c, s = backend.var("c"), backend.var("s")
            cons += [c * c + s * s == 1, c >= const(Fraction(math.cos(math.radians(eta))))]
            lx, ly = c * const(ax) - s * const(ay), s * const(ax) + c * const(ay)
        radius = radius_of(ref, e, cfg)
        if radius > 0:
            bx, by = backend.var("bx"), backend.var("by")
            cons.append(bx * bx + by * by <= const(radius * radius * (ux * ux + uy * uy)))
            lx, ly = lx + bx, ly + by
        bad = self._outside(backend, lx, self.lateral) + self._outside(backend, ly, self.forward)
        return [backend.And(*cons, b) for b in bad]

    def scenic(self, at: str) -> str:
        return f"dsl__relative_xy({self.ref}, {self.lateral}, {self.forward})"

    def draws(self, config: SynthConfig) -> RelativeXYDraws:
        return RelativeXYDraws(self.ref, (self.lateral.lo, self.forward.lo), (self.lateral.hi, self.forward.hi))


@dataclass(frozen=True)
class AbsoluteXYPos(PositionClause):
    """`on Range @ Range`: x @ y in the scene frame, cost 2."""

    x: Range
    y: Range
    cost = 2
    ref = None
    text = "on {c.x} @ {c.y}"
    labels = ("absolute position",)
    drawn_as = "absolute_position"

    def holds(self, e: Entity, ref: Entity | None, config: SynthConfig) -> bool:
        return self.x.contains(e.x, LENGTH_EPS) and self.y.contains(e.y, LENGTH_EPS)

    def decide(self, e: Entity, ref: Entity | None, config: SynthConfig) -> bool | None:
        # Rational comparisons of the floats with the printed bounds: exact and cheap.
        return all(printed(b.lo) <= Fraction(v) <= printed(b.hi) for b, v in ((self.x, e.x), (self.y, e.y)))

    def formula(self, backend: ExactBackend, e: Entity, ref: Entity | None) -> Any:
        const = backend.constant
        pairs = ((self.x, e.x), (self.y, e.y))
        return backend.And(*(const(printed(b.lo)) <= const(v) for b, v in pairs),
                           *(const(v) <= const(printed(b.hi)) for b, v in pairs))

    def violations(self, backend: ExactBackend, e: Entity, ref: Entity | None) -> list[Any]:
        """The entity anywhere in the disc of its own position bound."""
        const = backend.constant
        rho = Fraction(bounds_of(e, backend.config).pos)
        wx, wy = backend.var("wx"), backend.var("wy")
        disc = wx * wx + wy * wy <= const(rho * rho)
        x, y = const(e.x) + wx, const(e.y) + wy
        return [backend.And(disc, bad) for bad in self._outside(backend, x, self.x) + self._outside(backend, y, self.y)]

    def scenic(self, at: str) -> str:
        return f"({self.x} @ {self.y})"

    def draws(self, config: SynthConfig) -> AbsoluteXYDraws:
        return AbsoluteXYDraws(None, (self.x.lo, self.y.lo), (self.x.hi, self.y.hi))


# ------------------------------------------------------------------------------------------- what Scenic draws

def _sector_disc(mid: float, half: float, r0: float, r1: float) -> tuple[float, float, float]:
    """A disc (cx, cy, radius) holding every point at a distance in [r0, r1] and a direction within half of mid.

    The centre lies on the sector's axis, at rho from its apex. The squared distance from there to a sector point
    at (r, a) is rho^2 + r^2 - 2 rho r cos(a - mid): largest at |a - mid| = half and, convex in r, at r0 or r1.
    So the radius is exact for that centre; rho is the best of a few.
    """
    if half >= 180.0:
        return (0.0, 0.0, r1)
    cw = math.cos(math.radians(half))
    rho, rad = min(((rho, max(math.sqrt(max(0.0, rho * rho + r * r - 2 * rho * r * cw)) for r in (r0, r1)))
                    for rho in (r1 * k / 8 for k in range(9))), key=lambda t: t[1])
    ox, oy = rotated(mid, 0.0, rho)
    return (ox, oy, rad)


@dataclass(frozen=True)
class SectorDraws(Draws):
    """`DIR of REF by Range(a, b)`: dsl__sector draws (distance, angle offset in +-delta1)."""

    phi: float  # the sector's axis, from REF's heading
    writes = XY
    reads = (XY, HEADING)

    def evaluate(self, p: Sequence[float], own: Pose, ref: Pose | None) -> None:
        dx, dy = rotated(ref.heading + self.phi + p[1], 0.0, p[0])
        own.x, own.y = ref.x + dx, ref.y + dy

    def invert(self, own: Pose, ref: Pose | None) -> tuple[float, ...]:
        d = math.hypot(own.x - ref.x, own.y - ref.y)
        u = signed(bearing(ref.x, ref.y, own.x, own.y) - ref.heading - self.phi) if d > 0 else 0.0
        return (d, u)

    def area(self, p: Sequence[float], ref: Pose | None) -> float:
        return p[0]  # polar coordinates: a step in (distance, angle) sweeps distance times as much plane

    def reach(self, own: Reach, ref: Reach | None) -> Reach:
        half = ref.heading.half + self.hi[1]
        cx, cy, r = _sector_disc(ref.heading.mid + self.phi, half, self.lo[0], self.hi[0])
        return disc_plus(ref, cx, cy, r, own.heading)


@dataclass(frozen=True)
class RelativeXYDraws(Draws):
    """`on Range @ Range relative to REF`: dsl__relative_xy draws (lateral, forward) in REF's frame."""

    writes = XY
    reads = (XY, HEADING)

    def evaluate(self, p: Sequence[float], own: Pose, ref: Pose | None) -> None:
        dx, dy = rotated(ref.heading, p[0], p[1])
        own.x, own.y = ref.x + dx, ref.y + dy

    def invert(self, own: Pose, ref: Pose | None) -> tuple[float, ...]:
        return to_local(own.x - ref.x, own.y - ref.y, ref.heading)

    def reach(self, own: Reach, ref: Reach | None) -> Reach:
        mx, my = (self.lo[0] + self.hi[0]) / 2, (self.lo[1] + self.hi[1]) / 2
        corner = math.hypot(self.hi[0] - mx, self.hi[1] - my)
        m = math.hypot(mx, my)
        # The rectangle's centre turns with REF's heading: a chord of at most 2 m sin(half / 2).
        half = min(ref.heading.half, 180.0)
        chord = 2 * m * math.sin(math.radians(half) / 2)
        dx, dy = rotated(ref.heading.mid, mx, my)
        return disc_plus(ref, dx, dy, corner + chord, own.heading)


@dataclass(frozen=True)
class AbsoluteXYDraws(Draws):
    """`on Range @ Range`: x and y drawn in the scene frame."""

    writes = XY

    def evaluate(self, p: Sequence[float], own: Pose, ref: Pose | None) -> None:
        own.x, own.y = p[0], p[1]

    def invert(self, own: Pose, ref: Pose | None) -> tuple[float, ...]:
        return (own.x, own.y)

    def reach(self, own: Reach, ref: Reach | None) -> Reach:
        mx, my = (self.lo[0] + self.hi[0]) / 2, (self.lo[1] + self.hi[1]) / 2
        return Reach(mx, my, math.hypot(self.hi[0] - mx, self.hi[1] - my) + REACH_SLACK, own.heading)


class PositionPart(Part):
    name = "position"
    relations = DIRECTION_NAMES
    keyword = "at"
    clauses = (DirectionPos, LocalXYPos, AbsoluteXYPos)

    def perturbed(self, b: Bounds) -> bool:
        return b.pos != 0.0 or b.heading != 0.0

    # ------------------------------------------------------------------------------- float table, exact
    def closed_form(self, arrays: SceneArrays, config: SynthConfig) -> np.ndarray:
        x, y, h = arrays.x, arrays.y, arrays.heading
        dx = x[None, :] - x[:, None]  # [r, e] = e - r
        dy = y[None, :] - y[:, None]
        dist = np.hypot(dx, dy)
        cos1 = float(np.cos(np.radians(config.delta1)))
        codes = np.full(dx.shape, NONE, dtype=np.int8)
        for code, name in enumerate(DIRECTION_NAMES):
            ux, uy = unit_vectors(h + DIRECTIONS[name][1])
            mark(codes, code, *within(dx * ux[:, None] + dy * uy[:, None], dist, cos1))
        return no_self_witness(codes)

    def robust_closed_form(self, arrays: SceneArrays, bounds: list[Bounds], config: SynthConfig) -> np.ndarray:
        x, y, h = arrays.x, arrays.y, arrays.heading
        rho = np.array([b.pos for b in bounds])
        eta = np.array([b.heading for b in bounds])
        dx = x[None, :] - x[:, None]
        dy = y[None, :] - y[:, None]
        radius = rho[:, None] + rho[None, :]
        codes = np.full(dx.shape, NONE, dtype=np.int8)
        cone = narrowed_cones(config.delta1, eta)[:, None] + np.zeros_like(dx)  # the reference's heading is perturbed
        for code, name in enumerate(DIRECTION_NAMES):
            axis = (h + DIRECTIONS[name][1])[:, None] + np.zeros_like(dx)
            mark(codes, code, *disc_in_cone(dx, dy, radius, axis, cone))
        return no_self_witness(codes)

    def exact(self, code: int, ref: Entity, e: Entity, config: SynthConfig) -> bool:
        vx, vy = exact_offset(ref, e)
        u = exact_heading_vector(ref.heading + DIRECTIONS[DIRECTION_NAMES[code]][1])
        return exact_within(vx, vy, u, exact_cos_squared(config.delta1))

    # ------------------------------------------------------------------------------- SMT
    def relation(self, backend: SolverBackend, code: int, ref: Entity, e: Entity) -> bool:
        """Is there a Range(a, a + C_dist), a >= 0, such that `e = ... direction ref by Range(a, ...)` holds?"""
        cfg = backend.config
        vx, vy = backend.offset(ref, e)
        a = backend.var("a")
        return backend.check(
            a >= 0,
            backend.distance_in(vx, vy, a, a + backend.constant(cfg.c_dist)),
            backend.cone(vx, vy, ref.heading + DIRECTIONS[DIRECTION_NAMES[code]][1], cfg.delta1),
        )

    def robust_relation(self, backend: ExactBackend, code: int, ref: Entity, e: Entity) -> bool:
        """Does it hold for every perturbation? The Range then widens to cover every distance (robust_clause),
        so only the sector is in question."""
        cfg = backend.config
        cone = narrowed(cfg.delta1, bounds_of(ref, cfg).heading)
        return backend.robust_cone(exact_offset(ref, e), radius_of(ref, e, cfg),
                                   ref.heading + DIRECTIONS[DIRECTION_NAMES[code]][1], cone)

    def any_relation(self, backend: ExactBackend, ref: Entity, e: Entity) -> Any:
        vx, vy = backend.offset(ref, e)
        return backend.Or(*(backend.cone(vx, vy, ref.heading + phi, backend.config.delta1)
                            for _, phi in DIRECTIONS.values()))

    def measure_terms(self, backend: ExactBackend, quantity: str, target: Entity, ref: Entity) -> tuple[list, list]:
        vx, vy = backend.offset(ref, target)
        if quantity == "distance":
            d = backend.var("d")
            return [d >= 0, d * d == vx * vx + vy * vy], [d]
        ux, uy = (backend.constant(c) for c in exact_heading_vector(ref.heading))
        # cos t = uy, sin t = -ux for the heading vector (-sin t, cos t).
        lx, ly = backend.var("lx"), backend.var("ly")
        return [lx == vx * uy - vy * ux, ly == vy * uy + vx * ux], [lx, ly]

    # ------------------------------------------------------------------------------- exact, without a solver
    def exact_measure(self, quantity: str, target: Entity, ref: Entity) -> tuple[Fraction, ...]:
        vx, vy = intervals.offset(ref, target)
        if quantity == "distance":
            return (intervals.centring_value((vx * vx + vy * vy).sqrt(), lambda: self._exact(quantity, target, ref)[0]),)
        ux, uy = (intervals.ball(c) for c in exact_heading_vector(ref.heading))
        lx, ly = vx * uy - vy * ux, vy * uy + vx * ux
        return (intervals.centring_value(lx, lambda: self._exact(quantity, target, ref)[0]),
                intervals.centring_value(ly, lambda: self._exact(quantity, target, ref)[1]))

    @staticmethod
    def _exact(quantity: str, target: Entity, ref: Entity) -> tuple[Fraction, ...]:
        vx, vy = exact_offset(ref, target)
        if quantity == "distance":
            return (sqrt_rational(vx * vx + vy * vy),)
        ux, uy = exact_heading_vector(ref.heading)
        return (vx * uy - vy * ux, vy * uy + vx * ux)

    # ------------------------------------------------------------------------------- Alg. 4
    def quantity(self, code: int) -> str | None:
        return "distance" if code != NONE else "local"

    def float_measure(self, quantity: str, target: Entity, ref: Entity) -> tuple[Fraction, ...]:
        if quantity == "distance":
            return (Fraction(math.hypot(target.x - ref.x, target.y - ref.y)),)
        lx, ly = to_local(target.x - ref.x, target.y - ref.y, ref.heading)
        return (Fraction(lx), Fraction(ly))

    def solver_measure(self, backend: SolverBackend, quantity: str, target: Entity, ref: Entity) -> tuple[Fraction, ...]:
        if quantity != "distance":
            return self.float_measure(quantity, target, ref)
        return (backend.distance_value(target.x - ref.x, target.y - ref.y),)

    def clause(self, code: int, ref_id: str, values: tuple[Fraction, ...], config: SynthConfig) -> Clause:
        if code != NONE:
            return DirectionPos(DIRECTION_NAMES[code], ref_id, centred(values[0], config.c_dist, True))
        return LocalXYPos(centred(values[0], config.c_dist), centred(values[1], config.c_dist), ref_id)

    def robust_clause(self, code: int, target: Entity, ref: Entity, config: SynthConfig) -> Clause:
        radius = radius_of(target, ref, config)
        if code != NONE:
            return DirectionPos(DIRECTION_NAMES[code], ref.id, distance_range(target, ref, radius, config.c_dist))
        lateral, forward = local_ranges(target, ref, radius, bounds_of(ref, config).heading, config.c_dist)
        return LocalXYPos(lateral, forward, ref.id)

    # ------------------------------------------------------------------------------- syntax
    def parse(self, ln: Line, declared: set[str]) -> Clause:
        word = ln.peek()
        if word in ("ahead", "left", "right"):
            ln.take()
            ln.take(text="of")
        elif word == "behind":
            ln.take()
        elif word == "on":
            ln.take()
            first = ln.range_()
            ln.take(text="@")
            second = ln.range_()
            if ln.accept("relative"):
                ln.take(text="to")
                return LocalXYPos(first, second, ln.reference(declared))
            return AbsoluteXYPos(first, second)
        else:
            raise DslError(f"{ln.where()}: expected a position (ahead of, behind, left of, right of, on), found {word!r}")
        ref = ln.reference(declared)
        ln.take(text="by")
        return DirectionPos(word, ref, ln.range_())

def sampled_distance(r: Range) -> tuple[float, float]:
    """The distance interval Scenic draws for a sector's Range (kept off 0, where no bearing exists)."""
    if r.lo >= MIN_DISTANCE:
        return (r.lo, r.hi)
    if r.hi >= MIN_DISTANCE:
        return (MIN_DISTANCE, r.hi)
    return (r.hi, r.hi)  # all of it under the floor: its top only


def _scenic_distance(r: Range) -> str:
    """A sector's distance Range, kept off 0 where the bearing vanishes (see synth.scenic.emit)."""
    lo, hi = sampled_distance(r)
    if lo == r.lo:
        return str(r)
    return f"Range({'dsl__MIN_DISTANCE' if lo == MIN_DISTANCE else fmt_number(lo)}, {fmt_number(hi)})"


POSITION = PositionPart()
