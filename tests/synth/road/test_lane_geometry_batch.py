"""The batched forms of the lane-geometry steps against their definitions: the point halfway along many lines
(`halfways`, against the definition in exact arithmetic, and equal to one line at a time), the nearest segment of many (line, point) pairs
(`PackedSegments.nearest` against `Segments.nearest`), and facts decided for many points at once against facts
decided one point at a time, on random lines and points (hypothesis)."""

from __future__ import annotations

import contextlib
import math
from unittest.mock import patch

import numpy as np
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from synth.road import lane_facts
from synth.road.lane_facts import PackedSegments, RoadIndex, Segments, row_chunks
from synth.road.lane_geometry import (
    BEVEL_MERGE,
    MAX_TURNING,
    SHORT_TURNING,
    SHORT_WORK,
    WORK_BASE,
    WORK_PER_POINT,
    dedup,
    dedup_packed,
    halfway,
    halfways,
    lane_polygon,
    lane_polygons,
    widening_work,
)
from synth.road.roadmap import LANE, MapFeature, RoadMap

coord = st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False)
# lines with repeated points (dedup drops them) and lines too short to have a halfway point
lines = st.lists(st.lists(st.tuples(coord, coord), min_size=0, max_size=12).map(
    lambda pts: tuple(p for i, p in enumerate(pts) for _ in range(1 + (i % 3 == 1)))), min_size=1, max_size=8)


@given(lines)
@settings(max_examples=300, deadline=None)
def test_halfways_is_the_point_halfway_along_each_line_by_length(raw):
    xy, kept = dedup_packed(list(raw))
    got = halfways(xy, kept)
    assert got == [halfway(line) for line in raw]  # one line at a time: the same
    for line, mid in zip(raw, got):
        pts = dedup(line)
        if len(pts) < 2:
            assert mid is None
            continue
        x, y, ux, uy = mid
        lengths = [math.hypot(bx - ax, by - ay) for (ax, ay), (bx, by) in zip(pts, pts[1:])]
        total, tol = sum(lengths), 1e-9 * (1 + sum(lengths))
        # some segment holds the point (exactly, to rounding) at half the line's length from its start, and the
        # direction is that segment's
        found = False
        for k, ((ax, ay), (bx, by)) in enumerate(zip(pts, pts[1:])):
            gap2, t = _on_segment(ax, ay, bx, by, x, y)
            along = sum(lengths[:k]) + float(t) * lengths[k]
            found = found or (float(gap2) <= tol ** 2 and abs(along - total / 2) <= tol and math.isclose(
                ux, (bx - ax) / lengths[k], abs_tol=1e-12) and math.isclose(uy, (by - ay) / lengths[k], abs_tol=1e-12))
        assert found, (pts, mid)


def _on_segment(ax, ay, bx, by, x, y):
    """(squared distance, parameter) of the point of segment a-b nearest (x, y), in exact arithmetic."""
    from fractions import Fraction

    dx, dy = Fraction(bx) - Fraction(ax), Fraction(by) - Fraction(ay)
    px, py = Fraction(x) - Fraction(ax), Fraction(y) - Fraction(ay)
    t = min(max((px * dx + py * dy) / (dx * dx + dy * dy), Fraction(0)), Fraction(1))
    return (px - t * dx) ** 2 + (py - t * dy) ** 2, t


# how nearest goes: as a real map (one pass); in chunks of a few (pair, segment) rows; every line pruned by blocks
# of one or two segments, as a line of more than LONG_LINE segments is (with chunks of a few rows besides)
MODES = [{}, {"CHUNK_ROWS": 5}, {"LONG_LINE": 0, "BLOCK_MIN": 1}, {"LONG_LINE": 1, "BLOCK_MIN": 2, "CHUNK_ROWS": 3}]


def _nearest_in_mode(packed, mode, lines, xs, ys):
    with contextlib.ExitStack() as stack:
        for name, value in mode.items():
            stack.enter_context(patch.object(lane_facts, name, value))
        return packed.nearest(np.asarray(lines), np.asarray(xs, dtype=float), np.asarray(ys, dtype=float))


def _assert_nearest_is_segments_nearest(raw, asks, mode):
    packed = PackedSegments.of(list(raw))
    row, gap = _nearest_in_mode(packed, mode, [k for k, _, _ in asks], [x for _, x, _ in asks],
                                [y for _, _, y in asks])
    for (k, x, y), r, g in zip(asks, row.tolist(), gap.tolist()):
        seg = Segments.of(raw[k])
        if seg is None:
            assert r == -1
            continue
        j, want_gap = seg.nearest(x, y)
        assert g == want_gap
        assert r - packed.start[k] == j  # the first nearest segment, as np.argmin chooses


