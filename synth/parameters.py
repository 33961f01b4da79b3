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
from synth.parts.motion import AbsoluteSpeed, MovingLike, RelativeSpeed, Stationary
from synth.parts.position import sampled_distance
from synth.scene import EGO_ID, Entity, Scene

# Bounds are widened by this much (metres, degrees) so float rounding can never put a value outside them.
REACH_SLACK = 1e-6


@dataclass
class Pose:
    """The values of one entity the parts write (mutable: a sampler's working state)."""

    x: float = 0.0
    y: float = 0.0
    heading: float = 0.0
    speed: float = 0.0  # m/s (motion); 0 for an entity without a motion clause, as Scenic's default


@dataclass(frozen=True)
class Arc:
    """Headings within `half` degrees of `mid`; half >= 180 is every heading."""

    mid: float
    half: float

    @property
    def full(self) -> bool:
        return self.half >= 180.0

    def widened(self, by: float) -> Arc:
        return Arc(self.mid, min(180.0, self.half + by))


@dataclass(frozen=True)
class Reach:
    """Where an entity can be: its centre within r of (x, y), its heading in the arc."""

    x: float
    y: float
    r: float
    heading: Arc


XY, HEADING, SPEED = "xy", "heading", "speed"  # the fields of a Pose that clauses write and read


class Draws:
    """One clause of a statement: the parameters Scenic draws for it and what they make of the entity.

    `writes` is the Pose field it sets; `reads` the fields of its reference it reads, `reads_own` those of its own
    entity (set by an earlier clause of the statement): what a sampler must re-evaluate when something moves.
    `lo` / `hi` bound the box of its parameters.
    """

    ref: str | None
    lo: tuple[float, ...]
    hi: tuple[float, ...]
    writes: str
    reads: tuple[str, ...] = ()
    reads_own: tuple[str, ...] = ()

    def evaluate(self, p: Sequence[float], own: Pose, ref: Pose | None) -> None:
        raise NotImplementedError

    def invert(self, own: Pose, ref: Pose | None) -> tuple[float, ...]:
        raise NotImplementedError

    def reach(self, own: Reach, ref: Reach | None) -> Reach:
        raise NotImplementedError

    def area(self, p: Sequence[float], ref: Pose | None) -> float:
        """Jacobian of the map from parameters to the field it writes (1: volume-preserving)."""
        return 1.0

    requires = False  # does the emitted text add a requirement beyond the box (`allowed`)?

    def allowed(self, ref: Pose | None) -> bool:
        """That requirement (Scenic rejects a draw that fails it)."""
        return True


def _clip(v: float, lo: float, hi: float) -> float:
    return lo if v < lo else hi if v > hi else v


def _offset(angle: float, lateral: float, forward: float) -> tuple[float, float]:
    """(lateral @ forward).rotatedBy(angle): Scenic's vector rotation, counter-clockwise, degrees."""
    t = math.radians(angle)
    c, s = math.cos(t), math.sin(t)
    return (lateral * c - forward * s, lateral * s + forward * c)


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
    ox, oy = _offset(mid, 0.0, rho)
    return (ox, oy, rad)


def _disc_plus(ref: Reach, dx: float, dy: float, r: float, heading: Arc) -> Reach:
    return Reach(ref.x + dx, ref.y + dy, ref.r + r + REACH_SLACK, heading)


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
        dx, dy = _offset(ref.heading + self.phi + p[1], 0.0, p[0])
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
        return _disc_plus(ref, cx, cy, r, own.heading)


@dataclass(frozen=True)
class RelativeXYDraws(Draws):
    """`on Range @ Range relative to REF`: dsl__relative_xy draws (lateral, forward) in REF's frame."""

    ref: str
    lo: tuple[float, ...]
    hi: tuple[float, ...]
    writes = XY
    reads = (XY, HEADING)

    def evaluate(self, p: Sequence[float], own: Pose, ref: Pose | None) -> None:
        dx, dy = _offset(ref.heading, p[0], p[1])
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
        dx, dy = _offset(ref.heading.mid, mx, my)
        return _disc_plus(ref, dx, dy, corner + chord, own.heading)


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


