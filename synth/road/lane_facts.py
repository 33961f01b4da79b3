"""Where each entity is on the road: the lane facts of a point, decided exactly (docs/formats.md, "Lane facts").

A point is in a polygon when it lies inside it or on its boundary (closed polygons), decided on the exact
rational values of the floats: the crossing-number test whose only arithmetic is the sign of one 2x2
determinant per edge, taken from the float value when Shewchuk's error bound proves the float sign right and
recomputed with fractions.Fraction otherwise. Every other step is a comparison of floats, which is exact.

Speed comes from two float pre-filters that are conservative by construction: a polygon whose bounding box (the
exact minima and maxima of its vertices) does not contain the point cannot contain it, and an edge's float
determinant is trusted only beyond the error bound. So the answer is the exact one, and only points within
rounding distance of an edge pay for rational arithmetic.

The facts of a point in a map (LaneFacts): the lanes containing it (sorted by id), the chosen lane (among those,
the one whose direction at the point is closest to the entity's heading; ties by id), whether it is in an
intersection (an intersection feature, or a lane flagged as an intersection lane), on a crosswalk, and off road
(in no lane and no drivable area).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from synth.road.roadmap import CROSSWALK, DRIVABLE_AREA, INTERSECTION, LANE, MapFeature, RoadMap, packed

EPS = 2.0 ** -53
# Shewchuk, "Adaptive precision floating-point arithmetic and fast robust geometric predicates" (1997):
# |det - float det| <= CCW_ERRBOUND * (|detleft| + |detright|) for det = detleft - detright of orient2d.
CCW_ERRBOUND = (3.0 + 16.0 * EPS) * EPS


def orientation(ax: float, ay: float, bx: float, by: float, px: float, py: float) -> int:
    """The exact sign of the cross product (b - a) x (p - a): 1 if p is left of a->b, -1 right, 0 on the line."""
    detleft = (bx - ax) * (py - ay)
    detright = (by - ay) * (px - ax)
    det = detleft - detright
    bound = CCW_ERRBOUND * (abs(detleft) + abs(detright))
    if det > bound:
        return 1
    if -det > bound:
        return -1
    exact = (Fraction(bx) - Fraction(ax)) * (Fraction(py) - Fraction(ay)) - \
        (Fraction(by) - Fraction(ay)) * (Fraction(px) - Fraction(ax))
    return (exact > 0) - (exact < 0)


def contains(ring: tuple[tuple[float, float], ...], px: float, py: float) -> bool:
    """Whether the closed polygon `ring` (vertices in order, without the closing repeat) contains (px, py):
    exactly, one edge at a time (the reference the vectorised PolygonIndex must agree with)."""
    n = len(ring)
    return covers(((*ring[i], *ring[(i + 1) % n]) for i in range(n)), px, py)


def covers(edges, px: float, py: float) -> bool:
    """The crossing-number test of (px, py) over edges (ax, ay, bx, by): on one of them, or inside. Every edge
    whose y-range holds py must be among them (`contains` gives all; Banded those of one band)."""
    inside = False
    for ax, ay, bx, by in edges:
        if min(ax, bx) <= px <= max(ax, bx) and min(ay, by) <= py <= max(ay, by) \
                and orientation(ax, ay, bx, by, px, py) == 0:
            return True  # on the edge
        if (ay > py) != (by > py):
            o = orientation(ax, ay, bx, by, px, py)
            # The edge crosses the horizontal line through p; the crossing is right of p exactly when p is left
            # of an upward edge or right of a downward one.
            if (o > 0) if by > ay else (o < 0):
                inside = not inside
    return inside


BANDS = 64  # at most, per polygon (about one per four edges)


class PolygonIndex:
    """The polygons of some features as flat arrays, to test many points at once with the exact answer of
    `contains`: bounding boxes first (found through an R-tree, then compared exactly), then every edge of the
    candidates in float with the error bound, and `contains` itself for a (point, polygon) pair with an edge the
    float cannot decide."""

    def __init__(self, features: tuple[MapFeature, ...],
                 polygons: tuple[np.ndarray, np.ndarray] | None = None) -> None:
        """`polygons`: the features' polygons packed, if the caller has them (RoadMap.packed)."""
        self.features = features
        xy, counts = polygons if polygons is not None else packed([f.polygon for f in features])
        start = np.cumsum(counts) - counts
        self.start, self.count = start, counts
        if len(features):
            self.box = np.stack([np.minimum.reduceat(xy[:, 0], start), np.minimum.reduceat(xy[:, 1], start),
                                 np.maximum.reduceat(xy[:, 0], start), np.maximum.reduceat(xy[:, 1], start)], 1)
        else:
            self.box = np.zeros((0, 4))
        nxt = np.arange(1, len(xy) + 1)
        nxt[start + counts - 1] = start  # each ring's last vertex closes onto its first
        self.ax, self.ay = xy[:, 0], xy[:, 1]
        self.bx, self.by = xy[nxt, 0] if len(xy) else self.ax, xy[nxt, 1] if len(xy) else self.ay
        # A repeated vertex makes an edge of length 0: it crosses no horizontal line, and a point on it is the
        # vertex, on the next (non-degenerate) edge too; so it decides nothing and is left out of the float test
        # (its determinant, exactly 0, would otherwise send every point near it to the exact test).
        self.point_edge = (self.ax == self.bx) & (self.ay == self.by)
        self._tree = None
        self._grid: _BoxGrid | bool | None = None
        # Horizontal bands, as Banded cuts them: a point's crossing and on-edge tests only need the edges whose
        # y-range holds its y, all filed under its band (band_of is monotonic in y), a few of a polygon's dozens.
        # band_edges lists the edges of band g (of all polygons' bands, polygon by polygon) from band_start[g].
        self.bands = np.maximum(1, np.minimum(BANDS, counts // 4))
        self.band_height = (self.box[:, 3] - self.box[:, 1]) / self.bands
        self.band_height[self.band_height == 0] = 1.0
        self.band_first = np.cumsum(self.bands) - self.bands
        poly = np.repeat(np.arange(len(features)), counts)
        lo = self.band_of(np.minimum(self.ay, self.by), poly)
        hi = self.band_of(np.maximum(self.ay, self.by), poly)
        span = hi - lo + 1
        filed = np.repeat(np.arange(len(xy)), span)
        band = np.repeat(self.band_first[poly] + lo - (np.cumsum(span) - span), span) + np.arange(span.sum())
        order = np.argsort(band, kind="stable")
        self.band_edges = filed[order]
        self.band_start = np.searchsorted(band[order], np.arange(int(self.bands.sum()) + 1))

    def band_of(self, y: np.ndarray, poly: np.ndarray) -> np.ndarray:
        """The band (within its polygon) of each y, for y in that polygon's y-extent: Banded._band's formula."""
        k = ((y - self.box[poly, 1]) / self.band_height[poly]).astype(np.int64)
        return np.minimum(self.bands[poly] - 1, np.maximum(0, k))

    def candidates(self, xs: np.ndarray, ys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(point index, polygon index) of every pair whose polygon's box holds the point, in row-major order.
        A grid over the boxes (`_grid_proposals`; an R-tree where the map's extent is too odd for one) proposes
        a superset; the exact float comparison with the box decides, as a full points x boxes test would."""
        proposed = self._grid_proposals(xs, ys)
        pi, fi = proposed if proposed is not None else self._tree_proposals(xs, ys)
        b = self.box[fi]
        keep = (b[:, 0] <= xs[pi]) & (xs[pi] <= b[:, 2]) & (b[:, 1] <= ys[pi]) & (ys[pi] <= b[:, 3])
        pi, fi = pi[keep], fi[keep]
        if proposed is not None and not len(self._grid.wide):  # the grid's own order: points, then boxes, ascending
            return pi, fi
        order = np.lexsort((fi, pi))
        return pi[order], fi[order]

    def _tree_proposals(self, xs: np.ndarray, ys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pairs from an R-tree over the boxes, each widened by a margin (so that it finds a superset whatever it
        rounds)."""
        import shapely

        if self._tree is None:
            b = self.box
            m = 1e-9 * (1.0 + np.abs(b))
            self._tree = shapely.STRtree(shapely.box(b[:, 0] - m[:, 0], b[:, 1] - m[:, 1], b[:, 2] + m[:, 2],
                                                     b[:, 3] + m[:, 3]))
        return self._tree.query(shapely.points(xs, ys))

    def _grid_proposals(self, xs: np.ndarray, ys: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """Pairs from a uniform grid: each box filed under every cell its extent touches, each point meets the
        boxes of its cell. floor(v / side) is monotonic in v, so a box that holds a point is always filed under
        the point's cell: a superset, decided by numpy alone (an R-tree's query builds a geometry per point).
        Boxes spanning more than GRID_SPAN cells are proposed to every point. None (use the R-tree) when the
        grid would not fit in int64 keys or too many boxes are that large."""
        if self._grid is None:
            self._grid = _BoxGrid.of(self.box) or False
        return self._grid.proposals(xs, ys) if self._grid else None

    def containing(self, xs: np.ndarray, ys: np.ndarray) -> list[list[int]]:
        """For each point, the indices (into features, ascending) of the polygons that contain it."""
        xs = np.asarray(xs, dtype=float).reshape(-1)
        pi, fi = self.pairs(xs, ys)
        out: list[list[int]] = [[] for _ in range(len(xs))]
        for p, f in zip(pi.tolist(), fi.tolist()):  # row-major: each point's polygons ascending
            out[p].append(f)
        return out

    def covered(self, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
        """For each point, whether some polygon contains it."""
        xs = np.asarray(xs, dtype=float).reshape(-1)
        hit = np.zeros(len(xs), dtype=bool)
        hit[self.pairs(xs, ys)[0]] = True
        return hit

    def pairs(self, xs: np.ndarray, ys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(point index, polygon index) of every point and polygon that contains it, in row-major order."""
        xs, ys = np.asarray(xs, dtype=float).reshape(-1), np.asarray(ys, dtype=float).reshape(-1)
        none = np.zeros(0, dtype=np.int64)
        if not len(self.features) or not len(xs):
            return none, none
        pi, fi = self.candidates(xs, ys)
        if not len(pi):
            return none, none
        # The edges of the point's band of every candidate pair: pair k owns band_edges[band_start[g]:][:n], one
        # row of the pass each; in chunks of CHUNK_ROWS rows, as a polygon of 10^6 edges has thousands a band.
        g = self.band_first[fi] + self.band_of(ys[pi], fi)
        n = self.band_start[g + 1] - self.band_start[g]
        inside = np.concatenate([self._inside(pi[c], fi[c], g[c], n[c], xs, ys) for c in row_chunks(n)])
        return pi[inside], fi[inside]

    def _inside(self, pi: np.ndarray, fi: np.ndarray, g: np.ndarray, n: np.ndarray, xs: np.ndarray,
                ys: np.ndarray) -> np.ndarray:
        """Whether polygon fi[k] contains point pi[k], for candidate pairs whose point lies in band g[k] of n[k]
        edges."""
        pair = np.repeat(np.arange(len(pi)), n)
        edge = self.band_edges[np.repeat(self.band_start[g] - (np.cumsum(n) - n), n) + np.arange(n.sum())]
        px, py = xs[pi][pair], ys[pi][pair]
        ax, ay, bx, by = self.ax[edge], self.ay[edge], self.bx[edge], self.by[edge]
        detleft = (bx - ax) * (py - ay)
        detright = (by - ay) * (px - ax)
        det = detleft - detright
        sure = (np.abs(det) > CCW_ERRBOUND * (np.abs(detleft) + np.abs(detright))) | self.point_edge[edge]
        straddle = (ay > py) != (by > py)
        crossing = straddle & np.where(by > ay, det > 0, det < 0)
        # An edge whose sign the float cannot prove may be one p lies on, or one it crosses: decide exactly.
        doubtful = np.bincount(pair, weights=~sure, minlength=len(pi)) > 0
        inside = np.bincount(pair, weights=crossing & sure, minlength=len(pi)).astype(np.int64) % 2 == 1
        for k in np.flatnonzero(doubtful):
            inside[k] = contains(self.features[int(fi[k])].polygon, float(xs[pi[k]]), float(ys[pi[k]]))
        return inside


CHUNK_ROWS = 1 << 18  # rows (pair x segment, pair x edge) of one vectorised pass: some 30 MB of temporaries
LONG_LINE = 4096  # segments: a longer line's nearest segment is found by blocks (PackedSegments._pruned)
BLOCK_MIN = 16  # segments of a block, at least
PRUNE_SCALE = 1e100  # coordinates beyond: squares near overflow, the line is scanned whole


def row_chunks(rows: np.ndarray) -> list[slice]:
    """Consecutive slices of pairs whose rows (rows[j] for pair j) add up to at most CHUNK_ROWS, a pair of more
    rows in a slice of its own: a pass over every (pair, row) of a slice then holds at most max(CHUNK_ROWS, rows[j]) rows,
    bounded by the input (a line's or a polygon's own size) however many pairs meet a long one. One slice where
    all fit (every real map so far)."""
    ends, limit = np.cumsum(rows), CHUNK_ROWS
    if not len(ends) or ends[-1] <= limit:
        return [slice(0, len(rows))]
    out, i = [], 0
    while i < len(rows):
        j = max(i + 1, int(np.searchsorted(ends, (ends[i - 1] if i else 0) + limit, "right")))
        out.append(slice(i, j))
        i = j
    return out


GRID_SPAN = 64  # cells a box may span and still be filed in the grid
GRID_WIDE = 256  # boxes wider than that, at most, proposed to every point


@dataclass(frozen=True)
class _BoxGrid:
    """PolygonIndex's grid: the filed boxes' cell keys sorted (with their box), the wide boxes, the grid's cell
    side and extent (in cells)."""

    side: float
    x0: int
    y0: int
    nx: int
    ny: int
    keys: np.ndarray
    boxes: np.ndarray
    wide: np.ndarray

    @classmethod
    def of(cls, box: np.ndarray) -> _BoxGrid | None:
        if not len(box):
            return None
        # a side of about the typical box (a lane's), so that most boxes span a handful of cells
        side = max(1.0, float(np.median(np.maximum(box[:, 2] - box[:, 0], box[:, 3] - box[:, 1]))))
        with np.errstate(all="ignore"):
            cells = np.floor(box / side)
        if not np.isfinite(cells).all() or np.abs(cells).max() > 2.0 ** 40:
            return None
        cells = cells.astype(np.int64)
        x0, y0 = int(cells[:, 0].min()), int(cells[:, 1].min())
        nx, ny = int(cells[:, 2].max()) - x0 + 1, int(cells[:, 3].max()) - y0 + 1
        if nx * ny >= 2 ** 62:
            return None
        w, h = cells[:, 2] - cells[:, 0] + 1, cells[:, 3] - cells[:, 1] + 1
        filed = (w <= GRID_SPAN) & (h <= GRID_SPAN)
        wide = np.flatnonzero(~filed)
        if len(wide) > GRID_WIDE:
            return None
        j = np.flatnonzero(filed)
        n = w[j] * h[j]
        box_of = np.repeat(j, n)
        k = np.arange(int(n.sum())) - np.repeat(np.cumsum(n) - n, n)
        cx = cells[box_of, 0] - x0 + k % w[box_of]
        cy = cells[box_of, 1] - y0 + k // w[box_of]
        keys = cx * ny + cy
        order = np.argsort(keys, kind="stable")
        return cls(side, x0, y0, nx, ny, keys[order], box_of[order], wide)

    def proposals(self, xs: np.ndarray, ys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pairs in row-major order (points ascending, each point's filed boxes ascending: the keys were sorted
        stably over boxes in order), then the wide boxes' pairs."""
        with np.errstate(all="ignore"):
            fx, fy = np.floor(xs / self.side) - self.x0, np.floor(ys / self.side) - self.y0
        # points off the grid (or not finite) meet no filed box; the exact test would refuse them anyway
        on = np.flatnonzero((fx >= 0) & (fx < self.nx) & (fy >= 0) & (fy < self.ny))
        key = fx[on].astype(np.int64) * self.ny + fy[on].astype(np.int64)
        lo, hi = np.searchsorted(self.keys, key, "left"), np.searchsorted(self.keys, key, "right")
        n = hi - lo
        pi = np.repeat(on, n)
        fi = self.boxes[np.repeat(lo - (np.cumsum(n) - n), n) + np.arange(int(n.sum()))]
        if len(self.wide):
            pi = np.concatenate([pi, np.repeat(np.arange(len(xs)), len(self.wide))])
            fi = np.concatenate([fi, np.tile(self.wide, len(xs))])
        return pi, fi


@dataclass(frozen=True)
class LaneFacts:
    """Where one point is: the lanes containing it (ids, sorted), the chosen lane (None when in no lane),
    in_intersection, on_crosswalk, off_road."""

    lanes: tuple[str, ...]
    lane: str | None
    in_intersection: bool
    on_crosswalk: bool
    off_road: bool


class RoadIndex:
    """One map's polygons, indexed once, for the lane facts of many points (a scenario's frames)."""

    def __init__(self, road: RoadMap) -> None:
        self.road = road
        self.lanes, self.crosswalks, self.intersections, self.drivable = (
            PolygonIndex(road.of_kind(kind), road.packed("polygon", kind))
            for kind in (LANE, CROSSWALK, INTERSECTION, DRIVABLE_AREA))
        self._segments: dict[str, Segments | None] = {}
        self._packed_segments: PackedSegments | None = None
        self._ahead: dict[tuple[float, float, float], LaneFacts] = {}

    def prefetch(self, xs, ys, headings, keys=None) -> None:
        """Decide the facts of many points at once (every entity of a scenario in every frame) and keep them, in
        place of those kept before, for `facts` (or `known`, by the caller's `keys`, one per point) to answer by
        lookup: one vectorised pass instead of one per frame (numpy's per-call cost dominates a frame's few
        dozen points). A point asked for later is looked up by its exact (x, y, heading), or its key; any other
        is decided then, the same way, so the facts never depend on it."""
        xs, ys, hs = (np.asarray(v, dtype=float).reshape(-1) for v in (xs, ys, headings))
        keys = zip(xs.tolist(), ys.tolist(), hs.tolist()) if keys is None else keys
        # each distinct key once (a parked car is the same point in every frame: a third of nuScenes' points)
        at = dict(zip(keys, range(len(xs))))
        rows = np.fromiter(at.values(), dtype=np.int64, count=len(at))
        self._ahead = dict(zip(at, self._decide(xs[rows], ys[rows], hs[rows])))

    def known(self, keys) -> list[LaneFacts | None]:
        """The facts prefetched under these keys; None for a key not prefetched."""
        ahead = self._ahead
        return [ahead.get(k) for k in keys]

    def facts(self, xs, ys, headings) -> list[LaneFacts]:
        """Lane facts of points (map frame) of entities with these headings (degrees CCW from +x, map frame)."""
        xs, ys, hs = (np.asarray(v, dtype=float).reshape(-1) for v in (xs, ys, headings))
        out = self.known(zip(xs.tolist(), ys.tolist(), hs.tolist()))
        todo = [i for i, f in enumerate(out) if f is None]
        if todo:
            for i, f in zip(todo, self._decide(xs[todo], ys[todo], hs[todo])):
                out[i] = f
        return out  # type: ignore[return-value]

    def _decide(self, xs: np.ndarray, ys: np.ndarray, headings: np.ndarray) -> list[LaneFacts]:
        n = len(xs)
        pi, fi = self.lanes.pairs(xs, ys)
        on_cross = self.crosswalks.covered(xs, ys)
        in_inter = self.intersections.covered(xs, ys)
        count = np.bincount(pi, minlength=n)
        # a drivable area decides only off_road, of points in no lane
        in_drive = np.zeros(n, dtype=bool)
        nowhere = np.flatnonzero(count == 0)
        in_drive[nowhere] = self.drivable.covered(xs[nowhere], ys[nowhere])
        first = np.cumsum(count) - count
        feats = self.lanes.features
        # Most points lie in one lane or none: their facts depend only on (that lane, the three flags), so they
        # are decided once per distinct key and shared (LaneFacts is frozen). Points in several lanes take the
        # tie rule, with the direction of every lane at every such point computed in one pass.
        lane = np.full(n, -1, dtype=np.int64)
        one = count == 1
        lane[one] = fi[first[one]]
        flags = in_inter.astype(np.int64) * 4 + on_cross * 2 + in_drive
        code = np.where(count <= 1, (lane + 1) * 8 + flags, -1)
        distinct, which = np.unique(code, return_inverse=True)  # code -1 (several lanes) sorts first
        facts: list[LaneFacts | None] = []
        for c in distinct.tolist():
            k, f = c // 8 - 1, c % 8
            lanes = (feats[k],) if k >= 0 else ()
            facts.append(None if c < 0 else self._facts_of(lanes, lanes[0] if lanes else None, bool(f & 4),
                                                             bool(f & 2), bool(f & 1)))
        out: list[LaneFacts | None] = [facts[j] for j in which.tolist()]
        shared = np.flatnonzero(count > 1)
        if len(shared):
            at = np.flatnonzero(count[pi] > 1)  # the pairs of those points, row-major
            near = self.directions_near(fi[at].tolist(), xs[pi[at]], ys[pi[at]])
            starts = np.searchsorted(pi[at], shared).tolist()
            both: dict[tuple, LaneFacts] = {}  # facts by (lanes, chosen, flags): many points share them
            for i, s, m, f in zip(shared.tolist(), starts, count[shared].tolist(), flags[shared].tolist()):
                idx, dirs, h = fi[at[s:s + m]].tolist(), near[s:s + m], float(headings[i])
                best = min(range(m), key=lambda j: (lane_difference(h, dirs[j]), feats[idx[j]].feature_id))
                key = (tuple(idx), idx[best], f)
                if key not in both:
                    both[key] = self._facts_of(tuple(feats[k] for k in idx), feats[idx[best]], bool(f & 4),
                                               bool(f & 2), bool(f & 1))
                out[i] = both[key]
        return out  # type: ignore[return-value]

    @staticmethod
    def _facts_of(lanes: tuple[MapFeature, ...], chosen: MapFeature | None, in_inter: bool, on_cross: bool,
                  in_drive: bool) -> LaneFacts:
        return LaneFacts(lanes=tuple(sorted(f.feature_id for f in lanes)),
                         lane=chosen.feature_id if chosen is not None else None,
                         in_intersection=in_inter or any(f.is_intersection for f in lanes),
                         on_crosswalk=on_cross, off_road=not lanes and not in_drive)

    def choose_lane(self, lanes: list[MapFeature], x: float, y: float, heading: float) -> MapFeature | None:
        """The tie rule: of the lanes containing a point, the one whose local direction (that of its centre-line
        segment nearest the point) differs least from the heading; equal differences go to the smaller id."""
        if len(lanes) <= 1:
            return lanes[0] if lanes else None

        def key(f: MapFeature) -> tuple[float, str]:
            if f.feature_id not in self._segments:
                self._segments[f.feature_id] = Segments.of(f.line)
            seg = self._segments[f.feature_id]
            return (lane_difference(heading, seg.direction_near(x, y) if seg is not None else None), f.feature_id)

        return min(lanes, key=key)

    def directions_near(self, lanes: list[int], xs: np.ndarray, ys: np.ndarray) -> list[float | None]:
        """Segments.direction_near of lane lanes[j] (an index into self.lanes.features) at (xs[j], ys[j]), for
        many pairs at once: the same float operations on the same values, the first nearest segment of each
        (np.argmin's), so the same directions; None for a lane without a segment."""
        if self._packed_segments is None:
            self._packed_segments = PackedSegments.of_packed(*self.road.packed("line", LANE))
        return self._packed_segments.directions_near(np.asarray(lanes, dtype=np.int64), xs, ys)


@dataclass(frozen=True)
class Segments:
    """The non-degenerate segments of a line, as arrays: starts, vectors, squared lengths."""

    a: np.ndarray
    d: np.ndarray
    length2: np.ndarray

    @classmethod
    def of(cls, line) -> Segments | None:
        p = np.asarray(line, dtype=float).reshape(-1, 2)
        if len(p) < 2:
            return None
        a, d = p[:-1], np.diff(p, axis=0)
        length2 = (d * d).sum(axis=1)
        keep = length2 > 0
        return cls(a[keep], d[keep], length2[keep]) if keep.any() else None

    def nearest(self, x: float, y: float) -> tuple[int, float]:
        """(index of the segment nearest the point, its distance)."""
        t = np.clip(((x - self.a[:, 0]) * self.d[:, 0] + (y - self.a[:, 1]) * self.d[:, 1]) / self.length2, 0, 1)
        gap = np.hypot(self.a[:, 0] + t * self.d[:, 0] - x, self.a[:, 1] + t * self.d[:, 1] - y)
        k = int(np.argmin(gap))
        return k, float(gap[k])

    def direction_near(self, x: float, y: float) -> float:
        """The heading (degrees CCW from +x) of the segment nearest the point."""
        k, _ = self.nearest(x, y)
        return math.degrees(math.atan2(self.d[k, 1], self.d[k, 0])) % 360.0


def lane_difference(heading: float, direction: float | None) -> float:
    """How far a lane's local direction is from a heading (degrees, in [0, 180]); 180 for a lane without one."""
    return 180.0 if direction is None else abs((heading - direction + 180.0) % 360.0 - 180.0)


@dataclass(frozen=True)
class PackedSegments:
    """The Segments of many lines in flat arrays (line j's from start[j], count[j] of them), to find the nearest
    segment of many (line, point) pairs in one pass with Segments.nearest's own arithmetic."""

    a: np.ndarray
    d: np.ndarray
    length2: np.ndarray
    start: np.ndarray
    count: np.ndarray

    @classmethod
    def of(cls, lines: list) -> PackedSegments:
        return cls.of_packed(*packed(lines))

    @classmethod
    def of_packed(cls, xy: np.ndarray, counts: np.ndarray) -> PackedSegments:
        """`of` lines already packed (`packed`'s output, e.g. RoadMap.packed)."""
        a, d = xy[:-1], np.diff(xy, axis=0)
        length2 = (d * d).sum(axis=1)
        line = np.repeat(np.arange(len(counts)), counts)[:-1] if len(xy) else np.zeros(0, dtype=np.int64)
        ends = np.cumsum(counts)
        # a segment runs from a point to the next of the same line, and has a length (Segments.of's `keep`)
        keep = (np.arange(len(a)) + 1 < ends[line]) & (length2 > 0) if len(a) else np.zeros(0, dtype=bool)
        line = line[keep]
        count = np.bincount(line, minlength=len(counts)).astype(np.int64)
        return cls(a[keep], d[keep], length2[keep], np.cumsum(count) - count, count)

    def nearest(self, lines: np.ndarray, xs: np.ndarray, ys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Segments.nearest of line lines[j] at (xs[j], ys[j]) for many pairs at once, with its arithmetic on the
        same values: the row (into a, d, length2) of the first nearest segment (np.argmin's choice) and its
        distance; row -1 (and gap inf) for a line without a segment. Every (pair, segment) is one row of the
        pass, in chunks of at most CHUNK_ROWS rows; a line of more than LONG_LINE segments is not scanned whole
        for each of its points but pruned by blocks (`_pruned`), so a lane of 10^6 segments met by a hundred
        points costs neither a hundred lines' worth of memory nor of time."""
        lines = np.asarray(lines, dtype=np.int64)
        xs, ys = np.asarray(xs, dtype=float).reshape(-1), np.asarray(ys, dtype=float).reshape(-1)
        n = self.count[lines]
        long = n > LONG_LINE
        if not long.any():
            return self._in_rows(self.start[lines], n, xs, ys)
        best, low = np.full(len(lines), -1, dtype=np.int64), np.full(len(lines), np.inf)
        short = np.flatnonzero(~long)
        best[short], low[short] = self._in_rows(self.start[lines[short]], n[short], xs[short], ys[short])
        for line in np.unique(lines[long]).tolist():
            mine = np.flatnonzero(lines == line)
            best[mine], low[mine] = self._pruned(line, xs[mine], ys[mine])
        return best, low

    def _in_rows(self, starts: np.ndarray, n: np.ndarray, xs: np.ndarray, ys: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
        """`nearest` over the n[j] rows from starts[j] for point j (a line's segments, or a block of them), in
        chunks of at most CHUNK_ROWS rows."""
        parts = [self._rows_nearest(starts[c], n[c], xs[c], ys[c]) for c in row_chunks(n)]
        if len(parts) == 1:
            return parts[0]
        return np.concatenate([b for b, _ in parts]), np.concatenate([g for _, g in parts])

    def _rows_nearest(self, starts: np.ndarray, n: np.ndarray, xs: np.ndarray, ys: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
        pair = np.repeat(np.arange(len(n)), n)
        row = np.repeat(starts - (np.cumsum(n) - n), n) + np.arange(n.sum())
        x, y = xs[pair], ys[pair]
        a0, a1, d0, d1 = self.a[row, 0], self.a[row, 1], self.d[row, 0], self.d[row, 1]
        t = np.clip(((x - a0) * d0 + (y - a1) * d1) / self.length2[row], 0, 1)
        gap = np.hypot(a0 + t * d0 - x, a1 + t * d1 - y)
        has = n > 0
        first = np.cumsum(n) - n
        low = np.full(len(n), np.inf)
        low[has] = np.minimum.reduceat(gap, first[has]) if has.any() else low[has]
        # the first row of each pair that reaches its minimum (np.argmin's choice)
        at = np.flatnonzero(gap == low[pair])
        pairs_at, first_at = np.unique(pair[at], return_index=True)
        best = np.full(len(n), -1, dtype=np.int64)
        best[pairs_at] = row[at[first_at]]
        for k in np.flatnonzero(has & (best < 0)):  # NaN gaps (coordinates near overflow): argmin itself
            mine = pair == k
            j = int(np.argmin(gap[mine]))
            best[k], low[k] = row[mine][j], gap[mine][j]
        return best, low

    def _pruned(self, line: int, xs: np.ndarray, ys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """`nearest` of one long line at many points, exactly, without every segment for every point: the
        line's segments in blocks of about sqrt(count) (at least BLOCK_MIN), each with the box of its segments;
        per point, the least gap in the block whose box is nearest bounds the answer (upper), and only blocks
        whose box lies within upper (plus a margin far above the rounding of either computation) can hold a
        segment whose computed gap reaches the least one; those blocks' rows are decided as `_rows_nearest`
        decides them, the first least gap over them, block after block, is np.argmin's. Points or lines beyond
        PRUNE_SCALE (where products could overflow) are scanned whole."""
        s0, m = int(self.start[line]), int(self.count[line])
        a, d = self.a[s0:s0 + m], self.d[s0:s0 + m]
        e = a + d
        scale = float(max(np.abs(a).max(), np.abs(e).max()))
        best, low = np.full(len(xs), -1, dtype=np.int64), np.full(len(xs), np.inf)
        ok = np.isfinite(xs) & np.isfinite(ys) & (np.abs(xs) < PRUNE_SCALE) & (np.abs(ys) < PRUNE_SCALE)
        if not scale < PRUNE_SCALE:
            ok[:] = False
        whole = np.flatnonzero(~ok)
        if len(whole):
            best[whole], low[whole] = self._in_rows(np.full(len(whole), s0), np.full(len(whole), m), xs[whole],
                                                    ys[whole])
        size = max(BLOCK_MIN, math.isqrt(m))
        first = np.arange(0, m, size)
        rows = np.diff(np.append(first, m))
        lo = np.minimum.reduceat(np.minimum(a, e), first, axis=0)
        hi = np.maximum.reduceat(np.maximum(a, e), first, axis=0)
        points = np.flatnonzero(ok)
        step = max(1, CHUNK_ROWS // len(first))
        for c in range(0, len(points), step):
            at = points[c:c + step]
            x, y = xs[at], ys[at]
            dx = np.maximum(np.maximum(lo[:, 0] - x[:, None], x[:, None] - hi[:, 0]), 0.0)
            dy = np.maximum(np.maximum(lo[:, 1] - y[:, None], y[:, None] - hi[:, 1]), 0.0)
            box_gap = np.hypot(dx, dy)  # points x blocks: at most a lower bound of the gap of any segment in it
            k = np.argmin(box_gap, axis=1)
            _, upper = self._in_rows(s0 + first[k], rows[k], x, y)
            margin = 1e-12 * (1.0 + scale + np.abs(x) + np.abs(y) + upper)
            near = box_gap <= (upper + margin)[:, None]
            near[np.arange(len(at)), k] = True
            p, b = np.nonzero(near)  # row-major: each point's blocks ascending
            row, gap = self._in_rows(s0 + first[b], rows[b], x[p], y[p])
            order = np.lexsort((row, gap, p))  # each point's least gap, its first row
            p, row, gap = p[order], row[order], gap[order]
            head = np.flatnonzero(np.r_[True, p[1:] != p[:-1]])
            best[at[p[head]]], low[at[p[head]]] = row[head], gap[head]
        return best, low

    def directions_near(self, lines: np.ndarray, xs: np.ndarray, ys: np.ndarray) -> list[float | None]:
        best, _ = self.nearest(lines, xs, ys)
        d = self.d
        return [None if j < 0 else math.degrees(math.atan2(d[j, 1], d[j, 0])) % 360.0 for j in best.tolist()]


def local_direction(f: MapFeature, x: float, y: float) -> float | None:
    """The heading (degrees CCW from +x) of the segment of f's line nearest (x, y); None without a segment."""
    seg = Segments.of(f.line)
    return seg.direction_near(x, y) if seg is not None else None


class Banded:
    """One closed polygon for `contains` at one point at a time, answered exactly as `contains` answers it but
    over the edges of one horizontal band: the crossing test and the on-edge test only look at edges whose
    y-range holds the point's y, and (y - y0) / h is monotonic in floats, so every such edge is filed under the
    point's band. A drivable area of 500 edges then costs a few dozen edge tests instead of 500."""

    def __init__(self, ring: tuple[tuple[float, float], ...]) -> None:
        self.ring = ring
        xs, ys = [p[0] for p in ring], [p[1] for p in ring]
        self.box = (min(xs), min(ys), max(xs), max(ys))
        n = len(ring)
        self.n = max(1, min(BANDS, n // 4))
        self.h = (self.box[3] - self.box[1]) / self.n or 1.0
        self.bands: list[list[tuple[float, float, float, float]]] = [[] for _ in range(self.n)]
        for i in range(n):
            (ax, ay), (bx, by) = ring[i], ring[(i + 1) % n]
            for b in range(self._band(min(ay, by)), self._band(max(ay, by)) + 1):
                self.bands[b].append((ax, ay, bx, by))

    def _band(self, y: float) -> int:
        return min(self.n - 1, max(0, int((y - self.box[1]) / self.h)))

    def contains(self, px: float, py: float) -> bool:
        x0, y0, x1, y1 = self.box
        return x0 <= px <= x1 and y0 <= py <= y1 and covers(self.bands[self._band(py)], px, py)


CELL = 10.0  # metres: the side of a Cells cell


class Cells:
    """Polygons filed by the square cells (CELL metres) their bounding boxes touch, so that a point meets only the
    few whose boxes may hold it. A point's cell is floor(x / CELL), monotonic in floats like the boxes' cells, so a
    polygon whose box holds the point is always filed under the point's cell."""

    def __init__(self, items: list[tuple[Banded, MapFeature]]) -> None:
        self.cells: dict[tuple[int, int], list[tuple[Banded, MapFeature]]] = {}
        for ring, f in items:
            x0, y0, x1, y1 = ring.box
            for i in range(math.floor(x0 / CELL), math.floor(x1 / CELL) + 1):
                for j in range(math.floor(y0 / CELL), math.floor(y1 / CELL) + 1):
                    self.cells.setdefault((i, j), []).append((ring, f))

    def near(self, x: float, y: float) -> list[tuple[Banded, MapFeature]]:
        return self.cells.get((math.floor(x / CELL), math.floor(y / CELL)), [])
