"""A program's random parameters, as Scenic draws them from the emitted text, one statement part at a time.

Scenic samples a program written by synth.emit_scenic by drawing every Range in it independently and uniformly
and evaluating the statements in order (ego is fixed, as recorded). So a program denotes a distribution: the
product of its clauses' uniform boxes, pushed through the statements. Every clause of a statement (one per part
of synth.parts: position, heading, ...) has its `Draws` here, built by the DRAWS entry of its part:

- its parameters' box: what Scenic draws, in Scenic's own parameterisation (the emitted helpers): a sector
  (`ahead of R by Range(a, b)`) draws a distance in [a, b] and an angle offset in +-delta1 about R.heading + phi;
  `on Range @ Range relative to R` the two offsets in R's frame; `facing toward R` an offset in +-delta2 about
  the bearing to R; `facing Range deg relative to R` the angle added to R's heading. A distance Range that
  starts under MIN_DISTANCE is drawn from MIN_DISTANCE, as the emitted text says (see synth.emit_scenic);
- `evaluate`: the entity's fields from its parameters and its reference's (and its own earlier parts') values;
- `invert`: the parameters that give a placed entity (how a recorded scene, or a scene Scenic sampled, is read
  back as parameters: the start of the sampler in synth.gibbs, and the distribution tests), possibly outside
  the box (`clipped`, `inside`);
- `area`: the plane area (or angle) a unit box of parameters covers at p, relative to the entity's field: the
  Jacobian of the map from parameters to placement (a sector's distance, polar coordinates; 1 otherwise), which
  a move that re-expresses a placed entity in new parameters must weigh (synth.gibbs);
- `reach`: a sound bound on every value the part can take over the whole box, given its reference's bound: a
  disc for the centre, an arc for the heading. The collision rule (synth.collision_rule) uses it to keep only
  the pairs of boxes that can ever meet.

Angles are degrees here (Scenic draws radians; a uniform draw is the same distribution in either unit).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from synth.config import SynthConfig
from synth.draws import (
    HEADING,
    REACH_SLACK,
    SPEED,
    XY,
    Arc,
    Draws,
    Pose,
    Reach,
    clipped,
    disc_plus,
    inside,
    rotated,
)
from synth.dsl import (
    DIRECTIONS,
    AbsoluteHeading,
    AbsoluteXYPos,
    DirectionPos,
    FacingRelation,
    LocalXYPos,
    Program,
    RelativeHeading,
)
from synth.geometry import bearing, normalize, signed, to_local
from synth.parts.position import sampled_distance
from synth.scene import EGO_ID, Entity, Scene


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


# ------------------------------------------------------------------------------------------------ positions

@dataclass(frozen=True)
class SectorDraws(Draws):
    """`DIR of REF by Range(a, b)`: dsl__sector draws (distance, angle offset in +-delta1)."""

    ref: str
    phi: float
    lo: tuple[float, ...]
    hi: tuple[float, ...]
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

    ref: str
    lo: tuple[float, ...]
    hi: tuple[float, ...]
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

    lo: tuple[float, ...]
    hi: tuple[float, ...]
    ref = None
    writes = XY
    reads = ()

    def evaluate(self, p: Sequence[float], own: Pose, ref: Pose | None) -> None:
        own.x, own.y = p[0], p[1]

    def invert(self, own: Pose, ref: Pose | None) -> tuple[float, ...]:
        return (own.x, own.y)

    def reach(self, own: Reach, ref: Reach | None) -> Reach:
        mx, my = (self.lo[0] + self.hi[0]) / 2, (self.lo[1] + self.hi[1]) / 2
        return Reach(mx, my, math.hypot(self.hi[0] - mx, self.hi[1] - my) + REACH_SLACK, own.heading)


# ------------------------------------------------------------------------------------------------- headings

@dataclass(frozen=True)
class FacingDraws(Draws):
    """`facing toward | away from REF`: dsl__facing_* draws an offset in +-delta2 about the bearing."""

    ref: str
    toward: bool
    lo: tuple[float, ...]
    hi: tuple[float, ...]
    writes = HEADING
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
class RelativeHeadingDraws(Draws):
    """`facing Range(a, b) deg relative to REF`: the angle added to REF's heading."""

    ref: str
    lo: tuple[float, ...]
    hi: tuple[float, ...]
    writes = HEADING
    reads = (HEADING,)

    def evaluate(self, p: Sequence[float], own: Pose, ref: Pose | None) -> None:
        own.heading = normalize(ref.heading + p[0])

    def invert(self, own: Pose, ref: Pose | None) -> tuple[float, ...]:
        return (_angle_near(own.heading - ref.heading, self.lo[0], self.hi[0]),)

    def reach(self, own: Reach, ref: Reach | None) -> Reach:
        half = ref.heading.half + (self.hi[0] - self.lo[0]) / 2 + REACH_SLACK
        mid = ref.heading.mid + (self.lo[0] + self.hi[0]) / 2
        return Reach(own.x, own.y, own.r, Arc(normalize(mid), min(180.0, half)))


