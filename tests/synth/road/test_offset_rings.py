"""The numpy widening (lane_geometry.offset_rings) against GEOS's buffer, the rule it stands in for
(docs/formats.md, "A lane without a polygon"): on random lanes, every ring it accepts bounds the buffer's set
within the merged bevels' bound; every lane it refuses (its ring not simple, an offset running backwards) is
widened by GEOS exactly as before."""

from __future__ import annotations

import math

import numpy as np
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from synth.road.lane_geometry import dedup_packed, lane_polygons, offset_rings
from tests.support.widening import bound, geos_ring

# lanes as the sources draw them: a walk of steps 0.2..5 m turning a little each step (curves, bends, hairpins
# when the turns add up), and widths of real lanes, sides alike or not
turns = st.lists(st.floats(-1.2, 1.2), min_size=1, max_size=40)
steps = st.floats(0.2, 5.0)
half = st.sampled_from([0.1, 0.5, 1.0, 1.7, 2.5, 5.0])


def walk(start_heading, turn_list, step):
    x = y = 0.0
    h = start_heading
    pts = [(x, y)]
    for t in turn_list:
        h += t
        x, y = x + step * math.cos(h), y + step * math.sin(h)
        pts.append((x, y))
    return tuple(pts)


@given(st.lists(st.tuples(st.floats(-math.pi, math.pi), turns, steps, half, half), min_size=1, max_size=6))
@settings(max_examples=200, deadline=None)
def test_an_accepted_offset_ring_is_the_buffer_and_the_rest_are_geos_s(lanes):
    lines = [walk(h, t, s) for h, t, s, _, _ in lanes]
    lefts, rights = [a for *_, a, _ in lanes], [b for *_, b in lanes]
    xy, kept = dedup_packed(lines)
    fast, _, _ = offset_rings(xy, kept, np.array(lefts), np.array(rights), kept >= 2)
    rings = lane_polygons(lines, lefts, rights)
    for i, (line, left, right, ring) in enumerate(zip(lines, lefts, rights, rings)):
        want = geos_ring(line, left, right)
        got = shapely.Polygon(ring)
        assert got.is_valid
        if i in fast:
            assert shapely.hausdorff_distance(got, want, densify=0.1) <= bound(left, right)
            assert abs(got.area - want.area) <= bound(left, right) * want.length
            assert not shapely.is_ccw(got.exterior)  # clockwise, as GEOS's
        else:  # the fallback: GEOS's ring itself
            assert got.equals_exact(want, 0.0) or got.equals(want)


def test_a_hairpin_tighter_than_its_width_is_left_to_geos():
    # a U-turn of radius 1 m widened by 2 m a side: the inner offset crosses itself; the offset ring is refused
    # and the lane gets GEOS's polygon
    line = tuple((math.cos(a), math.sin(a)) for a in np.linspace(0, math.pi, 12))
    xy, kept = dedup_packed([line])
    fast, _, _ = offset_rings(xy, kept, np.array([2.0]), np.array([2.0]), np.array([True]))
    assert len(fast) == 0
    (ring,) = lane_polygons([line], [2.0], [2.0])
    assert shapely.Polygon(ring).equals(geos_ring(line, 2.0, 2.0))


def test_a_gentle_curve_is_accepted_and_close_to_geos():
    line = tuple((10 * math.cos(a), 10 * math.sin(a)) for a in np.linspace(0, 1.0, 30))
    xy, kept = dedup_packed([line])
    fast, ring, counts = offset_rings(xy, kept, np.array([1.7]), np.array([1.2]), np.array([True]))
    assert list(fast) == [0] and counts.tolist() == [len(ring)]
    got = shapely.Polygon(ring)
    assert shapely.hausdorff_distance(got, geos_ring(line, 1.7, 1.2), densify=0.1) <= bound(1.7, 1.2)
