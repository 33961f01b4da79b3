"""pipeline.export.behaviour_motion, as values: random behaviour programs (hypothesis) move an entity so that every
segment's pace holds on the steps inside it, read by the checker's own semantics (synth.behaviour.kinds: the
same `holds` `r2s check` reads); a car changing lanes left on a two-lane road ends in the left lane by its lane
fact, and one following its lane stays in it."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pipeline.export.behaviour_motion import Behaviours, by_behaviours
from synth.behaviour.kinds import Cruising, SlowingToAStop, Stopped
from synth.behaviour.program import parse_clip_program
from synth.behaviour.track import Sample
from synth.config import SynthConfig
from synth.road.lane_facts import RoadIndex
from synth.road.roadmap import LANE, MapFeature, RoadMap
from synth.scene import scene_from_dict
from synth.world import WorldPose

CONFIG = SynthConfig()
WIDTH = 3.5


def _lane(fid: str, x: float, left: str | None = None, right: str | None = None) -> MapFeature:
    """A straight lane up x = `x` from y = -20 to 200."""
    line = ((x, -20.0), (x, 200.0))
    poly = ((x - WIDTH / 2, -20.0), (x + WIDTH / 2, -20.0), (x + WIDTH / 2, 200.0), (x - WIDTH / 2, 200.0))
    return MapFeature("two", fid, LANE, poly, line, left=left, right=right)


ROAD = RoadMap.of("two", [_lane("r", 0.0, left="l"), _lane("l", -WIDTH, right="r")])


def _scene(speed: float) -> object:
    return scene_from_dict({"frame_id": "two/0", "entities": [
        {"id": "ego", "type": "Car", "x": 0.0, "y": 0.0, "heading": 0.0, "speed": speed, "lanes": ["r"],
         "lane": "r", "in_intersection": False, "on_crosswalk": False, "off_road": False}],
        "road": {"map_id": "two", "features": [
            {"id": f.feature_id, "kind": "lane", "line": [list(p) for p in f.line],
             "polygon": [list(p) for p in f.polygon], "left": f.left, "right": f.right, "successors": [],
             "predecessors": [], "is_intersection": False} for f in ROAD.features]}})


def _moved(text: str, speed: float, steps: int):
    scene = _scene(speed)
    program = parse_clip_program(text)
    return by_behaviours(scene, WorldPose.identity(), Behaviours(program, text, "two/0"), steps)


RANGE = st.tuples(st.integers(0, 3000), st.integers(0, 800)).map(lambda p: (p[0] / 100, (p[0] + p[1]) / 100))
PACE = st.one_of(
    st.just("stopped"), st.just("slowing to a stop"),
    st.builds(lambda r, w: f"{w} Range({r[0]}, {r[1]}) m/s", RANGE,
              st.sampled_from(["cruising", "speeding up", "slowing down"])))


@settings(max_examples=60, deadline=None)
@given(speed=st.integers(0, 3000).map(lambda v: v / 100),
       segments=st.lists(st.tuples(PACE, st.integers(3, 20)), min_size=1, max_size=4))
def test_each_segment_s_pace_holds_on_its_steps(speed, segments):
    lines = []
    for k, (pace, tenths) in enumerate(segments):
        head = "behaviour ego" if k == 0 else "then"
        path = "" if pace == "stopped" else "following lane, "
        lines.append(f"{head} {path}{pace} for Range({tenths / 10}, {tenths / 10}) s")
    text = "\n".join(lines) + "\n"
    program = parse_clip_program(text)
    steps = sum(t for _, t in segments) + 5
    ego = _moved(text, speed, steps).trajectories[0]
    assert (ego.speed >= 0).all()
    start = 0
    for seg, (_, tenths) in zip(program.behaviours[0].segments, segments):
        a, b = start, start + tenths  # the steps at the segment's start and end (0.1 s each)
        samples = [Sample(k / 10, float(ego.speed[k]), 90.0) for k in range(len(ego.speed))]
        pace = seg.pace
        if isinstance(pace, Cruising):  # every speed inside the segment within its Range
            assert pace.within(samples, a + 1, b), (text, ego.speed[a:b + 1])
        elif isinstance(pace, (Stopped, SlowingToAStop)):
            assert pace.holds(samples, a + 1 if isinstance(pace, Stopped) else a, b, CONFIG) or \
                samples[a].speed <= CONFIG.v_stop, (text, ego.speed[a:b + 1])
        start = b
    # it moves by its speeds: each step's length the mean of the speeds at its ends times 0.1 s
    step = np.hypot(np.diff(ego.x), np.diff(ego.y))
    assert np.allclose(step, (ego.speed[1:] + ego.speed[:-1]) / 2 * 0.1, atol=1e-9)


def _lanes(t) -> list[str | None]:
    world = WorldPose.identity()
    pts = [world.local(x, y) for x, y in zip(t.x, t.y)]
    heads = [math.degrees(y) for y in t.yaw]
    return [f.lane for f in RoadIndex(ROAD).facts([p[0] for p in pts], [p[1] for p in pts], heads)]


def test_a_lane_change_left_ends_in_the_left_lane_and_following_stays():
    change = _moved("behaviour ego changing lanes left, cruising Range(9, 11) m/s for Range(2, 2) s\n"
                    "then following lane, cruising Range(9, 11) m/s for Range(3, 3) s\n", 10.0, 50)
    lanes = _lanes(change.trajectories[0])
    assert lanes[0] == "r" and set(lanes[25:]) == {"l"}
    assert change.trajectories[0].x[-1] == pytest.approx(-WIDTH, abs=1e-9)  # on the left lane's centre line (world = ego frame here)
    follow = _moved("behaviour ego following lane, cruising Range(9, 11) m/s for Range(5, 5) s\n", 10.0, 50)
    assert set(_lanes(follow.trajectories[0])) == {"r"}
    assert follow.trajectories[0].y[-1] == pytest.approx(49.0, abs=1e-9)  # 4.9 s at 10 m/s
