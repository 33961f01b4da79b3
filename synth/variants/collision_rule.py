"""The collision rule of variants: two boxes may overlap in a variant only if they overlap in the recording.

Scenic's own rule (no object intersects any other) contradicts real recordings: pedestrians walk in groups,
barriers and cones stand in touching rows, and 14 of 20 real frames tried had such pairs, so no variant could
ever satisfy it. The rule here keeps every recorded contact and forbids every new one.

Which pairs must be stated? A pair whose boxes can never meet, whatever the program's Ranges draw, needs no
requirement. The bound is sound and cheap: each entity's centre lies in a disc and its heading in an arc that
contain everything the program can place there (synth.variants.parameters, Draws.reach, derived in declaration order
from ego outwards), and two boxes can only meet if their discs come within the sum of their half-diagonals.
The remaining pairs are `apart`: the emitted Scenic text requires `not (a intersects b)` for each of them
(synth.scenic.emit) and the sampler (synth.variants.gibbs) tests exactly them, so both samplers draw from one
distribution: the program's, conditioned on the rule. Everything is derived from the program, the recorded
scene and the tolerances, which is what the Scenic text's `# r2s-source` record holds, so the rule is
re-derived from the record byte for byte.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from synth.config import SynthConfig
from synth.dsl import Program
from synth.scene import Entity, Scene
from synth.variants.overlap import box_radius, overlapping_pairs
from synth.variants.parameters import REACH_SLACK, Parameterisation, parameterise


@dataclass(frozen=True)
class CollisionRule:
    """Over ego and the program's entities in declaration order (index 0 is ego)."""

    ids: tuple[str, ...]
    lengths: tuple[float, ...]
    widths: tuple[float, ...]
    recorded: tuple[tuple[int, int], ...]  # (i < j) overlapping in the recording: may overlap in a variant
    apart: tuple[tuple[int, int], ...]  # (i < j) not overlapping in the recording that can meet: must stay apart

    def named(self, pairs: tuple[tuple[int, int], ...]) -> list[tuple[str, str]]:
        return [(self.ids[i], self.ids[j]) for i, j in pairs]


def entities_in_order(program: Program, scene: Scene) -> list[Entity]:
    """Ego, then the scene's entity of each statement, in declaration order."""
    by_id = scene.by_id()
    return [scene.ego, *(by_id[s.id] for s in program.statements)]


def collision_rule(program: Program, scene: Scene, config: SynthConfig,
                   params: Parameterisation | None = None) -> CollisionRule:
    """The rule for variants of `scene` drawn from `program` (which declares only entities of the scene)."""
    ents = entities_in_order(program, scene)
    params = params or parameterise(program, scene, config)
    dims = [e.dimensions() for e in ents]
    recorded = set(overlapping_pairs(ents))
    reach = params.reaches()
    cx, cy = np.array([r.x for r in reach]), np.array([r.y for r in reach])
    bound = np.array([r.r for r in reach]) + box_radius(np.array([d[0] for d in dims]), np.array([d[1] for d in dims]))
    i, j = np.triu_indices(len(ents), 1)
    near = np.hypot(cx[i] - cx[j], cy[i] - cy[j]) <= bound[i] + bound[j] + REACH_SLACK
    apart = [(a, b) for a, b in zip(i[near].tolist(), j[near].tolist()) if (a, b) not in recorded]
    return CollisionRule(tuple(e.id for e in ents), tuple(d[0] for d in dims), tuple(d[1] for d in dims),
                         tuple(sorted(recorded)), tuple(apart))
