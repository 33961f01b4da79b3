"""What a simulated variant's construction does not decide, required over time (docs/scenic.md, "Simulated
variants"): the lane facts at its simulated places. A variant moves each entity along its recorded places at other
speeds, so at a frame it stands between two recorded places of the same segment, and the lane there may be one the
recording never stood in. `LaneWatch.holds` reads each frame's states as r2s simulate writes them (`world_states`,
the lane facts of synth.road.lane_facts on the clip's road) and applies each segment's path rules as the checker
does (synth.behaviour.kinds: following lane, changing lanes, turning's intersection), so that Scenic rejects a
simulation the checker would refuse on its lanes. It keeps the lanes of the frames so far (a monitor's state) and
starts again at step 0."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from synth.behaviour.kinds import ChangingLanes, FollowingLane, Path, Turning
from synth.geometry import normalize
from synth.road.lane_facts import RoadIndex
from synth.road.lane_relations import LaneGraph

# A state as the variant scenario records it: Scenic's place, heading (radians from +y), speed.
State = tuple[float, float, float, float]


def world_states(states: Sequence[State], offset: tuple[float, float]) -> tuple[list[float], list[float], list[float]]:
    """Places (the world's: Scenic's plus the road file's origin) and headings (degrees CCW from +x) of states."""
    return ([s[0] + offset[0] for s in states], [s[1] + offset[1] for s in states],
            [normalize(math.degrees(s[2]) + 90.0) for s in states])


@dataclass(frozen=True)
class LaneRule:
    """One entity's lane rules: its id, its index among the recorded states, its sample at each frame it is in
    (frame -> sample), its segments' boundary samples and paths."""

    name: str
    entity: int
    samples: tuple[tuple[int, int], ...]
    boundaries: tuple[int, ...]
    paths: tuple[Path | None, ...]


def lane_rule(name: str, entity: int, frames: Sequence[int], boundaries: Sequence[int],
              paths: Sequence[Path | None]) -> LaneRule | None:
    """The rule of an entity in `frames` (one per sample), None when no segment's path reads lanes."""
    if not any(isinstance(p, (FollowingLane, ChangingLanes, Turning)) for p in paths):
        return None
    return LaneRule(name, entity, tuple((f, i) for i, f in enumerate(frames)), tuple(boundaries), tuple(paths))


class LaneWatch:
    """The lane rules of a variant's entities over its frames (module docstring); `failure` says the last broken
    one."""

    def __init__(self, index: RoadIndex, graph: LaneGraph | None, offset: tuple[float, float],
                 frame_steps: Sequence[int], rules: Sequence[LaneRule]) -> None:
        self.index, self.graph, self.offset = index, graph, offset
        self.frame_at = {step: k for k, step in enumerate(frame_steps)}
        self.rules = tuple(rules)
        self.sample_at = [dict(r.samples) for r in self.rules]
        self._reset()

    def _reset(self) -> None:
        self.failure = ""
        self.lane: list[str | None] = [None] * len(self.rules)  # at each rule's sample so far
        self.moved: dict[tuple[int, int], bool] = {}  # (rule, segment): a step moved to its side
        self.crossed: dict[tuple[int, int], bool] = {}  # (rule, segment): a sample in an intersection

    def holds(self, step: int, states: Sequence[State]) -> bool:
        """Do the lane rules hold at simulation step `step` (only a frame's step is read) of these states?"""
        if step == 0:
            self._reset()
        k = self.frame_at.get(step)
        if k is None:
            return True
        live = [(n, r, self.sample_at[n][k]) for n, r in enumerate(self.rules) if k in self.sample_at[n]]
        if not live:
            return True
        xs, ys, hs = world_states([states[r.entity] for _, r, _ in live], self.offset)
        ok = True
        for (n, rule, i), fact in zip(live, self.index.facts(xs, ys, hs)):
            before, self.lane[n] = self.lane[n], fact.lane
            for j, (a, b, path) in enumerate(zip(rule.boundaries, rule.boundaries[1:], rule.paths)):
                if a <= i <= b and not self._segment(n, j, path, i, a, b, before, fact):
                    self.failure = f"{rule.name}'s segment {j} ({path}) at frame {k}: lane {fact.lane}"
                    ok = False
        return ok

    def _segment(self, n: int, j: int, path: Path | None, i: int, a: int, b: int, before: str | None,
                 fact) -> bool:
        """Segment j's path rules at its sample i (the lane at sample i - 1 `before`), as synth.behaviour.kinds'
        `holds` reads them."""
        if isinstance(path, Turning):
            crossed = self.crossed[n, j] = (i > a and self.crossed.get((n, j), False)) or fact.in_intersection
            return i < b or crossed
        if not isinstance(path, (FollowingLane, ChangingLanes)):
            return True
        if fact.lane is None:
            return False
        if i == a:
            self.moved[n, j] = False
            return True
        keep = self._related(before, fact.lane, "same")
        if isinstance(path, FollowingLane):
            return keep
        side = self._related(before, fact.lane, path.side)
        self.moved[n, j] = self.moved.get((n, j), False) or (side and not keep)
        return (keep or side) and (i < b or self.moved[n, j])

    def _related(self, before: str | None, lane: str, side: str) -> bool:
        return self.graph is not None and before is not None and lane in self.graph.related(before, side)
