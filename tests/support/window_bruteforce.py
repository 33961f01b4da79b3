"""An independent reference for programs over a window: the optimal window cost from the frames' own witnesses.

It shares nothing with synth.window.program, synth.tables, synth.oracle or synth.search: each frame's witnesses are
recomputed as (reference, relation) pairs with float atan2 bearings and plain speed differences, as
tests.support.bruteforce does; a (reference, relation) witnesses e for the window iff it does in every frame where
e is present (which also says the reference is present there), and the optimum is the DP over
subsets of the window's entities, best[S] = min over e in S of best[S - e] + c(e, S - e). Exponential: up to ~14
entities in the whole window.

With lanes, the lane relations of each frame come from tests.support.lanes (walks spelled out, GEOS geometry:
every relation that holds, not the first), and an entity without a lane witness pays 1 if one lane fact (in
intersection, on crosswalk, off road, off lane) holds in every frame it is in, else 2 (its lane by id, or
anywhere): the cheapest clause without a reference that holds in all of them.
"""

from __future__ import annotations

from collections.abc import Sequence

from synth.config import SynthConfig
from synth.geometry import angular_difference, bearing
from synth.scene import Entity, Scene
from tests.support.lanes import SIDES, BruteLanes

EGO, ALWAYS = "ego", "*"  # the references every declaration may use: ego and a witness that needs none


def frame_witnesses(scene: Scene, config: SynthConfig) -> list[dict[str, set[tuple[str, str]]]]:
    """Per part, per entity id: its witnesses in this frame as (reference id, relation), read off the semantics
    (sectors of delta1 about the reference's four axes; facing within delta2 of the bearing to or from it;
    stationary, or a speed within DV of the reference's)."""
    position: dict[str, set] = {}
    heading: dict[str, set] = {}
    motion: dict[str, set] = {}
    for e in scene.others:
        position[e.id], heading[e.id], motion[e.id] = set(), set(), set()
        if config.motion and e.speed <= config.v_stop:
            motion[e.id].add((ALWAYS, "stationary"))
        for r in scene.entities:
            if r.id == e.id:
                continue
            if config.motion and abs(e.speed - r.speed) <= config.dv:
                motion[e.id].add((r.id, "like"))
            if (r.x, r.y) == (e.x, e.y):
                continue
            b = bearing(r.x, r.y, e.x, e.y)
            position[e.id] |= {(r.id, f"axis{phi}") for phi in (0, 90, 180, 270)
                               if angular_difference(b, r.heading + phi) <= config.delta1}
            if angular_difference(e.heading, bearing(e.x, e.y, r.x, r.y)) <= config.delta2:
                heading[e.id].add((r.id, "toward"))
            if angular_difference(e.heading, b) <= config.delta2:
                heading[e.id].add((r.id, "away"))
    return [position, heading] + ([motion] if config.motion else []) + ([lane_witnesses(scene)] if config.lanes else [])


def lane_witnesses(scene: Scene) -> dict[str, set[tuple[str, str]]]:
    """Per entity: every (reference id, side) whose lane relation holds in this frame (the brute force's chains)."""
    brute = BruteLanes(scene.road)
    related: dict[tuple[str, str], set[str]] = {}
    out: dict[str, set] = {}
    for e in scene.others:
        out[e.id] = set()
        for r in scene.entities:
            if r.id == e.id or e.lane is None or r.lane is None:
                continue
            for side in SIDES:
                if (r.lane, side) not in related:
                    related[r.lane, side] = brute.related(r.lane, side)
                if e.lane in related[r.lane, side]:
                    out[e.id].add((r.id, side))
    return out


def lane_facts(e: Entity) -> set[str]:
    """The cost-1 lane facts of an entity as recorded."""
    off_lane = not e.lanes and e.off_road is False
    return {name for name, held in (("intersection", e.in_intersection), ("crosswalk", e.on_crosswalk),
                                    ("off road", e.off_road), ("off lane", off_lane)) if held}


def lane_weights(scenes: Sequence[Scene]) -> dict[str, int]:
    """Per entity: its lane fallback over the window, 1 if a fact holds in every frame it is in, else 2."""
    facts: dict[str, set[str]] = {}
    for scene in scenes:
        for e in scene.others:
            facts[e.id] = facts[e.id] & lane_facts(e) if e.id in facts else lane_facts(e)
    return {i: 1 if f else 2 for i, f in facts.items()}


def window_witnesses(scenes: Sequence[Scene], config: SynthConfig) -> list[dict[str, set[tuple[str, str]]]]:
    """Per part, per entity: the (reference, relation) witnesses of every frame where it is present."""
    out: list[dict[str, set]] = []
    for scene in scenes:
        for k, part in enumerate(frame_witnesses(scene, config)):
            if k == len(out):
                out.append({})
            for e, ws in part.items():
                out[k][e] = out[k][e] & ws if e in out[k] else set(ws)
    return out


def optimal_window_cost(scenes: Sequence[Scene], config: SynthConfig | None = None) -> int:
    config = config or SynthConfig()
    parts = window_witnesses(scenes, config)
    ids = sorted({e.id for s in scenes for e in s.others})
    n = len(ids)

    weights = [{i: 1 for i in ids} for _ in parts]
    if config.lanes:
        weights[-1] = lane_weights(scenes)

    def c(e: int, declared: int) -> int:
        avail = {EGO, ALWAYS} | {ids[r] for r in range(n) if declared >> r & 1}
        return sum(0 if any(r in avail for r, _ in part[ids[e]]) else w[ids[e]] for part, w in zip(parts, weights))

    best = [0] * (1 << n)
    for s in range(1, 1 << n):
        best[s] = min(best[s & ~(1 << e)] + c(e, s & ~(1 << e)) for e in range(n) if s >> e & 1)
    return best[-1]


__all__ = ["frame_witnesses", "lane_weights", "lane_witnesses", "optimal_window_cost", "window_witnesses"]
