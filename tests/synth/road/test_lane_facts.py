"""Lane facts: exact point-in-polygon against independent deciders (rational arithmetic, shapely / GEOS), the
vectorised index against the one-edge-at-a-time reference, and the facts of points on a small hand-made road."""

from __future__ import annotations

import math
from fractions import Fraction
from unittest.mock import patch

import numpy as np
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from synth.road import lane_facts
from synth.road.lane_facts import Banded, PolygonIndex, RoadIndex, contains, orientation
from synth.road.roadmap import CROSSWALK, DRIVABLE_AREA, INTERSECTION, LANE, MapFeature, RoadMap
from synth.variants.scene_road import SceneRoad
from tests.support.polygons import rational_covers

coord = st.floats(-1e4, 1e4, allow_nan=False, allow_infinity=False)


def exact_sign(ax, ay, bx, by, px, py) -> int:
    F = Fraction
    v = (F(bx) - F(ax)) * (F(py) - F(ay)) - (F(by) - F(ay)) * (F(px) - F(ax))
    return (v > 0) - (v < 0)


@given(coord, coord, coord, coord, st.floats(0, 1), st.integers(-3, 3))
@settings(max_examples=400, deadline=None)
def test_orientation_is_the_sign_of_the_rational_determinant_even_next_to_the_line(ax, ay, bx, by, t, ulps):
    # a point on the segment's line, in float, then nudged by a few ulps: where the float determinant lies
    px = ax + t * (bx - ax)
    py = ay + t * (by - ay)
    for _ in range(abs(ulps)):
        py = math.nextafter(py, math.inf if ulps > 0 else -math.inf)
    assert orientation(ax, ay, bx, by, px, py) == exact_sign(ax, ay, bx, by, px, py)


def star_polygon(draw_radii: list[float], cx: float, cy: float) -> tuple[tuple[float, float], ...]:
    """A simple polygon: vertices at increasing angles around a centre, at the given radii."""
    n = len(draw_radii)
    return tuple((cx + r * math.cos(2 * math.pi * k / n), cy + r * math.sin(2 * math.pi * k / n))
                 for k, r in enumerate(draw_radii))


polygons = st.builds(star_polygon, st.lists(st.floats(0.5, 50), min_size=3, max_size=12), coord, coord)


@given(polygons, st.data())
@settings(max_examples=150, deadline=None)
def test_contains_is_the_rational_answer_and_geos_s_on_random_points_vertices_and_edge_points(ring, data):
    poly = shapely.Polygon(ring)
    xs, ys = zip(*ring)
    points = [(data.draw(st.floats(min(xs) - 5, max(xs) + 5)), data.draw(st.floats(min(ys) - 5, max(ys) + 5)))
              for _ in range(20)]
    points += list(ring)  # vertices: on the boundary, so contained
    k = data.draw(st.integers(0, len(ring) - 1))
    (ax, ay), (bx, by) = ring[k], ring[(k + 1) % len(ring)]
    points.append(((ax + bx) / 2, (ay + by) / 2))  # near (often exactly on) an edge
    for px, py in points:
        got = contains(ring, px, py)
        assert got == rational_covers(ring, px, py), (ring, px, py)
        # GEOS decides with double-double arithmetic: right but for points a hair's breadth from an edge
        if poly.exterior.distance(shapely.Point(px, py)) > 1e-9 * (1 + abs(px) + abs(py)):
            assert got == poly.covers(shapely.Point(px, py)), (ring, px, py)


