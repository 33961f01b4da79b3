"""A program's random parameters, as Scenic draws them from the emitted text, one statement part at a time.

Scenic samples a program written by synth.scenic.emit by drawing every Range in it independently and uniformly
and evaluating the statements in order (ego is fixed, as recorded). So a program denotes a distribution: the
product of its clauses' uniform boxes, pushed through the statements. Every clause of a statement (one per part
of synth.parts: position, heading, ...) says what Scenic draws for it (Clause.draws, a synth.draws.Draws):

- its parameters' box: what Scenic draws, in Scenic's own parameterisation (the emitted helpers): a sector
  (`ahead of R by Range(a, b)`) draws a distance in [a, b] and an angle offset in +-delta1 about R.heading + phi;
  `on Range @ Range relative to R` the two offsets in R's frame; `facing toward R` an offset in +-delta2 about
  the bearing to R; `facing Range deg relative to R` the angle added to R's heading. A distance Range that
  starts under MIN_DISTANCE is drawn from MIN_DISTANCE, as the emitted text says (see synth.scenic.emit);
- and the maps between the box and the entity's fields (evaluate, invert, area, reach: synth.draws).

Angles are degrees here (Scenic draws radians; a uniform draw is the same distribution in either unit).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

from synth.config import SynthConfig
from synth.draws import HEADING, REACH_SLACK, SPEED, XY, Arc, Draws, Pose, Reach, clipped, inside
from synth.scene import EGO_ID, Entity, Scene

if TYPE_CHECKING:
    from synth.dsl import Program


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
        ps = tuple(clause.draws(config) for _, clause in st.clauses())
        draws.append(ps)
        refs.append(tuple(None if p.ref is None else index[p.ref] for p in ps))
    return Parameterisation(ids, (scene.ego.type, *(s.type for s in program.statements)), scene.ego,
                            tuple(draws), tuple(refs))


__all__ = ["HEADING", "REACH_SLACK", "SPEED", "XY", "Arc", "Draws", "Parameterisation", "Pose", "Reach", "clipped",
           "inside", "parameterise"]
