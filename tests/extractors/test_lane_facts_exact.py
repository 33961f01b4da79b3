"""The fast lane facts (issue 24: R-tree candidates, banded float edge tests with the error bound, point-edges left
out, a scenario's points decided at once by RoadIndex.prefetch, the tie rule's directions in one pass) give every
fact the exact one-point-at-a-time definition gives: on real recordings as `r2s extract` writes them (the shipped
nuScenes excerpt; with ../shared/data, nuScenes-mini and the Argoverse 2 test log) and on random polygons with
points exactly on their edges and vertices and a few ulps off them."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from frames.maps import maps_dir, read_maps
from synth.road.lane_facts import (
    LaneFacts,
    PolygonIndex,
    RoadIndex,
    Segments,
    contains,
    lane_difference,
    local_direction,
)
from synth.road.roadmap import CROSSWALK, DRIVABLE_AREA, INTERSECTION, LANE, MapFeature, RoadMap
from tests.support.extract import r2s
from tests.support.polygons import rational_covers

AV2_LOG = ("argoverse2", "test_data", "sensor_dataset_logs", "adcf7d18-0510-35b0-a2fa-b4cea13a6d76")


_BOXES: dict[str, object] = {}  # the road last asked about and its polygons' boxes


def reference_facts(road: RoadMap, x: float, y: float, heading: float) -> LaneFacts:
    """The definition (docs/formats.md, "Lane facts"), one polygon at a time: a polygon whose vertices' box misses
    the point is skipped, every other is tested by `contains` over all its edges; the chosen lane by each lane's
    own Segments."""
    if _BOXES.get("road") is not road:  # each polygon's box (its vertices' minima and maxima), once per map
        _BOXES["road"] = road
        _BOXES["boxes"] = {kind: [(f, min(p[0] for p in f.polygon), min(p[1] for p in f.polygon),
                                    max(p[0] for p in f.polygon), max(p[1] for p in f.polygon))
                                   for f in road.of_kind(kind)] for kind in (LANE, CROSSWALK, INTERSECTION,
                                                                             DRIVABLE_AREA)}
    boxes = _BOXES["boxes"]

    def inside(kind: str) -> list[MapFeature]:
        return [f for f, x0, y0, x1, y1 in boxes[kind] if x0 <= x <= x1 and y0 <= y <= y1 and contains(f.polygon, x, y)]

    lanes = inside(LANE)
    chosen = min(lanes, key=lambda f: (lane_difference(heading, local_direction(f, x, y)), f.feature_id)) \
        if lanes else None
    return LaneFacts(tuple(sorted(f.feature_id for f in lanes)), chosen.feature_id if chosen else None,
                     bool(inside(INTERSECTION)) or any(f.is_intersection for f in lanes), bool(inside(CROSSWALK)),
                     not lanes and not inside(DRIVABLE_AREA))


def assert_extracted_facts_are_the_definition(frames_dir) -> int:
    frames = pd.read_parquet(frames_dir)
    roads = {road.map_id: road for road in read_maps(maps_dir(frames_dir))}
    placed = frames[frames["map_x"].notna() & frames["map_id"].notna()].sort_values("map_id", kind="stable")
    n_lanes = 0
    for r in placed.itertuples():
        got = LaneFacts(tuple(r.lanes), r.lane, r.in_intersection, r.on_crosswalk, r.off_road)
        want = reference_facts(roads[r.map_id], r.map_x, r.map_y, r.map_heading)
        assert got == want, (r.frame_id, r.track_id, got, want)
        n_lanes += len(want.lanes) > 0
    return n_lanes


def test_every_fact_of_the_shipped_excerpt_is_the_one_point_at_a_time_definition(excerpt_frames):
    assert assert_extracted_facts_are_the_definition(excerpt_frames) > 50  # many entities in lanes, not a vacuum


@pytest.mark.parametrize("source,parts", [("scenarionet", ("nuscenes-mini", "scenarionet")), ("argoverse2", AV2_LOG)])
def test_every_fact_of_the_shared_recordings_is_the_definition(shared_dir, tmp_path, capsys, source, parts):
    path = shared_dir.joinpath("data", *parts)
    if not path.exists():
        pytest.skip(f"{path} not here")
    out = tmp_path / "frames"
    result = r2s(capsys, "extract", source, str(path), "--categories", "all", "--out", str(out))
    assert result.returncode == 0, result.stderr
    assert assert_extracted_facts_are_the_definition(out) > 1000


@st.composite
def rings(draw):
    """A simple polygon on a quarter-metre grid (so that points a quarter or half of the way along an edge are
    exactly on it), many vertices (several bands), some repeated (edges of length 0), anywhere up to 1e5 m."""
    n = draw(st.integers(3, 24))
    cx, cy = (draw(st.integers(-400_000, 400_000)) / 4 for _ in range(2))
    radii = [draw(st.integers(4, 200)) for _ in range(n)]
    ring = []
    for k, r in enumerate(radii):
        p = (cx + round(r * math.cos(2 * math.pi * k / n) * 4) / 4, cy + round(r * math.sin(2 * math.pi * k / n) * 4) / 4)
        if not ring or p != ring[-1]:
            ring.append(p)
            if draw(st.integers(0, 9)) == 0:
                ring.append(p)  # a repeated vertex
    if ring[-1] == ring[0]:
        ring.pop()
    return tuple(ring)


def nudged(v: float, ulps: int) -> float:
    for _ in range(abs(ulps)):
        v = math.nextafter(v, math.inf if ulps > 0 else -math.inf)
    return v


@given(st.lists(rings(), min_size=1, max_size=4), st.data())
@settings(max_examples=60, deadline=None)
def test_the_index_decides_points_on_and_beside_edges_and_vertices_exactly(polys, data):
    import shapely

    polys = [r for r in polys if len(set(r)) >= 3 and shapely.LinearRing(r).is_simple]
    if not polys:
        return
    features = tuple(MapFeature("m", f"f{i}", LANE, polygon=r, line=r[:2]) for i, r in enumerate(polys))
    points = []
    for r in polys:
        for _ in range(8):  # a vertex, and points exactly on an edge (a quarter and half of the way along)
            k = data.draw(st.integers(0, len(r) - 1))
            (ax, ay), (bx, by) = r[k], r[(k + 1) % len(r)]
            points += [(ax, ay), ((ax + bx) / 2, (ay + by) / 2), (ax + (bx - ax) / 4, ay + (by - ay) / 4)]
        for _ in range(10):  # a few ulps off an edge point, in x and y
            px, py = data.draw(st.sampled_from(points))
            points.append((nudged(px, data.draw(st.integers(-3, 3))), nudged(py, data.draw(st.integers(-3, 3)))))
        xs, ys = [p[0] for p in r], [p[1] for p in r]
        points += [(data.draw(st.floats(min(xs) - 1, max(xs) + 1)), data.draw(st.floats(min(ys) - 1, max(ys) + 1)))
                   for _ in range(10)]
    got = PolygonIndex(features).containing(np.array([p[0] for p in points]), np.array([p[1] for p in points]))
    want = [[i for i, r in enumerate(polys) if rational_covers(r, px, py)] for px, py in points]
    assert got == want


@given(st.lists(rings(), min_size=2, max_size=5), st.data())
@settings(max_examples=40, deadline=None)
def test_prefetched_facts_and_the_one_pass_tie_rule_are_the_definition(polys, data):
    """Lanes over one another (every ring a lane, its centre line through its vertices, so the tie rule has
    several to choose from), prefetched points asked for again and points never prefetched."""
    import shapely

    polys = [r for r in polys if len(set(r)) >= 3 and shapely.LinearRing(r).is_simple]
    kinds = (LANE, LANE, CROSSWALK, INTERSECTION, DRIVABLE_AREA)
    features = [MapFeature("m", f"f{i}", kinds[i % 5] if i else LANE, polygon=r,
                           line=r[: data.draw(st.integers(2, len(r)))] if kinds[i % 5] == LANE or not i else (),
                           is_intersection=data.draw(st.booleans()))
                for i, r in enumerate(polys)]
    for i, f in enumerate(list(features)):  # a second lane on top of each area, running another way
        features.append(MapFeature("m", f"g{i}", LANE, polygon=f.polygon, line=tuple(reversed(f.polygon))))
    road = RoadMap.of("m", features)
    ring = polys[0]
    points = [p for r in polys for p in r[:6]] + [((a[0] + b[0]) / 2, (a[1] + b[1]) / 2) for a, b in
                                                 zip(ring, ring[1:] + ring[:1])]
    headings = [data.draw(st.sampled_from([0.0, 90.0, 180.0, 270.0, data.draw(st.floats(0, 359.99))]))
                for _ in points]
    index = RoadIndex(road)
    half = len(points) // 2
    index.prefetch([p[0] for p in points[:half]], [p[1] for p in points[:half]], headings[:half])
    got = index.facts([p[0] for p in points], [p[1] for p in points], headings)
    assert got == [reference_facts(road, x, y, h) for (x, y), h in zip(points, headings)]


@given(st.lists(st.lists(st.tuples(st.integers(-40, 40), st.integers(-40, 40)), min_size=1, max_size=12),
                min_size=1, max_size=6), st.data())
@settings(max_examples=80, deadline=None)
def test_directions_in_one_pass_are_those_of_each_line_s_segments(lines, data):
    """Repeated points (segments of length 0), single points (no segment), equidistant segments (the first
    nearest is the one)."""
    lines = [tuple((x / 2, y / 2) for x, y in line) for line in lines]
    road = RoadMap.of("m", [MapFeature("m", f"l{i}", LANE, polygon=((0.0, 0.0), (1.0, 0.0), (0.0, 1.0)),
                                       line=line if len(line) > 1 else line * 2) for i, line in enumerate(lines)])
    index = RoadIndex(road)
    pairs = [(data.draw(st.integers(0, len(lines) - 1)), data.draw(st.integers(-50, 50)) / 4,
              data.draw(st.integers(-50, 50)) / 4) for _ in range(20)]
    got = index.directions_near([k for k, _, _ in pairs], np.array([x for _, x, _ in pairs]),
                                np.array([y for _, _, y in pairs]))
    want = []
    for k, x, y in pairs:
        seg = Segments.of(index.lanes.features[k].line)
        want.append(seg.direction_near(x, y) if seg is not None else None)
    assert got == want


@given(st.lists(st.floats(allow_nan=False, allow_infinity=False), min_size=1, max_size=50))
@settings(max_examples=200, deadline=None)
def test_headings_of_both_lookups_are_math_degrees_mod_360(yaws):
    # prefetch_facts and a frame's own lookup (_facts_args) turn yaws into headings with numpy: the floats of
    # math.degrees(h) % 360.0, the heading's definition
    import math

    from extractors.base import _facts_args, headings_of

    got = headings_of(np.array(yaws))
    want = np.array([math.degrees(y) % 360.0 for y in yaws])
    assert np.array_equal(np.array(_facts_args([(0.0, 0.0, y) for y in yaws])[2]), got, equal_nan=True)
    assert np.array_equal(got, want, equal_nan=True) and (np.signbit(got) == np.signbit(want)).all()
