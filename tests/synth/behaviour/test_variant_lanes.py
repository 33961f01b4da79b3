"""The lane rules Scenic requires of a simulated variant (synth.behaviour.variant_lanes.LaneWatch, docs/scenic.md
"Simulated variants") against the checker's own reading of the same frames: for random lane sequences on a small
lane graph and random segments, the watch passes every frame of a simulation exactly when every segment's lane
conditions hold as synth.behaviour.kinds reads them (following lane, changing lanes: `holds`; turning: some
sample in an intersection), whatever frames the entity is in."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from synth.behaviour.kinds import ChangingLanes, FollowingLane, Heading, Turning
from synth.behaviour.track import Sample, Steps
from synth.behaviour.variant_lanes import LaneWatch, lane_rule
from synth.road.lane_facts import LaneFacts
from synth.syntax import Range

# a, b one chain; c left of a's chain; d right of it
RELATED = {("a", "same"): {"a", "b"}, ("b", "same"): {"a", "b"}, ("c", "same"): {"c"}, ("d", "same"): {"d"},
           ("a", "left"): {"c"}, ("b", "left"): {"c"}, ("a", "right"): {"d"}, ("b", "right"): {"d"},
           ("c", "right"): {"a", "b"}, ("d", "left"): {"a", "b"}}
PATHS = [FollowingLane(), ChangingLanes("left"), ChangingLanes("right"), Turning("left"),
         Heading(Range(0, 10)), None]


class Graph:
    def related(self, lane, side):
        return frozenset(RELATED.get((lane, side), set()))


class Index:
    """Lane facts by place: x is the frame, y the entity (its facts drawn beforehand)."""

    def __init__(self, facts):
        self.table = facts

    def facts(self, xs, ys, hs):
        return [self.table[round(y)][round(x)] for x, y in zip(xs, ys)]


@st.composite
def cases(draw):
    n_frames = draw(st.integers(2, 8))
    entities = []
    for _ in range(draw(st.integers(1, 3))):
        frames = sorted(draw(st.sets(st.integers(0, n_frames - 1), min_size=2, max_size=n_frames)))
        n = len(frames)
        m = draw(st.integers(1, n - 1))
        inner = sorted(draw(st.sets(st.integers(1, n - 2), min_size=m - 1, max_size=m - 1))) if n > 2 else []
        bounds = [0, *inner, n - 1][:m + 1] if len(inner) == m - 1 else [0, n - 1]
        paths = [draw(st.sampled_from(PATHS)) for _ in range(len(bounds) - 1)]
        lanes = [draw(st.sampled_from(["a", "b", "c", "d", None])) for _ in range(n)]
        inter = [draw(st.booleans()) for _ in range(n)]
        entities.append((frames, bounds, paths, lanes, inter))
    return n_frames, entities


def checker_reads(bounds, paths, lanes, inter) -> bool:
    samples = [Sample(float(k), 1.0, 0.0, lane, i) for k, (lane, i) in enumerate(zip(lanes, inter))]
    steps = Steps.of(samples, Graph())
    for a, b, path in zip(bounds, bounds[1:], paths):
        if isinstance(path, (FollowingLane, ChangingLanes)) and not path.holds(samples, steps, a, b):
            return False
        if isinstance(path, Turning) and not any(inter[a:b + 1]):
            return False
    return True


@settings(max_examples=400, deadline=None)
@given(cases())
def test_the_watch_passes_a_simulation_exactly_when_the_checker_reads_its_lanes_as_held(case):
    n_frames, entities = case
    table, rules = [], []
    for e, (frames, bounds, paths, lanes, inter) in enumerate(entities):
        row = [None] * n_frames
        for f, lane, i in zip(frames, lanes, inter):
            row[f] = LaneFacts((lane,) if lane else (), lane, i, False, lane is None)
        table.append(row)
        rule = lane_rule(f"car{e}", e, frames, bounds, paths)
        if rule is not None:
            rules.append(rule)
    steps = [2 * k for k in range(n_frames)]  # two simulation steps per frame
    watch = LaneWatch(Index(table), Graph(), (0.0, 0.0), steps, rules)
    for attempt in range(2):  # a second simulation starts the monitor again
        ok = True
        for step in range(steps[-1] + 1):
            k = min(step // 2, n_frames - 1)
            states = [(float(k), float(e), 0.0, 1.0) for e in range(len(entities))]
            ok = watch.holds(step, states) and ok
        assert ok == all(checker_reads(*e[1:]) for e in entities), (attempt, watch.failure)
