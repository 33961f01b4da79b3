"""The two documented rules that complete a source's lanes (docs/formats.md, "Maps Parquet"):

- **A lane without a polygon** (Waymo-converted scenarios give a centre line and widths; nuScenes lane
  connectors come with a centre line only) gets the polygon of its centre line widened to each side by its half
  widths (the mean of the source's per-vertex widths on each side where it gives them, else half of
  DEFAULT_LANE_WIDTH): see `lane_polygon` (its offset ring where that is the buffer, else GEOS's buffer).
- **A lane without neighbours in its source** (nuScenes via ScenarioNet) gets them by probing: from the point
  halfway along its centre line (by length), one lane width to the left and to the right, square to the
  centre-line segment there; the width is the lane's there, twice the distance to its polygon's boundary. The neighbour on a side is the lane containing the probe
  point whose direction there (its nearest centre-line segment) is within NEIGHBOUR_ANGLE of the lane's own,
  the nearest to the probe by centre line if several (then the smaller id); intersection lanes neither have nor
  are neighbours. None is found where no such lane contains the probe (the edge of the road, or a lane of
  opposite direction: that is the oncoming lane, never a neighbour).
"""

from __future__ import annotations

import math
from bisect import bisect_left
from itertools import accumulate

import numpy as np

from synth.road.lane_facts import PackedSegments, PolygonIndex, Segments
from synth.road.roadmap import LANE, MapFeature, Points, ShellRing, packed, packed_subset

# The width of a nuScenes lane connector, which the converter gives without polygon or width: the median width
# (twice the distance from the centre line's halfway point to the polygon's boundary) of the nuScenes lanes that
# have a polygon in the six nuScenes-mini scenes of ../shared/data, 3.4 m (bench/results/maps.md).
DEFAULT_LANE_WIDTH = 3.4
NEIGHBOUR_ANGLE = 30.0  # degrees
# The half widths (metres, to one side of a centre line) a source's per-vertex widths may give: outside, a width
# is unknown (the lane's other side there, else the default). Real lanes are 0.7 to 5 m wide; the Waymo converter
# writes 0 where it found no boundary and, where it pairs a lane with the wrong end of its boundary, widths that
# grow by twice the step to over 100 m (bench/results/maps.md). Below MIN_HALF_WIDTH a lane's polygon is thinner
# than the rounding of moving it into an ego frame (a polygon of width 1e-300 collapses there).
MIN_HALF_WIDTH, MAX_HALF_WIDTH = 0.1, 5.0
# The work of widening one centre line is bounded by its size: GEOS's buffer nodes every crossing of the line's
# offset curves, and a line that folds back on itself within its width has a number of them that grows as the
# square of its points (a zigzag of 10^4 points took 1.5 GB, then std::bad_alloc; one of 2,000 over a minute). A
# line is widened only if (a) the sum, over the cells of a grid of side twice its half width, of the square of
# the number of its vertices in each cell (`widening_work`) is at most WORK_PER_POINT per vertex plus WORK_BASE,
# and (b) it turns (`turning`) at most MAX_TURNING radians plus TURNING_PER_POINT per vertex. The real lanes of
# ../shared (Waymo, nuScenes) use at most 21 per vertex and 5.4 pi; a line beyond either is not widened (its lane
# is dropped, and counted).
WORK_PER_POINT, WORK_BASE = 64, 4096
MAX_TURNING, TURNING_PER_POINT = 16 * math.pi, 0.05
SHORT_WORK = int(WORK_PER_POINT / 2 + math.sqrt(WORK_PER_POINT ** 2 / 4 + WORK_BASE))  # n^2 <= 64 n + 4096
SHORT_TURNING = int(MAX_TURNING / math.pi) + 2  # n - 2 joints of at most pi each


def dedup(line: Points) -> Points:
    return tuple(p for i, p in enumerate(line) if i == 0 or p != line[i - 1])