@given(lines, st.lists(st.tuples(st.integers(0, 7), coord, coord), min_size=1, max_size=20),
       st.sampled_from(MODES))
@settings(max_examples=300, deadline=None)
def test_packed_nearest_is_segments_nearest_of_each_pair(raw, asks, mode):
    _assert_nearest_is_segments_nearest(raw, [(k % len(raw), x, y) for k, x, y in asks], mode)


@given(st.lists(st.tuples(coord, coord, st.floats(0, 360, exclude_max=True)), min_size=1, max_size=40))
@settings(max_examples=150, deadline=None)
def test_facts_of_many_points_are_the_facts_of_each(points):
    # overlapping lanes along x and y through the origin, so points fall in none, one or several
    lanes = [MapFeature("m", f"l{i}", LANE, polygon=lane_polygon(line, 200.0, 200.0), line=line)
             for i, line in enumerate([((-900.0, 0.0), (900.0, 0.0)), ((0.0, -900.0), (0.0, 900.0)),
                                       ((900.0, 10.0), (-900.0, 10.0))])]
    road = RoadIndex(RoadMap.of("m", lanes))
    xs, ys, hs = (np.array([p[k] for p in points]) for k in range(3))
    many = road._decide(xs, ys, hs)
    for i in range(len(points)):
        assert many[i] == road._decide(xs[i:i + 1], ys[i:i + 1], hs[i:i + 1])[0]


@given(st.lists(st.tuples(coord, coord, st.floats(0, 300), st.floats(0, 300)), min_size=1, max_size=30),
       st.lists(st.tuples(coord, coord), min_size=1, max_size=60), st.integers(0, 3))
@settings(max_examples=300, deadline=None)
def test_candidates_are_every_box_that_holds_the_point(boxes, pts, scale):
    # boxes from a metre to a few km (some span more cells than the grid files), points on their edges too
    from synth.road.lane_facts import PolygonIndex

    k = 10.0 ** scale
    feats = tuple(MapFeature("m", f"p{i}", LANE, polygon=((x, y), (x + w * k, y), (x + w * k, y + h * k),
                                                         (x, y + h * k)))
                  for i, (x, y, w, h) in enumerate(boxes))
    pts = pts + [(x + w * k, y) for x, y, w, _ in boxes]
    index = PolygonIndex(feats)
    xs, ys = np.array([p[0] for p in pts]), np.array([p[1] for p in pts])
    pi, fi = index.candidates(xs, ys)
    b = index.box
    want = [(i, j) for i in range(len(pts)) for j in range(len(feats))
            if b[j, 0] <= xs[i] <= b[j, 2] and b[j, 1] <= ys[i] <= b[j, 3]]
    assert list(zip(pi.tolist(), fi.tolist())) == want


@given(st.lists(st.lists(st.tuples(st.sampled_from([0.0, -0.0, 1.0, 2.5]), st.sampled_from([0.0, 1.0, -3.0])),
                         max_size=7), max_size=8))
@settings(max_examples=400, deadline=None)
def test_three_distinct_is_len_of_set_of_each_ring(rings):
    from synth.road.roadmap import _three_distinct, packed

    got = _three_distinct(*packed([tuple(r) for r in rings])).tolist()
    assert got == [len(set(r)) >= 3 for r in rings]


@given(lines)
@settings(max_examples=200, deadline=None)
def test_halfways_of_long_lines_one_at_a_time_are_the_matrix_s(raw):
    # lines beyond ROW_SPAN segments are summed one at a time; the same additions in the same order
    import synth.road.lane_geometry as lg

    xy, kept = dedup_packed(list(raw))
    rows = lg.halfways(xy, kept)
    span, lg.ROW_SPAN = lg.ROW_SPAN, 0
    try:
        assert lg.halfways(xy, kept) == rows
    finally:
        lg.ROW_SPAN = span


@given(st.lists(st.lists(st.tuples(st.floats(-50, 50), st.floats(-50, 50)), min_size=2, max_size=12), min_size=1,
                max_size=5), st.floats(0.1, 8.0), st.floats(0.1, 8.0))
@settings(max_examples=300, deadline=None)
def test_lane_polygons_are_simple_rings_as_check_simple_trusts(raw, left, right):
    # check_simple does not ask GEOS again about a ShellRing (the shell GEOS's buffer made): it must be simple,
    # however tightly the centre line turns or doubles back
    from synth.road.roadmap import ShellRing, ring_is_simple

    for ring in lane_polygons([tuple(r) for r in raw], [left] * len(raw), [right] * len(raw)):
        assert ring == () or (type(ring) is ShellRing and ring_is_simple(ring))


