"""The replay path of a car (synth.behaviour.replay_path) against brute force: on random lane chains (hypothesis)
a following-lane path lies on the chain's centre lines, from the first sample's nearest point of its lane to the
last's, whatever lane facts flip to an overlapping unlinked lane; a lane change goes from the source lane's centre
line to the target's linearly; on the shipped Argoverse 2 clip every path of a car that only follows its lane lies
on the road's lane centre lines."""

from __future__ import annotations

import math

import numpy as np
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st
from shapely.geometry import LineString, MultiLineString, Point

from pipeline.scenes import scene as frame_scene
from synth import SynthConfig
from synth.behaviour.kinds import FollowingLane
from synth.behaviour.replay_path import Lanes, replay_path, replay_points
from synth.behaviour.synthesize import synthesize_behaviours
from synth.behaviour.track import read_clip
from tests.support import ROOT

AV2 = ROOT / "data" / "argoverse2-log-excerpt" / "frames.parquet"
LOG = "adcf7d18-0510-35b0-a2fa-b4cea13a6d76"


def _dense(line: LineString, step: float = 0.005) -> np.ndarray:
    """Points every `step` metres along a line (the brute force's stand-in for the line)."""
    return shapely.get_coordinates(shapely.line_interpolate_point(line, np.arange(0.0, line.length + step, step)))


def _nearest(line: LineString, p) -> np.ndarray:
    pts = _dense(line)
    return pts[np.argmin(np.hypot(pts[:, 0] - p[0], pts[:, 1] - p[1]))]


def _chain(turns: list[float], lengths: list[float]) -> list[LineString]:
    """Lanes end to start, each a two-piece polyline turning by `turns` degrees at its middle."""
    lanes, x, y, h = [], 0.0, 0.0, 0.0
    for turn, length in zip(turns, lengths):
        pts = [(x, y)]
        for piece in (0, 1):
            h += math.radians(turn) * piece
            x, y = x + length / 2 * math.cos(h), y + length / 2 * math.sin(h)
            pts.append((x, y))
        lanes.append(LineString(pts))
    return lanes


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(-25, 25), min_size=1, max_size=4), st.lists(st.floats(8, 30), min_size=4, max_size=4),
       st.lists(st.tuples(st.floats(0.02, 0.98), st.floats(-1.0, 1.0), st.booleans()), min_size=2, max_size=30))
def test_following_lane_lies_on_the_recorded_lanes_centre_lines(turns, lengths, samples):
    chain = _chain(turns, lengths[:len(turns)])
    whole = LineString([c for line in chain for c in line.coords])
    lines = {f"L{k}": line for k, line in enumerate(chain)}
    lines["X"] = LineString([(0, 5), (60, 5)])  # an overlapping lane no link reaches: lane facts flip to it
    successors = {f"L{k}": [f"L{k + 1}"] for k in range(len(chain) - 1)}
    lanes = Lanes(lines.get, lambda lane: successors.get(lane, []))
    places, facts = [], []
    for k, (share, lateral, flip) in enumerate(sorted(samples)):
        s = share * whole.length
        p, q = whole.interpolate(s), whole.interpolate(min(s + 0.01, whole.length))
        d = np.array([q.x - p.x, q.y - p.y])
        n = np.array([-d[1], d[0]]) / (np.linalg.norm(d) or 1)
        places.append((p.x + lateral * n[0], p.y + lateral * n[1]))
        on = next(i for i, line in enumerate(chain) if line.distance(p) < 1e-6)
        facts.append("X" if flip and 0 < k < len(samples) - 1 else f"L{on}")
    path = replay_points(places, facts, lanes, ["lane"], [False] * (len(places) - 1), [0, len(places) - 1])
    centre = MultiLineString(chain)
    assert all(centre.distance(Point(p)) < 1e-6 for p in path.points)
    start, end = _nearest(lines[facts[0]], places[0]), _nearest(lines[facts[-1]], places[-1])
    assert math.dist(path.points[0], start) < 0.01 and math.dist(path.points[-1], end) < 0.01 or len(path.points) == 1
    along = _dense(whole)
    s_of = [float(np.argmin(np.hypot(along[:, 0] - p[0], along[:, 1] - p[1]))) * 0.005 for p in (start, end)]
    assert abs(path.lengths[0] - max(0.0, s_of[1] - s_of[0])) < 0.05


@settings(max_examples=30, deadline=None)
@given(st.floats(10, 60), st.integers(1, 18), st.sampled_from([3.0, 3.5, -3.5]))
def test_a_lane_change_blends_linearly_from_source_to_target(length, flip, width):
    source, target = LineString([(0, 0), (80, 0)]), LineString([(0, width), (80, width)])
    lanes = Lanes({"A": source, "B": target}.get, lambda lane: [])
    places = [(5 + length * k / 19, width * (k >= flip) * 0.9) for k in range(20)]
    facts = ["B" if k >= flip else "A" for k in range(20)]
    moved = [k == flip - 1 for k in range(19)]
    path = replay_points(places, facts, lanes, ["change"], moved, [0, 19])
    assert source.distance(Point(path.points[0])) < 1e-9 and target.distance(Point(path.points[-1])) < 1e-9
    for x, y in path.points:  # the blend's share is its share of the way along: y = width * (x - x0) / length
        assert abs(y - width * (x - places[0][0]) / length) < 1e-6
    assert abs(path.lengths[0] - math.hypot(length, width)) < 1e-6


def test_recorded_segments_and_laneless_samples_keep_the_recorded_places():
    places = [(0.0, 0.0), (1.0, 0.5), (2.0, 0.0), (3.0, 1.0)]
    lanes = Lanes({"A": LineString([(0, 0), (9, 0)])}.get, lambda lane: [])
    path = replay_points(places, ["A", None, None, "Q"], lanes, ["recorded", "lane"], [False] * 3, [0, 1, 3])
    assert path.points[:2] == tuple(places[:2]) and path.points[-2:] == tuple(places[2:])  # no lane at 1 .. 3 (Q: none of the road)
    assert abs(sum(path.lengths) - sum(math.dist(a, b) for a, b in zip(places, places[1:]))) < 1e-9


def test_following_lane_cars_of_the_av2_clip_drive_the_roads_centre_lines():
    ids = [f"{LOG}/{k}" for k in range(100, 130)]
    clip = read_clip([frame_scene(str(AV2), f) for f in ids])
    result = synthesize_behaviours(clip, SynthConfig(motion=True, lanes=True))
    world = clip.scenes[0].world
    centre = MultiLineString([[world.point(*p) for p in f.line] for f in clip.graph.road.lanes if len(f.line) > 1])
    checked = 0
    for segmented, track in zip(result.segmented, clip.tracks):
        segments = segmented.behaviour.segments
        if segments and all(isinstance(s.path, FollowingLane) for s in segments) and track.type != "Pedestrian":
            path = replay_path(segmented, track, clip)
            assert all(centre.distance(Point(p)) < 1e-6 for p in path.points), track.id
            checked += 1
    assert checked >= 3
