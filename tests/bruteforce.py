"""An independent reference: the optimal cost by dynamic programming over subsets, from the semantics alone.

It shares nothing with synth.search, synth.relations or synth.oracle: relations are recomputed with float
atan2 bearings (the paper's beta, N and W), and the optimum is best[S] = min over e in S of
best[S - e] + c(e, S - e). Exponential: for frames up to ~14 entities.
"""

from __future__ import annotations

import math

from synth.config import SynthConfig
from synth.geometry import angular_difference, bearing
from synth.scene import Scene


def witnesses(scene: Scene, config: SynthConfig) -> tuple[list[set[int]], list[set[int]]]:
    """pos[e], head[e]: indices of references (-1 = ego, else index into scene.others) witnessing e."""
    refs = [(-1, scene.ego)] + list(enumerate(scene.others))
    pos: list[set[int]] = [set() for _ in scene.others]
    head: list[set[int]] = [set() for _ in scene.others]
    for i, e in enumerate(scene.others):
        for j, r in refs:
            if j == i or (r.x, r.y) == (e.x, e.y):
                continue
            b = bearing(r.x, r.y, e.x, e.y)
            if any(angular_difference(b, r.heading + phi) <= config.delta1 for phi in (0, 90, 180, 270)):
                pos[i].add(j)
            toward = bearing(e.x, e.y, r.x, r.y)
            if angular_difference(e.heading, toward) <= config.delta2 or angular_difference(e.heading, b) <= config.delta2:
                head[i].add(j)
    return pos, head


def optimal_cost(scene: Scene, config: SynthConfig | None = None) -> int:
    config = config or SynthConfig()
    pos, head = witnesses(scene, config)
    n = len(scene.others)

    def c(e: int, declared: int) -> int:
        avail = {-1} | {r for r in range(n) if declared >> r & 1}
        return (not (pos[e] & avail)) + (not (head[e] & avail))

    best = [0] * (1 << n)
    for s in range(1, 1 << n):
        best[s] = min(best[s & ~(1 << e)] + c(e, s & ~(1 << e)) for e in range(n) if s >> e & 1)
    return best[-1]


def floor_sum(scene: Scene, config: SynthConfig | None = None) -> int:
    """Sum over entities of their cheapest possible declaration (every other entity available)."""
    config = config or SynthConfig()
    pos, head = witnesses(scene, config)
    return sum((not p) + (not h) for p, h in zip(pos, head))


def random_scene_dict(rng, n: int) -> dict:
    """A street-like random scene: entities in lanes, headings near the lane axes or anywhere."""
    ents = [{"id": "ego", "type": "Car", "x": 0.0, "y": 0.0, "heading": 0.0}]
    for i in range(1, n + 1):
        lane = rng.choice([-7.0, -3.5, 0.0, 3.5, 7.0])
        heading = rng.choice([0.0, 180.0, 90.0, 270.0]) + rng.uniform(-8, 8) if rng.random() < 0.8 else rng.uniform(0, 360)
        ents.append({"id": f"car{i}", "type": rng.choice(["Car", "Truck", "Pedestrian"]),
                     "x": lane + rng.uniform(-1, 1), "y": rng.uniform(-40, 40), "heading": heading % 360,
                     "length": 4.5, "width": 1.9})
    return {"frame_id": f"random/{n}", "entities": ents}


__all__ = ["witnesses", "optimal_cost", "floor_sum", "random_scene_dict", "math"]
