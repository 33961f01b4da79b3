"""Maps as data: what a valid map is (every malformed map is one MapError line), and the two rules that complete a
source's lanes (a polygon from a centre line, neighbours by probing), checked against what they must give."""

from __future__ import annotations

import dataclasses
import math

import pytest
import shapely

from synth.road.lane_geometry import DEFAULT_LANE_WIDTH, lane_polygon, neighbours
from synth.road.roadmap import CROSSWALK, LANE, ROAD_LINE, MapError, MapFeature, RoadMap, links_within


def lane(fid, ring, line, **kw):
    return MapFeature("m", fid, LANE, polygon=ring, line=line, **kw)


RING = ((0.0, 0.0), (10.0, 0.0), (10.0, 3.0), (0.0, 3.0))
LINE = ((0.0, 1.5), (10.0, 1.5))


@pytest.mark.parametrize("feature, message", [
    (lane("a", ((0.0, 0.0), (math.nan, 0.0), (10.0, 3.0)), LINE), "polygon point that is not two finite numbers"),
    (lane("a", RING, ((0.0, math.inf), (1.0, 1.0))), "line point that is not two finite numbers"),
    (lane("a", ((0.0, 0.0), (10.0, 3.0), (10.0, 0.0), (0.0, 3.0)), LINE), "self-intersecting polygon"),
    (lane("a", ((0.0, 0.0), (10.0, 0.0), (0.0, 0.0)), LINE), "no polygon of three distinct vertices"),
    (lane("a", RING, ((0.0, 1.5),)), "no line of two points"),
    (lane("a", RING, LINE, left="ghost"), "left neighbour 'ghost', which is not a lane of the map"),
    (lane("a", RING, LINE, successors=("ghost",)), "successor 'ghost'"),
    (lane("a", RING, LINE, right="a"), "names itself"),
    (MapFeature("m", "w", CROSSWALK), "no polygon"),
    (MapFeature("m", "k", "kerb", polygon=RING), "unknown kind 'kerb'"),
])
def test_a_malformed_map_is_one_map_error_naming_the_feature(feature, message):
    with pytest.raises(MapError) as info:
        RoadMap.of("m", [feature, lane("z", RING, LINE)])
    assert message in str(info.value) and "\n" not in str(info.value)


def test_a_neighbour_naming_a_road_line_is_dangling_and_links_out_of_a_crop_can_be_dropped():
    line = MapFeature("m", "l", ROAD_LINE, line=LINE)
    with pytest.raises(MapError, match="not a lane of the map"):
        RoadMap.of("m", [lane("a", RING, LINE, left="l"), line])
    cropped = links_within([lane("a", RING, LINE, left="out", successors=("out", "b")), lane("b", RING, LINE)],
                           neighbours=True)
    road = RoadMap.of("m", cropped)
    assert road["a"].left is None and road["a"].successors == ("b",)


def test_the_polygon_of_a_centre_line_is_simple_holds_the_line_and_has_the_width_even_round_tight_turns():
    # a U-turn of radius 1 m, tighter than the default half width: offsetting vertices would fold the polygon
    turn = tuple((math.cos(math.pi * k / 12), math.sin(math.pi * k / 12)) for k in range(13))
    for line in (LINE, ((0.0, 0.0), (5.0, 0.0), (5.0, 0.0), (10.0, 5.0)), turn):
        ring = lane_polygon(line)
        poly = shapely.Polygon(ring)
        assert poly.is_valid and poly.buffer(1e-9).covers(shapely.LineString(line))
    straight = shapely.Polygon(lane_polygon(LINE))
    assert straight.area == pytest.approx(10 * DEFAULT_LANE_WIDTH)
    sided = shapely.Polygon(lane_polygon(LINE, 1.0, 2.0))  # left (+y) 1 m, right 2 m
    assert sided.bounds == pytest.approx((0.0, -0.5, 10.0, 2.5))


def test_geometric_neighbours_are_the_same_direction_lanes_beside_never_the_oncoming_one():
    def strip(fid, y0, forward=True, **kw):
        ring = ((0.0, y0), (30.0, y0), (30.0, y0 + 3.5), (0.0, y0 + 3.5))
        line = ((0.0, y0 + 1.75), (30.0, y0 + 1.75))
        return lane(fid, ring, line if forward else line[::-1], **kw)

    lanes = (strip("r", 0.0), strip("m", 3.5), strip("l", 7.0), strip("o", 10.5, forward=False),
             strip("i", 0.0, is_intersection=True))
    got = {f.feature_id: (f.left, f.right) for f in neighbours(lanes)}
    assert got == {"r": ("m", None), "m": ("l", "r"), "l": (None, "m"), "o": (None, None), "i": (None, None)}
    assert all(f.neighbour_rule == "geometric" for f in neighbours(lanes))


def test_with_features_validates_the_new_links_and_keeps_coordinates_and_packing():
    road = RoadMap.of("m", [lane("a", RING, LINE), lane("b", RING, LINE), MapFeature("m", "l", ROAD_LINE, line=LINE)])
    linked = road.with_features([road["a"].with_(left="b", neighbour_rule="geometric")])
    assert linked["a"].left == "b" and linked["b"] == road["b"] and linked.features[1:] == road.features[1:]
    assert [len(x) for x in linked.packed("line", LANE)] == [len(x) for x in road.packed("line", LANE)]
    with pytest.raises(MapError, match="not a lane of the map"):
        road.with_features([road["a"].with_(left="l")])
    with pytest.raises(MapError, match="names itself"):
        road.with_features([road["a"].with_(right="a")])
    with pytest.raises(ValueError, match="changed more than its links"):
        road.with_features([road["a"].with_(line=((0.0, 0.0), (1.0, 0.0)))])
    with pytest.raises(ValueError, match="not in map"):
        road.with_features([road["a"].with_(feature_id="ghost")])


@pytest.mark.parametrize("fields", [{}, {"polygon": RING, "line": LINE, "left": "b", "successors": ("c",)},
                                    {"is_intersection": True, "polygon_rule": "centre line", "source_type": "X"}])
def test_fast_construction_and_with_are_the_dataclass_s_own(fields):
    fast = MapFeature.fast("m", "a", LANE, **fields)
    slow = MapFeature("m", "a", LANE, **fields)
    assert fast == slow and hash(fast) == hash(slow) and repr(fast) == repr(slow)
    assert fast.with_(left="z") == dataclasses.replace(slow, left="z")
    with pytest.raises(TypeError, match="no field 'colour'"):
        MapFeature.fast("m", "a", LANE, colour="red")
    with pytest.raises(TypeError, match="no field 'colour'"):
        slow.with_(colour="red")