@dataclass(frozen=True)
class AbsoluteHeadingDraws(Draws):
    """`facing Range(a, b) deg`: the heading drawn directly."""

    lo: tuple[float, ...]
    hi: tuple[float, ...]
    ref = None
    writes = HEADING
    reads = ()

    def evaluate(self, p: Sequence[float], own: Pose, ref: Pose | None) -> None:
        own.heading = normalize(p[0])

    def invert(self, own: Pose, ref: Pose | None) -> tuple[float, ...]:
        return (_angle_near(own.heading, self.lo[0], self.hi[0]),)

    def reach(self, own: Reach, ref: Reach | None) -> Reach:
        half = (self.hi[0] - self.lo[0]) / 2 + REACH_SLACK
        return Reach(own.x, own.y, own.r, Arc(normalize((self.lo[0] + self.hi[0]) / 2), min(180.0, half)))


def _angle_near(angle: float, lo: float, hi: float) -> float:
    """The representative of `angle` (mod 360) in [lo, hi], or outside it the one nearest to it."""
    a = lo + normalize(angle - lo)
    return a if a <= hi or a - hi < (lo + 360.0) - a else a - 360.0


# ------------------------------------------------------------------------------------------------- programs

def position_draws(pos, config: SynthConfig) -> Draws:
    if isinstance(pos, DirectionPos):
        d0, d1 = sampled_distance(pos.distance)
        return SectorDraws(pos.ref, DIRECTIONS[pos.direction][1], (d0, -config.delta1), (d1, config.delta1))
    if isinstance(pos, LocalXYPos):
        return RelativeXYDraws(pos.ref, (pos.lateral.lo, pos.forward.lo), (pos.lateral.hi, pos.forward.hi))
    if isinstance(pos, AbsoluteXYPos):
        return AbsoluteXYDraws((pos.x.lo, pos.y.lo), (pos.x.hi, pos.y.hi))
    raise TypeError(f"not a DSL position: {pos!r}")


def heading_draws(head, config: SynthConfig) -> Draws:
    if isinstance(head, FacingRelation):
        return FacingDraws(head.ref, head.mode == "toward", (-config.delta2,), (config.delta2,))
    if isinstance(head, RelativeHeading):
        return RelativeHeadingDraws(head.ref, (head.angle.lo,), (head.angle.hi,))
    if isinstance(head, AbsoluteHeading):
        return AbsoluteHeadingDraws((head.angle.lo,), (head.angle.hi,))
    raise TypeError(f"not a DSL heading: {head!r}")


# A clause's Draws, by the name of its part (synth.parts): a new part is one more entry.
DRAWS: dict[str, Callable[[object, SynthConfig], Draws]] = {"position": position_draws, "heading": heading_draws,
                                                             "motion": lambda clause, config: clause.draws(config)}