# ------------------------------------------------------------------------------------------------- motion

@dataclass(frozen=True)
class SpeedDraws(Draws):
    """A motion clause (synth.parts.motion): Scenic draws the speed uniformly in [a, b], a and b following the
    reference's speed and clamped at 0 (`Range(0, dsl__V_STOP)`, dsl__speed_like, dsl__speed_relative, an
    absolute Range). The parameter is that uniform draw t in [0, 1], speed = a + (b - a) t: a fixed box, while
    the interval moves with the reference."""

    ref: str | None
    offsets: tuple[float, float]  # added to the reference's speed (0 without one), then clamped at 0
    lo: tuple[float, ...] = (0.0,)
    hi: tuple[float, ...] = (1.0,)
    writes = SPEED

    @property
    def reads(self) -> tuple[str, ...]:
        return () if self.ref is None else (SPEED,)

    def interval(self, ref: Pose | None) -> tuple[float, float]:
        base = 0.0 if ref is None else ref.speed
        return (max(0.0, base + self.offsets[0]), max(0.0, base + self.offsets[1]))

    def evaluate(self, p: Sequence[float], own: Pose, ref: Pose | None) -> None:
        a, b = self.interval(ref)
        own.speed = a + (b - a) * p[0]

    def invert(self, own: Pose, ref: Pose | None) -> tuple[float, ...]:
        a, b = self.interval(ref)
        return ((own.speed - a) / (b - a) if b > a else 0.0,)

    def area(self, p: Sequence[float], ref: Pose | None) -> float:
        a, b = self.interval(ref)
        return b - a

    @property
    def requires(self) -> bool:
        # A relative Range wholly below 0 holds no speed unless the reference is fast enough: the emitted text
        # requires it (MotionPart.scenic_requirements), so Scenic rejects such draws.
        return self.ref is not None and self.offsets[1] < 0.0

    def allowed(self, ref: Pose | None) -> bool:
        return not self.requires or ref.speed >= -self.offsets[1]

    def reach(self, own: Reach, ref: Reach | None) -> Reach:
        return own  # a speed places nothing


def _angle_near(angle: float, lo: float, hi: float) -> float:
    """The representative of `angle` (mod 360) in [lo, hi], or outside it the one nearest to it."""
    a = lo + normalize(angle - lo)
    return a if a <= hi or a - hi < (lo + 360.0) - a else a - 360.0


def clipped(draws: Draws, values: Sequence[float]) -> tuple[float, ...]:
    return tuple(_clip(v, lo, hi) for v, lo, hi in zip(values, draws.lo, draws.hi))


def inside(draws: Draws, values: Sequence[float]) -> bool:
    return all(lo <= v <= hi for v, lo, hi in zip(values, draws.lo, draws.hi))


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


def motion_draws(motion, config: SynthConfig) -> Draws:
    if isinstance(motion, Stationary):
        return SpeedDraws(None, (0.0, config.v_stop))
    if isinstance(motion, MovingLike):
        return SpeedDraws(motion.ref, (-config.dv, config.dv))
    if isinstance(motion, RelativeSpeed):
        return SpeedDraws(motion.ref, (motion.speed.lo, motion.speed.hi))
    if isinstance(motion, AbsoluteSpeed):
        return SpeedDraws(None, (motion.speed.lo, motion.speed.hi))
    raise TypeError(f"not a DSL motion: {motion!r}")


# A clause's Draws, by the name of its part (synth.parts): a new part is one more entry.
DRAWS: dict[str, Callable[[object, SynthConfig], Draws]] = {"position": position_draws, "heading": heading_draws,
                                                             "motion": motion_draws}


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
