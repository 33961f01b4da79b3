"""An independent reference for programs over a window: the optimal window cost from the frames' own witnesses.

It shares nothing with synth.window, synth.tables, synth.oracle or synth.search: each frame's witnesses are
recomputed as (reference, relation) pairs with float atan2 bearings and plain speed differences, as
tests.support.bruteforce does; a (reference, relation) witnesses e for the window iff it does in every frame where
e is present (which also says the reference is present there), and the optimum is the DP over
subsets of the window's entities, best[S] = min over e in S of best[S - e] + c(e, S - e). Exponential: up to ~14
entities in the whole window.
"""

from __future__ import annotations

from collections.abc import Sequence

from synth.config import SynthConfig
from synth.geometry import angular_difference, bearing
from synth.scene import Scene

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
    return [position, heading] + ([motion] if config.motion else [])


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

    def c(e: int, declared: int) -> int:
        avail = {EGO, ALWAYS} | {ids[r] for r in range(n) if declared >> r & 1}
        return sum(not any(r in avail for r, _ in part[ids[e]]) for part in parts)

    best = [0] * (1 << n)
    for s in range(1, 1 << n):
        best[s] = min(best[s & ~(1 << e)] + c(e, s & ~(1 << e)) for e in range(n) if s >> e & 1)
    return best[-1]


__all__ = ["frame_witnesses", "optimal_window_cost", "window_witnesses"]