def dedup_packed(lines: list[Points]) -> tuple[np.ndarray, np.ndarray]:
    """`dedup` of many lines at once: their points without consecutive repeats, concatenated (N, 2), and how many
    each line keeps."""
    return dedup_arrays(*packed(lines))


def dedup_arrays(xy: np.ndarray, counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """`dedup_packed` of lines already packed (`packed`'s output)."""
    line = np.repeat(np.arange(len(counts)), counts)
    keep = np.ones(len(xy), dtype=bool)
    keep[1:] = (xy[1:] != xy[:-1]).any(axis=1)
    keep[(np.cumsum(counts) - counts)[counts > 0]] = True  # a line's first point
    return xy[keep], np.bincount(line[keep], minlength=len(counts)).astype(np.int64)


def lane_polygon(line: Points, left: float | None = None, right: float | None = None) -> Points:
    """The polygon of a centre line widened by `left` / `right` metres to each side (None: half of
    DEFAULT_LANE_WIDTH); empty for a line of fewer than two distinct points.

    The set of points within those distances of the line, cut square at its ends: GEOS's buffer of the line
    (flat caps, bevel joins; one single-sided buffer per side when the sides differ), its outer ring kept; or,
    where it provably bounds that set (`offset_rings`), the line's offset ring, without GEOS. Unlike the offset
    ring everywhere, a buffer never folds over itself where the line turns tighter than its width (a third of the
    nuScenes lane connectors do, at the joints of their arcs): those lines take GEOS's."""
    return lane_polygons([line], [left], [right])[0]


def lane_polygons(lines: list[Points], lefts: list[float | None], rights: list[float | None]) -> list[Points]:
    """`lane_polygon` of many lines, in a few vectorised numpy passes and GEOS calls (a map has hundreds of such
    lanes). A line that cannot be widened gets an empty polygon, as one of fewer than two distinct points: a
    non-finite coordinate, a half width outside (0, inf), more work than `widening_work` allows, or an error of
    GEOS's."""
    import shapely

    half = DEFAULT_LANE_WIDTH / 2
    out: list[Points] = [()] * len(lines)
    xy, kept = dedup_packed(lines)
    left_all = np.array([half if w is None else w for w in lefts], dtype=float)
    right_all = np.array([half if w is None else w for w in rights], dtype=float)
    line = np.repeat(np.arange(len(lines)), kept)
    finite = np.bincount(line, weights=~np.isfinite(xy).all(axis=1), minlength=len(lines)) == 0
    sane = finite & (left_all > 0) & (right_all > 0) & np.isfinite(left_all) & np.isfinite(right_all)
    ok = (kept >= 2) & sane
    # a line of at most SHORT_WORK points is within the work bound whatever it is (n^2 <= 64 n + 4096), and one of
    # at most SHORT_TURNING within the turning bound (pi a joint): only longer lines are measured
    long = ok & (kept > SHORT_WORK)
    if long.any():
        ok[long] = widening_work(xy, kept, np.maximum(left_all, right_all), long)[long] <= (
            WORK_PER_POINT * kept[long] + WORK_BASE)
    long = ok & (kept > SHORT_TURNING)
    if long.any():
        ok[long] = (turning(xy, kept) <= MAX_TURNING + TURNING_PER_POINT * kept)[long]
    todo = np.flatnonzero(ok).tolist()
    if not todo:
        return out
    # the offset rings first (numpy, a few passes over all lines); GEOS only for the lines whose ring is not
    # provably the buffer's (bench/results/maps.md: 96% of the Waymo lanes, 68% of the nuScenes ones take the
    # offset ring)
    fast = offset_rings(xy, kept, left_all, right_all, ok)
    _emit(out, *fast)
    todo = [i for i in todo if not out[i]]
    if not todo:
        return out
    used = np.isin(line, todo)
    geoms = shapely.linestrings(xy[used], indices=np.searchsorted(todo, line[used]))
    left, right = left_all[todo], right_all[todo]
    try:
        areas = _widened(geoms, left, right)
    except shapely.errors.GEOSException:  # one line at a time: those GEOS cannot widen keep no polygon
        areas = np.array([_widened_or_none(geoms[k:k + 1], left[k:k + 1], right[k:k + 1])
                          for k in range(len(todo))], dtype=object)
    made = ~shapely.is_missing(areas) & ~shapely.is_empty(areas)
    areas, todo = areas[made], [i for i, m in zip(todo, made.tolist()) if m]
    if not todo:
        return out
    ring, which = shapely.get_coordinates(shapely.get_exterior_ring(areas), return_index=True)
    counts = np.bincount(which, minlength=len(todo))
    closing = np.cumsum(counts) - 1  # each ring's closing repeat dropped
    keep = np.ones(len(ring), dtype=bool)
    keep[closing] = False
    _emit(out, np.asarray(todo), ring[keep], counts - 1)
    return out


def _emit(out: list[Points], which: np.ndarray, ring: np.ndarray, counts: np.ndarray) -> None:
    """Each of `which`'s lines' ring (packed, without closing repeat) into `out`, as a ShellRing."""
    ring = np.ascontiguousarray(ring, dtype=float)  # made here: each ring keeps its slice of it, no copy
    ends = np.cumsum(counts).tolist()
    for i, end, k in zip(which.tolist(), ends, counts.tolist()):
        out[i] = ShellRing.owning(ring[end - k:end])


# Two bevel points closer than this (metres) are one: the miter point of their joint, which lies beyond their
# chord by under 1e-6 m there (the chord's sagitta, a quarter of BEVEL_MERGE times the joint's angle).
BEVEL_MERGE = 1e-2
# A segment shorter than this (metres) is below the precision of its offsets' directions at map coordinates
# (1e4 m: 1e-12 relative): a line that has one is widened by GEOS.
MIN_SEGMENT = 1e-6


def offset_rings(xy: np.ndarray, kept: np.ndarray, left: np.ndarray, right: np.ndarray,
                 which: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The buffers of `which` of the packed lines (dedup_packed's: at least two points, finite, without
    consecutive repeats) that are their offset rings: each side's offset of every segment, joined at a joint
    turning away from the side by its bevel (both offset points; one, the miter point, where they are within
    BEVEL_MERGE) and at one turning towards it by the offsets' crossing (the miter point), the left side forward,
    then the right side back, as GEOS's flat-capped, bevel-joined buffer has it. That ring bounds the buffer
    where no offset segment runs against its centre segment (else the offsets cross over: a swallowtail) and
    the ring is simple (else the line comes back within its width); only those lines are returned: which lines
    (indices), their rings packed (without closing repeat, clockwise as GEOS's) and each ring's point count."""
    import shapely

    sub, k = (xy, kept) if which.all() else (xy[np.repeat(which, kept)], kept[which])
    lines = np.flatnonzero(which)
    if not len(lines):
        return lines, np.empty((0, 2)), np.zeros(0, dtype=np.int64)
    line = np.repeat(np.arange(len(lines)), k)
    first = np.cumsum(k) - k
    last = first + k - 1
    d = np.diff(sub, axis=0)
    length = np.hypot(d[:, 0], d[:, 1])
    with np.errstate(all="ignore"):  # across two lines' ends: unused
        t = d / length[:, None]
    normal = np.empty_like(sub)  # the left normal of each point's next segment (of its last: its previous one)
    normal[:-1, 0], normal[:-1, 1] = -t[:, 1], t[:, 0]
    before = np.empty_like(sub)  # of its previous segment (of its first: its next one)
    before[1:] = normal[:-1]
    normal[last] = before[last]
    before[first] = normal[first]
    cross = before[:, 0] * normal[:, 1] - before[:, 1] * normal[:, 0]
    dot = before[:, 0] * normal[:, 0] + before[:, 1] * normal[:, 1]
    # the points whose line GEOS widens (one bincount at the end): a joint of over 120 degrees (the miter is far
    # and ill-conditioned), a segment too short, an offset segment running against its centre segment (below)
    wrong = dot <= -0.5
    seg = np.ones(len(sub) - 1, dtype=bool)  # d[i] is a segment of a line
    seg[last[:-1]] = False
    wrong[:-1] |= seg & ~(length >= MIN_SEGMENT)
    with np.errstate(all="ignore"):
        miter = (before + normal) / (1.0 + dot)[:, None]
    gap = np.hypot(*(before - normal).T)  # of the bevel's two points, per metre of width
    sides = []
    for width, towards in ((left[which][line], cross > 0), (-right[which][line], cross < 0)):
        one = towards | (np.abs(width) * gap < BEVEL_MERGE)
        w = width[:, None]
        # the direction first, then one product and sum a point: the same floats as the miter point's or the
        # bevel point's own sub + w * direction
        a = sub + w * np.where(one[:, None], miter, before)
        b = sub + w * np.where(one[:, None], miter, normal)
        # each offset segment (b of its start to a of its end) runs the way of its centre segment
        step = a[1:] - b[:-1]
        wrong[:-1] |= seg & ~(step[:, 0] * t[:, 0] + step[:, 1] * t[:, 1] > 0)
        sides.append((a, b, one))
    bad = np.bincount(line[wrong], minlength=len(lines)) > 0
    (la, lb, lone), (ra, rb, rone) = sides
    # ring of line j: its points' (a, b) on the left forward, then (b, a) on the right backward; a single point
    # where a joint has one (`one`)
    per_left = np.where(lone, 1, 2)
    per_right = np.where(rone, 1, 2)
    n_left = np.bincount(line, weights=per_left, minlength=len(lines)).astype(np.int64)
    n_right = np.bincount(line, weights=per_right, minlength=len(lines)).astype(np.int64)
    counts = n_left + n_right
    ring_start = np.cumsum(counts) - counts
    ring = np.empty((int(counts.sum()), 2))
    # left: the a's at their place, then the b's of the two-point joints after them
    lpos = ring_start[line] + (np.cumsum(per_left) - per_left) - (np.cumsum(n_left) - n_left)[line]
    ring[lpos] = la
    ring[lpos[~lone] + 1] = lb[~lone]
    # right, backward: the point's place counted from the ring's end
    rpos = (ring_start + counts)[line] - 1 - ((np.cumsum(per_right) - per_right) - (np.cumsum(n_right) - n_right)[line])
    ring[rpos] = ra
    ring[rpos[~rone] - 1] = rb[~rone]
    ring_line = np.repeat(np.arange(len(lines)), counts)
    good = ~bad
    if good.any():
        rings = shapely.linearrings(ring[good[ring_line]], indices=np.repeat(np.arange(good.sum()), counts[good]))
        good[good] = shapely.is_simple(rings)
    return lines[good], ring[good[ring_line]], counts[good]


def _widened(geoms: np.ndarray, left: np.ndarray, right: np.ndarray) -> np.ndarray:
    """The buffers of lines (flat caps, bevel joins; one single-sided buffer per side where the sides differ),
    each as one polygon: of parts that meet only at a point, the largest."""
    import shapely

    # each line buffered once: both sides in one buffer where they agree, else one single-sided buffer a side
    # (GEOS buffers each geometry of an array alone, so a subset's buffers are those of the whole array)
    sided = left != right
    areas = np.empty(len(geoms), dtype=object)
    areas[~sided] = shapely.buffer(geoms[~sided], left[~sided], cap_style="flat", join_style="bevel")
    if sided.any():
        areas[sided] = shapely.union(
            shapely.buffer(geoms[sided], left[sided], cap_style="flat", join_style="bevel", single_sided=True),
            shapely.buffer(geoms[sided], -right[sided], cap_style="flat", join_style="bevel", single_sided=True))
    multi = shapely.get_type_id(areas) != 3
    for k in np.flatnonzero(multi):  # parts that meet only at a point: keep the largest
        parts = getattr(areas[k], "geoms", ())
        areas[k] = max(parts, key=lambda g: g.area) if len(parts) else None
    return areas


def _widened_or_none(geoms: np.ndarray, left: np.ndarray, right: np.ndarray):
    import shapely

    try:
        return _widened(geoms, left, right)[0]
    except shapely.errors.GEOSException:
        return None


def turning(xy: np.ndarray, kept: np.ndarray) -> np.ndarray:
    """Each packed line's total turning: the sum of the absolute angles (radians) between its consecutive
    segments (lines without consecutive repeats: dedup_packed's)."""
    out = np.zeros(len(kept))
    if len(xy) < 3:
        return out
    line = np.repeat(np.arange(len(kept)), kept)
    d = np.diff(xy, axis=0)
    same = line[1:] == line[:-1]  # d[i] is a segment of line[i] when same[i]
    joint = same[:-1] & same[1:]  # d[i], d[i + 1] are consecutive segments of one line
    a, b = d[:-1][joint], d[1:][joint]
    with np.errstate(all="ignore"):
        angle = np.abs(np.arctan2(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0], a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1]))
    np.add.at(out, line[1:-1][joint], np.nan_to_num(angle, nan=np.pi))
    return out


def widening_work(xy: np.ndarray, kept: np.ndarray, half: np.ndarray, which: np.ndarray) -> np.ndarray:
    """For each packed line (`which` of them; 0 for the others), the work estimate of widening it by `half`: its
    vertices filed in the cells of a grid of side 2 * half (at least MIN_HALF_WIDTH), the sum of the squares of
    the number in each cell. A line that runs on counts a few vertices a cell; one that folds back within its
    width counts them all in a few cells."""
    work = np.zeros(len(kept))
    line = np.repeat(np.arange(len(kept)), kept)
    mine = which[line]
    if not mine.any():
        return work
    side = 2.0 * np.maximum(half, MIN_HALF_WIDTH)[line[mine]]
    with np.errstate(all="ignore"):
        cells = np.floor(xy[mine] / side[:, None])
    cells = np.clip(np.nan_to_num(cells), -2**31, 2**31).astype(np.int64)
    # one integer a (line, cell): lines and cells packed into disjoint bit ranges (np.unique of rows is slow)
    keys = (line[mine] << 64 - 21) ^ ((cells[:, 0] & (2**21 - 1)) << 21) ^ (cells[:, 1] & (2**21 - 1))
    uniq, first, counts = np.unique(keys, return_index=True, return_counts=True)
    np.add.at(work, line[mine][first], counts.astype(float) ** 2)
    return work


def widths_at(lanes: list[MapFeature], xs: np.ndarray, ys: np.ndarray,
              polygons: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """`width_at` of many lanes, each at its point, in one pass: each ring's segments as Segments.of makes them
    (closed, those of length 0 left out), Segments.nearest's arithmetic on the same values, the least gap.
    `polygons`: the lanes' polygons packed, if the caller has them."""
    out = np.zeros(len(lanes))
    polygons = polygons if polygons is not None else packed([f.polygon for f in lanes])
    mine = polygons[1] >= 3
    ok = np.flatnonzero(mine).tolist()
    if not ok:
        return out
    xy, counts = packed_subset(polygons, mine)
    start = np.cumsum(counts) - counts
    nxt = np.arange(1, len(xy) + 1)
    nxt[start + counts - 1] = start  # the closing segment
    a, d = xy, xy[nxt] - xy
    length2 = (d * d).sum(axis=1)
    lane = np.repeat(np.asarray(ok), counts)
    keep = length2 > 0
    a, d, length2, lane = a[keep], d[keep], length2[keep], lane[keep]
    x, y = xs[lane], ys[lane]
    t = np.clip(((x - a[:, 0]) * d[:, 0] + (y - a[:, 1]) * d[:, 1]) / length2, 0, 1)
    gap = np.hypot(a[:, 0] + t * d[:, 0] - x, a[:, 1] + t * d[:, 1] - y)
    n = np.bincount(lane, minlength=len(lanes))
    has = n > 0
    out[has] = 2.0 * np.minimum.reduceat(gap, (np.cumsum(n) - n)[has])
    return out


def width_at(f: MapFeature, x: float, y: float) -> float:
    """A lane's width at a point of its centre line: twice the distance from the point to its polygon's boundary."""
    ring = np.asarray(f.polygon, dtype=float).reshape(-1, 2)
    seg = Segments.of(np.concatenate([ring, ring[:1]])) if len(ring) >= 3 else None
    return 2.0 * seg.nearest(x, y)[1] if seg is not None else 0.0


def halfway(line: Points) -> tuple[float, float, float, float] | None:
    """(x, y, ux, uy): the point halfway along a line by arc length and the unit direction of its segment."""
    p = np.asarray(dedup(line), dtype=float).reshape(-1, 2)
    return halfways(p, np.array([len(p)]))[0]


ROW_SPAN = 512  # segments: lines up to this long have their running lengths summed as rows of one matrix


def halfways(xy: np.ndarray, kept: np.ndarray) -> list[tuple[float, float, float, float] | None]:
    """`halfway_rows` as one tuple per line, None for a line of fewer than two points."""
    rows = halfway_rows(xy, kept)
    return [tuple(r) if n >= 2 else None for r, n in zip(rows.tolist(), np.asarray(kept).reshape(-1).tolist())]


def halfway_rows(xy: np.ndarray, kept: np.ndarray) -> np.ndarray:
    """The point halfway along each of many lines (packed as dedup_packed gives them: no consecutive repeats)
    and the unit direction of its segment, one row (x, y, ux, uy) a line: each line's running length summed in
    order (np.cumsum along a row, or itertools.accumulate for a line longer than ROW_SPAN: the same additions),
    the first segment where it reaches half the total, the point that far along it. NaN for a line of fewer
    than two points or with a NaN coordinate (RoadMap.of refuses such maps)."""
    kept = np.asarray(kept, dtype=np.int64).reshape(-1)
    lines = len(kept)
    seg = np.diff(xy, axis=0) if len(xy) else np.zeros((0, 2))
    length = np.hypot(seg[:, 0], seg[:, 1])
    start = np.cumsum(kept) - kept
    nseg = np.maximum(kept - 1, 0)
    total, before, k = np.zeros(lines), np.zeros(lines), np.zeros(lines, dtype=np.int64)
    short = np.flatnonzero((nseg > 0) & (nseg <= ROW_SPAN))
    if len(short):
        width = int(nseg[short].max())
        row = np.repeat(np.arange(len(short)), nseg[short])
        col = np.arange(len(row)) - np.repeat(np.cumsum(nseg[short]) - nseg[short], nseg[short])
        grid = np.zeros((len(short), width))
        grid[row, col] = length[np.repeat(start[short], nseg[short]) + col]
        run = np.cumsum(grid, axis=1)
        total[short] = run[np.arange(len(short)), nseg[short] - 1]
        with np.errstate(invalid="ignore"):
            below = (run < (total[short] / 2)[:, None]) & (np.arange(width) < nseg[short][:, None])
        k[short] = np.minimum(below.sum(axis=1), nseg[short] - 1)
        has = k[short] > 0
        before[short[has]] = run[np.flatnonzero(has), k[short[has]] - 1]
    for i in np.flatnonzero(nseg > ROW_SPAN).tolist():  # long lines: the same sums, one line at a time
        lengths = length[start[i]:start[i] + nseg[i]].tolist()
        run_i = list(accumulate(lengths))
        total[i] = run_i[-1]
        k[i] = min(bisect_left(run_i, run_i[-1] / 2), nseg[i] - 1)
        before[i] = run_i[k[i] - 1] if k[i] else 0.0
    out = np.full((lines, 4), np.nan)
    some = np.flatnonzero(nseg > 0)
    at = start[some] + k[some]  # the segment (and its first point) holding the halfway point
    with np.errstate(all="ignore"):
        lk = length[at]
        t = (total[some] / 2 - before[some]) / lk
        d, p = seg[at], xy[at]
        mid = np.stack([p[:, 0] + t * d[:, 0], p[:, 1] + t * d[:, 1], d[:, 0] / lk, d[:, 1] / lk], axis=1)
    mid[~(lk > 0)] = np.nan
    out[some] = mid
    return out


def neighbours(lanes: tuple[MapFeature, ...], lines: tuple[np.ndarray, np.ndarray] | None = None,
               polygons: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[MapFeature, ...]:
    """The lanes with left / right neighbours found by the probing rule (neighbour_rule "geometric"). `lines`,
    `polygons`: the lanes' lines and polygons packed, if the caller has them (RoadMap.packed)."""
    mine = np.fromiter((f.kind == LANE and not f.is_intersection for f in lanes), dtype=bool, count=len(lanes))
    candidates = tuple(f for f, m in zip(lanes, mine.tolist()) if m)
    lines = packed_subset(lines, mine) if lines is not None else packed([f.line for f in candidates])
    polygons = packed_subset(polygons, mine) if polygons is not None else packed([f.polygon for f in candidates])
    cos_limit = math.cos(math.radians(NEIGHBOUR_ANGLE))
    xy, kept = dedup_arrays(*lines)
    mid = halfway_rows(xy, kept)
    has_mid = kept >= 2
    at = np.flatnonzero(has_mid).tolist()
    w = np.zeros(len(mid))
    w[at] = widths_at([candidates[i] for i in at], mid[at, 0], mid[at, 1], packed_subset(polygons, has_mid))
    # every probe point of every lane, tested at once: lane i's left probe, then its right one
    probing = np.flatnonzero(has_mid & ~(w <= 0))
    x, y, ux, uy = (mid[probing, c] for c in range(4))
    wp = w[probing]
    qx = np.stack([x - 1.0 * wp * uy, x - -1.0 * wp * uy], axis=1).reshape(-1)
    qy = np.stack([y + 1.0 * wp * ux, y + -1.0 * wp * ux], axis=1).reshape(-1)
    own = np.repeat(probing, 2)
    side_of = np.tile([0, 1], len(probing))
    pux, puy = np.repeat(ux, 2), np.repeat(uy, 2)
    pi, fi = PolygonIndex(candidates, polygons).pairs(qx, qy)
    other = fi != own[pi]
    pi, fi = pi[other], fi[other]
    # the nearest segment of each lane hit to its probe (Segments.nearest's arithmetic), and its direction there
    segments = PackedSegments.of_packed(*lines)
    row, gap = segments.nearest(fi, qx[pi], qy[pi])
    has = row >= 0
    pi, fi, row, gap = pi[has], fi[has], row[has], gap[has]
    d = segments.d[row] / np.sqrt(segments.length2[row])[:, None]
    along = ~(d[:, 0] * pux[pi] + d[:, 1] * puy[pi] < cos_limit)
    sides: dict[tuple[int, str], tuple[float, str]] = {}
    for p, k, g in zip(pi[along].tolist(), fi[along].tolist(), gap[along].tolist()):
        i, side = int(own[p]), ("left", "right")[side_of[p]]
        best = (g, candidates[k].feature_id)
        if (i, side) not in sides or best < sides[i, side]:
            sides[i, side] = best
    index = {f.feature_id: i for i, f in enumerate(candidates)}
    out = []
    for f in lanes:
        i = index.get(f.feature_id) if f.kind == LANE and not f.is_intersection else None
        if i is None:
            out.append(f.with_(neighbour_rule="geometric"))
            continue
        left, right = sides.get((i, "left")), sides.get((i, "right"))
        out.append(f.with_(left=left and left[1], right=right and right[1], neighbour_rule="geometric"))
    return tuple(out)