def test_the_widening_bounds_pass_every_short_line_and_measure_the_rest():
    """Lines too short to exceed a bound are not measured (lane_polygons): that is sound only if the shortcut's
    lengths are the largest within the bounds whatever the line, which the bounds' own arithmetic says."""
    assert SHORT_WORK ** 2 <= WORK_PER_POINT * SHORT_WORK + WORK_BASE < (SHORT_WORK + 1) ** 2
    assert (SHORT_TURNING - 2) * math.pi <= MAX_TURNING < (SHORT_TURNING - 1) * math.pi
    # n vertices in one cell cost n^2; spread one a cell, n
    n = 50
    one_cell = np.column_stack([np.linspace(0, 0.1, n), np.zeros(n)])
    spread = np.column_stack([np.arange(n) * 10.0, np.zeros(n)])
    work = widening_work(np.concatenate([one_cell, spread]), np.array([n, n]), np.array([1.7, 1.7]),
                         np.array([True, True]))
    assert work.tolist() == [n * n, n]


@given(st.lists(st.integers(0, 9), max_size=30), st.integers(1, 12))
@settings(max_examples=300, deadline=None)
def test_row_chunks_cover_every_pair_in_order_within_the_limit(rows, limit):
    with patch.object(lane_facts, "CHUNK_ROWS", limit):
        chunks = row_chunks(np.array(rows, dtype=np.int64))
    assert [i for c in chunks for i in range(len(rows))[c]] == list(range(len(rows)))
    # each chunk within the limit, or one pair alone; and no two neighbours that would fit in one
    assert all(sum(rows[c]) <= limit or c.stop - c.start == 1 for c in chunks)
    assert all(sum(rows[a]) + rows[b.start] > limit for a, b in zip(chunks, chunks[1:]))


@given(st.lists(st.tuples(st.integers(-6, 6), st.integers(-6, 6)), min_size=40, max_size=300),
       st.lists(st.tuples(st.integers(-14, 14), st.integers(-14, 14)), min_size=1, max_size=30), st.sampled_from(MODES))
@settings(max_examples=150, deadline=None)
def test_a_long_line_pruned_by_blocks_gives_the_first_nearest_segment_even_among_ties(walk, points, mode):
    # a line on a small grid of half metres folds back over itself: many segments at the same least distance
    # from a point, in different blocks, and the pruned search must still pick np.argmin's first
    line = tuple((x / 2, y / 2) for x, y in walk)
    _assert_nearest_is_segments_nearest((line, line[:3]), [(0, x / 4, y / 4) for x, y in points] + [(1, 0.0, 0.0)],
                                        {**mode, "LONG_LINE": mode.get("LONG_LINE", 8)})


@given(st.lists(st.tuples(st.lists(st.tuples(st.floats(-50, 50), st.floats(-50, 50)), min_size=2, max_size=8),
                          st.sampled_from([0.5, 1.7, 2.0]), st.sampled_from([0.5, 1.7, 2.0])), min_size=1,
                max_size=6))
@settings(max_examples=150, deadline=None)
def test_a_batch_of_lanes_some_sided_widens_each_as_alone(lanes):
    # a batch buffers the lanes whose sides agree and those whose sides differ in separate calls: each lane's
    # polygon must still be its own: the outer ring of its line's buffer (or of the union of its single-sided ones)
    raw = [tuple(line) for line, _, _ in lanes]
    rings = lane_polygons(raw, [left for _, left, _ in lanes], [right for _, _, right in lanes])
    for (line, left, right), ring in zip(lanes, rings):
        assert ring == lane_polygon(tuple(line), left, right)
        if ring:
            g = shapely.LineString(dedup(tuple(line)))
            area = (shapely.buffer(g, left, cap_style="flat", join_style="bevel") if left == right else
                    shapely.union(shapely.buffer(g, left, cap_style="flat", join_style="bevel", single_sided=True),
                                  shapely.buffer(g, -right, cap_style="flat", join_style="bevel",
                                                 single_sided=True)))
            area = area if area.geom_type == "Polygon" else max(area.geoms, key=lambda p: p.area)
            # its outer ring kept: GEOS's, or the offset ring that bounds the same set but for merged bevels
            near = BEVEL_MERGE ** 2 / (4 * min(left, right)) + 1e-9
            assert shapely.hausdorff_distance(shapely.Polygon(ring), shapely.Polygon(area.exterior)) <= near