@dataclass(frozen=True)
class Parameterisation:
    """A program's clauses, as draws, in declaration order. Index 0 is ego (fixed, none); statement k is index k + 1."""

    ids: tuple[str, ...]
    types: tuple[str, ...]
    ego: Entity
    draws: tuple[tuple[Draws, ...], ...]  # per index, one per clause in statement order; () for ego
    refs: tuple[tuple[int | None, ...], ...]  # per index, per part: the reference's index (None: absolute)

    def start(self, scene: Scene) -> tuple[list[Pose], list[list[tuple[float, ...]]]]:
        """The parameters of a placed scene (clipped into their boxes), and the poses they evaluate to."""
        by_id = scene.by_id()
        recorded = [Pose(by_id[i].x, by_id[i].y, by_id[i].heading, by_id[i].speed or 0.0) for i in self.ids]
        poses = [Pose(self.ego.x, self.ego.y, self.ego.heading, self.ego.speed or 0.0)] + [Pose() for _ in self.ids[1:]]
        params: list[list[tuple[float, ...]]] = [[]]
        for k in range(1, len(self.ids)):
            row = []
            for part, r in zip(self.draws[k], self.refs[k]):
                # Invert against the recorded entity and its already re-evaluated reference, then evaluate.
                p = clipped(part, part.invert(recorded[k], None if r is None else poses[r]))
                part.evaluate(p, poses[k], None if r is None else poses[r])
                row.append(p)
            params.append(row)
        return poses, params

    def evaluate_into(self, k: int, params: Sequence[Sequence[float]], poses: list[Pose]) -> None:
        """Entity k's pose from its parameters and its references' poses (written into poses[k])."""
        for part, r, p in zip(self.draws[k], self.refs[k], params):
            part.evaluate(p, poses[k], None if r is None else poses[r])

    def moved_by(self, k: int, part: int, dependants: list[int]) -> tuple[list[int], set[str]]:
        """Every entity whose value changes when clause `part` of entity k is redrawn (k first, then in order), of
        k's dependants (the entities that refer to k through any chain of references, in order), and which Pose
        fields change (a speed that changes moves no box)."""
        changed = {(k, self.draws[k][part].writes)}
        moved = [k]
        for m in [k, *dependants]:
            hit = False
            for j, (p, r) in enumerate(zip(self.draws[m], self.refs[m])):
                if m == k and j <= part:
                    continue
                if any((r, f) in changed for f in p.reads) or any((m, f) in changed for f in p.reads_own):
                    changed.add((m, p.writes))
                    hit = True
            if hit and m != k:
                moved.append(m)
        return moved, {f for _, f in changed}

    def reaches(self) -> list[Reach]:
        ego = self.ego
        out = [Reach(ego.x, ego.y, 0.0, Arc(ego.heading, 0.0))]
        for k in range(1, len(self.ids)):
            own = Reach(0.0, 0.0, math.inf, Arc(0.0, 180.0))
            for part, r in zip(self.draws[k], self.refs[k]):
                own = part.reach(own, None if r is None else out[r])
            out.append(own)
        return out


def parameterise(program: Program, scene: Scene, config: SynthConfig) -> Parameterisation:
    """The program's parts in Scenic's parameterisation; ego (and its box) from the scene."""
    ids = (EGO_ID, *(s.id for s in program.statements))
    index = {name: k for k, name in enumerate(ids)}
    draws: list[tuple[Draws, ...]] = [()]
    refs: list[tuple[int | None, ...]] = [()]
    for st in program.statements:
        # Parts without draws here (motion: a speed moves no box) do not enter the placement of boxes.
        ps = tuple(DRAWS[part.name](clause, config) for part, clause in st.clauses() if part.name in DRAWS)
        draws.append(ps)
        refs.append(tuple(None if p.ref is None else index[p.ref] for p in ps))
    return Parameterisation(ids, (scene.ego.type, *(s.type for s in program.statements)), scene.ego,
                            tuple(draws), tuple(refs))


__all__ = ["HEADING", "REACH_SLACK", "SPEED", "XY", "Arc", "Draws", "Parameterisation", "Pose", "Reach", "clipped",
           "inside", "parameterise"]