@given(st.lists(polygons, min_size=1, max_size=6), st.data(), st.sampled_from([lane_facts.CHUNK_ROWS, 1, 7]))
@settings(max_examples=100, deadline=None)
def test_the_vectorised_index_gives_the_reference_answer_for_every_pair(rings, data, chunk_rows):
    # also in chunks of a few (pair, edge) rows, as the points in a polygon of many edges go
    features = tuple(MapFeature("m", f"f{i}", LANE, polygon=r, line=r[:2]) for i, r in enumerate(rings))
    xs = np.array([data.draw(coord) for _ in range(15)] + [r[0][0] for r in rings])
    ys = np.array([data.draw(coord) for _ in range(15)] + [r[0][1] for r in rings])
    # points near polygons too, where the index has work to do
    for r in rings:
        cx = sum(p[0] for p in r) / len(r)
        cy = sum(p[1] for p in r) / len(r)
        xs, ys = np.append(xs, cx), np.append(ys, cy)
    with patch.object(lane_facts, "CHUNK_ROWS", chunk_rows):
        got = PolygonIndex(features).containing(xs, ys)
    want = [[i for i, r in enumerate(rings) if contains(r, float(x), float(y))] for x, y in zip(xs, ys)]
    assert got == want


def square(x0, y0, x1, y1):
    x0, y0, x1, y1 = map(float, (x0, y0, x1, y1))
    return ((x0, y0), (x1, y0), (x1, y1), (x0, y1))


def road() -> RoadMap:
    """Two lanes side by side heading +x (y in [0, 3] and [3, 6]), one heading -x beyond (y in [6, 9]), a
    crosswalk over all three at x in [10, 12], an intersection lane at x in [20, 30], and a drivable area that
    also covers a shoulder (y in [-2, 0])."""
    f = [
        MapFeature("m", "a", LANE, polygon=square(0, 0, 20, 3), line=((0.0, 1.5), (20.0, 1.5)), left="b"),
        MapFeature("m", "b", LANE, polygon=square(0, 3, 20, 6), line=((0.0, 4.5), (20.0, 4.5)), right="a"),
        MapFeature("m", "c", LANE, polygon=square(0, 6, 20, 9), line=((20.0, 7.5), (0.0, 7.5))),
        MapFeature("m", "x", LANE, polygon=square(20, 0, 30, 9), line=((20.0, 1.5), (30.0, 1.5)),
                   is_intersection=True),
        MapFeature("m", "w", CROSSWALK, polygon=square(10, 0, 12, 9)),
        MapFeature("m", "d", DRIVABLE_AREA, polygon=square(0, -2, 30, 9)),
    ]
    return RoadMap.of("m", f)


def test_facts_of_points_on_a_hand_made_road():
    index = RoadIndex(road())
    xs = [5.0, 5.0, 11.0, 25.0, 5.0, 5.0, 50.0, 20.0]
    ys = [1.0, 3.0, 4.0, 1.0, 7.0, -1.0, 50.0, 1.0]
    hs = [0.0, 90.0, 0.0, 0.0, 180.0, 0.0, 0.0, 0.0]
    facts = index.facts(np.array(xs), np.array(ys), np.array(hs))
    got = [(f.lanes, f.lane, f.in_intersection, f.on_crosswalk, f.off_road) for f in facts]
    assert got == [
        (("a",), "a", False, False, False),
        (("a", "b"), "a", False, False, False),  # on the shared edge; both lanes run at 0 deg from +x: smaller id
        (("b",), "b", False, True, False),
        (("x",), "x", True, False, False),
        (("c",), "c", False, False, False),
        ((), None, False, False, False),  # on the shoulder: in no lane, but on the drivable area
        ((), None, False, False, True),
        (("a", "x"), "a", True, False, False),  # the boundary into the intersection
    ]


def test_the_chosen_lane_of_overlapping_lanes_is_the_one_heading_the_entity_s_way():
    f = [MapFeature("m", "east", LANE, polygon=square(0, 0, 10, 10), line=((0.0, 5.0), (10.0, 5.0))),
         MapFeature("m", "north", LANE, polygon=square(0, 0, 10, 10), line=((5.0, 0.0), (5.0, 10.0)))]
    index = RoadIndex(RoadMap.of("m", f))
    east, north = index.facts(np.array([5.0, 5.0]), np.array([5.0, 5.0]), np.array([10.0, 80.0]))
    assert east.lanes == north.lanes == ("east", "north")
    assert (east.lane, north.lane) == ("east", "north")


