"""An independent reference: the optimal cost by dynamic programming over subsets, from the semantics alone.

It shares nothing with synth.search, synth.relations, synth.oracle or synth.parts: relations are recomputed with
float atan2 bearings (the paper's beta, N and W) and plain speed differences, and the optimum is
best[S] = min over e in S of best[S - e] + c(e, S - e), c summing one 0/1 per part (position, heading, and with
motion the speed: `stationary` is a witness that needs no reference, like ego). Exponential: for frames up to
~14 entities.
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


FREE = -2  # a witness that needs no reference (stationary): always available, like ego (-1)


def motion_witnesses(scene: Scene, config: SynthConfig) -> list[set[int]]:
    """motion[e]: FREE if e is stationary, and every reference (-1 = ego) whose speed is within DV of e's."""
    refs = [(-1, scene.ego)] + list(enumerate(scene.others))
    out: list[set[int]] = [set() for _ in scene.others]
    for i, e in enumerate(scene.others):
        if e.speed <= config.v_stop:
            out[i].add(FREE)
        out[i] |= {j for j, r in refs if j != i and abs(e.speed - r.speed) <= config.dv}
    return out


def part_witnesses(scene: Scene, config: SynthConfig) -> list[list[set[int]]]:
    """Witness sets of every part the config asks for, per entity."""
    pos, head = witnesses(scene, config)
    return [pos, head] + ([motion_witnesses(scene, config)] if config.motion else [])


def optimal_cost(scene: Scene, config: SynthConfig | None = None) -> int:
    config = config or SynthConfig()
    parts = part_witnesses(scene, config)
    n = len(scene.others)

    def c(e: int, declared: int) -> int:
        avail = {FREE, -1} | {r for r in range(n) if declared >> r & 1}
        return sum(not (w[e] & avail) for w in parts)

    best = [0] * (1 << n)
    for s in range(1, 1 << n):
        best[s] = min(best[s & ~(1 << e)] + c(e, s & ~(1 << e)) for e in range(n) if s >> e & 1)
    return best[-1]


def floor_sum(scene: Scene, config: SynthConfig | None = None) -> int:
    """Sum over entities of their cheapest possible declaration (every other entity available)."""
    config = config or SynthConfig()
    return sum(sum(not w[e] for w in part_witnesses(scene, config)) for e in range(len(scene.others)))


def random_speed(rng) -> float:
    """Parked, at a walking pace or in traffic; on a 0.25 m/s grid half the time, so that speeds sit exactly on
    V_STOP and DV apart (the edges, where a float decision could go either way)."""
    v = rng.choice([0.0, rng.uniform(0.0, 0.6), rng.uniform(0.5, 2.0), rng.uniform(5.0, 15.0)])
    return round(v * 4) / 4 if rng.random() < 0.5 else v


def random_scene_dict(rng, n: int, speeds: bool = False) -> dict:
    """A street-like random scene: entities in lanes, headings near the lane axes or anywhere (and speeds)."""
    ents = [{"id": "ego", "type": "Car", "x": 0.0, "y": 0.0, "heading": 0.0}]
    for i in range(1, n + 1):
        lane = rng.choice([-7.0, -3.5, 0.0, 3.5, 7.0])
        heading = rng.choice([0.0, 180.0, 90.0, 270.0]) + rng.uniform(-8, 8) if rng.random() < 0.8 else rng.uniform(0, 360)
        ents.append({"id": f"car{i}", "type": rng.choice(["Car", "Truck", "Pedestrian"]),
                     "x": lane + rng.uniform(-1, 1), "y": rng.uniform(-40, 40), "heading": heading % 360,
                     "length": 4.5, "width": 1.9})
    if speeds:
        for e in ents:
            e["speed"] = random_speed(rng)
    return {"frame_id": f"random/{n}", "entities": ents}


__all__ = ["floor_sum", "math", "motion_witnesses", "optimal_cost", "part_witnesses", "random_scene_dict",
           "random_speed", "witnesses"]
