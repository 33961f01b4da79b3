"""What Scenic draws for one clause, as the sampler sees it: the Draws protocol and the values it works on.

Every clause kind (synth.parts) says what Scenic draws for it (Clause.draws): a box of parameters in Scenic's
own parameterisation of the emitted text, and the maps between those parameters and the entity's fields.
synth.variants.parameters assembles a program's draws; synth.variants.gibbs and synth.variants.collision_rule read them. Angles are degrees
here (Scenic draws radians; a uniform draw is the same distribution in either unit).

- `evaluate`: the entity's fields from its parameters and its reference's (and its own earlier clauses') values;
- `invert`: the parameters that give a placed entity (how a recorded scene, or a scene Scenic sampled, is read
  back as parameters), possibly outside the box (`clipped`, `inside`);
- `area`: the plane area (or angle) a unit box of parameters covers at p, relative to the entity's field: the
  Jacobian of the map from parameters to placement, which a move that re-expresses a placed entity in new
  parameters must weigh (synth.variants.gibbs);
- `reach`: a sound bound on every value the clause can take over the whole box, given its reference's bound: a
  disc for the centre, an arc for the heading (synth.variants.collision_rule keeps only the pairs of boxes that can meet);
- `allowed`: a requirement beyond the box (`requires`), which the emitted text states as a `require` line: Scenic
  rejects a scene that fails it, the chain a move. It sees the entity's pose, its reference's, and the scene's
  road (synth.variants.scene_road.SceneRoad: the lane facts of a pose), so a clause can keep its entity in a region.

A `Requirement` is a clause that draws nothing and only constrains (a lane clause: its entity's centre in a
region of the recorded road): an empty box, and reads of both poses so that every move of either asks it again.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

if TYPE_CHECKING:
    from synth.variants.scene_road import SceneRoad

# Bounds are widened by this much (metres, degrees) so float rounding can never put a value outside them.
REACH_SLACK = 1e-6

XY, HEADING, SPEED = "xy", "heading", "speed"  # the fields of a Pose that the built-in clauses write and read
PLACE = "place"  # what a Requirement writes: no field, and nothing reads it (re-evaluating it moves nothing)


@dataclass
class Pose:
    """The values of one entity the clauses write (mutable: a sampler's working state). A part whose clauses
    write a field of their own sets it as an attribute (Draws.writes names it)."""

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


@dataclass(frozen=True)
class Draws:
    """One clause of a statement: the parameters Scenic draws for it and what they make of the entity.

    `ref` is the clause's reference (None: none); `lo` / `hi` bound the box of its parameters (a subclass adds
    the fields of its own after them). `writes` is the Pose field it sets; `reads` the fields of its reference it
    reads, `reads_own` those of its own entity (set by an earlier clause of the statement): what a sampler must
    re-evaluate when something moves.
    """

    ref: str | None
    lo: tuple[float, ...]
    hi: tuple[float, ...]
    writes: ClassVar[str]
    reads: ClassVar[tuple[str, ...]] = ()
    reads_own: ClassVar[tuple[str, ...]] = ()

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

    def allowed(self, own: Pose, ref: Pose | None, road: SceneRoad | None) -> bool:
        """That requirement at the entity's pose and its reference's, on the scene's road (None: the scene has
        none). Scenic rejects a draw that fails it."""
        return True


@dataclass(frozen=True)
class Requirement(Draws):
    """A clause that draws nothing and only constrains its entity's pose (and its reference's): `allowed`, over
    an empty box. It reads both poses' centres and headings, so a move of the entity or of its reference asks it
    again (Parameterisation.moved_by, the chain's readers); it writes nothing that any clause reads."""

    writes = PLACE
    reads = (XY, HEADING)
    reads_own = (XY, HEADING)
    requires = True

    def evaluate(self, p: Sequence[float], own: Pose, ref: Pose | None) -> None:
        return None

    def invert(self, own: Pose, ref: Pose | None) -> tuple[float, ...]:
        return ()

    def reach(self, own: Reach, ref: Reach | None) -> Reach:
        return own  # it places nothing: the entity is where its other clauses put it


def _clip(v: float, lo: float, hi: float) -> float:
    return lo if v < lo else hi if v > hi else v


def clipped(draws: Draws, values: Sequence[float]) -> tuple[float, ...]:
    return tuple(_clip(v, lo, hi) for v, lo, hi in zip(values, draws.lo, draws.hi))


def inside(draws: Draws, values: Sequence[float]) -> bool:
    return all(lo <= v <= hi for v, lo, hi in zip(values, draws.lo, draws.hi))


def rotated(angle: float, lateral: float, forward: float) -> tuple[float, float]:
    """(lateral @ forward).rotatedBy(angle): Scenic's vector rotation, counter-clockwise, degrees."""
    t = math.radians(angle)
    c, s = math.cos(t), math.sin(t)
    return (lateral * c - forward * s, lateral * s + forward * c)


def disc_plus(ref: Reach, dx: float, dy: float, r: float, heading: Arc) -> Reach:
    """A reach about ref's centre moved by (dx, dy), r wider (and the slack)."""
    return Reach(ref.x + dx, ref.y + dy, ref.r + r + REACH_SLACK, heading)