@given(st.lists(polygons, min_size=1, max_size=5), st.data())
@settings(max_examples=80, deadline=None)
def test_a_scene_road_gives_the_facts_of_one_pose_as_the_index_gives_them_for_many(rings, data):
    """SceneRoad.facts (one pose in plain Python, heading from +y as scenes give it: what the sampler asks per
    move) against RoadIndex.facts (vectorised, heading from +x) on random roads: overlapping lanes (the tie
    rule), crosswalks, intersections, drivable areas; random points, vertices and edge midpoints."""
    kinds = (LANE, LANE, CROSSWALK, INTERSECTION, DRIVABLE_AREA)
    features = tuple(MapFeature("m", f"f{i}", kinds[i], polygon=r, line=(r[0], r[1]) if kinds[i] == LANE else (),
                                is_intersection=i == 1 and data.draw(st.booleans()))
                     for i, r in enumerate(rings))
    road_map = RoadMap.of("m", features)
    points = [(data.draw(coord), data.draw(coord)) for _ in range(10)] + [p for r in rings for p in r[:3]]
    points += [((r[0][0] + r[1][0]) / 2, (r[0][1] + r[1][1]) / 2) for r in rings]
    headings = [data.draw(st.floats(0, 359.99)) for _ in points]
    want = RoadIndex(road_map).facts(np.array([p[0] for p in points]), np.array([p[1] for p in points]),
                                     np.array([(h + 90) % 360 for h in headings]))
    one = SceneRoad(road_map)
    assert [one.facts(x, y, h) for (x, y), h in zip(points, headings)] == want


def test_a_scene_placed_on_its_road_carries_the_facts_of_where_its_entities_now_are():
    from synth.scene import scene_from_dict

    scene = scene_from_dict({"frame_id": "f", "entities": [
        {"id": "ego", "type": "Car", "x": 5.0, "y": 1.0, "heading": 270.0},  # heading +x (from +y: 270)
        {"id": "car1", "type": "Car", "x": 11.0, "y": 4.0, "heading": 90.0},
        {"id": "car2", "type": "Car", "x": 50.0, "y": 50.0, "heading": 0.0}]})
    placed = SceneRoad(road()).placed(scene)
    assert placed.road == road() and [e.id for e in placed.entities] == ["ego", "car1", "car2"]
    got = [(e.lanes, e.lane, e.in_intersection, e.on_crosswalk, e.off_road) for e in placed.entities]
    assert got == [(("a",), "a", False, False, False), (("b",), "b", False, True, False),
                   ((), None, False, False, True)]


@given(st.builds(star_polygon, st.lists(st.floats(0.5, 50), min_size=3, max_size=90), coord, coord), st.data())
@settings(max_examples=120, deadline=None)
def test_a_banded_polygon_answers_as_contains_does(ring, data):
    """Banded (the edges of the point's band only) against contains (every edge) and the rational brute force:
    random points, every vertex, edge midpoints, and points on the band boundaries."""
    banded = Banded(ring)
    xs, ys = zip(*ring)
    points = [(data.draw(st.floats(min(xs) - 5, max(xs) + 5)), data.draw(st.floats(min(ys) - 5, max(ys) + 5)))
              for _ in range(25)]
    points += list(ring) + [((a[0] + b[0]) / 2, (a[1] + b[1]) / 2) for a, b in zip(ring, ring[1:] + ring[:1])]
    points += [(data.draw(st.floats(min(xs), max(xs))), banded.box[1] + k * banded.h) for k in range(banded.n + 1)]
    for px, py in points:
        assert banded.contains(px, py) == contains(ring, px, py) == rational_covers(ring, px, py), (ring, px, py)
