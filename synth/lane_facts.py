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

from synth.roadmap import CROSSWALK, DRIVABLE_AREA, INTERSECTION, LANE, MapFeature, RoadMap

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


class PolygonIndex:
    """The polygons of some features as flat arrays, to test many points at once with the exact answer of
    `contains`: bounding boxes first, then every edge of the candidates in float with the error bound, and
    `contains` itself for a (point, polygon) pair with an edge the float cannot decide."""

    def __init__(self, features: tuple[MapFeature, ...]) -> None:
        self.features = features
        rings = [np.asarray(f.polygon, dtype=float).reshape(-1, 2) for f in features]
        self.box = np.array([[r[:, 0].min(), r[:, 1].min(), r[:, 0].max(), r[:, 1].max()] for r in rings]) \
            if rings else np.zeros((0, 4))
        counts = np.array([len(r) for r in rings], dtype=np.int64)
        self.start = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64) if rings else counts
        self.count = counts
        a = np.concatenate(rings) if rings else np.zeros((0, 2))
        b = np.concatenate([np.roll(r, -1, axis=0) for r in rings]) if rings else np.zeros((0, 2))
        self.ax, self.ay, self.bx, self.by = a[:, 0], a[:, 1], b[:, 0], b[:, 1]

    def containing(self, xs: np.ndarray, ys: np.ndarray) -> list[list[int]]:
        """For each point, the indices (into features, ascending) of the polygons that contain it."""
        xs, ys = np.asarray(xs, dtype=float), np.asarray(ys, dtype=float)
        out: list[list[int]] = [[] for _ in range(len(xs))]
        if not len(self.features) or not len(xs):
            return out
        b = self.box
        inbox = (b[None, :, 0] <= xs[:, None]) & (xs[:, None] <= b[None, :, 2]) & \
                (b[None, :, 1] <= ys[:, None]) & (ys[:, None] <= b[None, :, 3])
        pi, fi = np.nonzero(inbox)
        if not len(pi):
            return out
        # Every edge of every candidate pair: pair k owns edges start[f] .. start[f] + count[f].
        n = self.count[fi]
        pair = np.repeat(np.arange(len(pi)), n)
        edge = np.repeat(self.start[fi] - np.concatenate([[0], np.cumsum(n)[:-1]]), n) + np.arange(n.sum())
        px, py = xs[pi][pair], ys[pi][pair]
        ax, ay, bx, by = self.ax[edge], self.ay[edge], self.bx[edge], self.by[edge]
        detleft = (bx - ax) * (py - ay)
        detright = (by - ay) * (px - ax)
        det = detleft - detright
        sure = np.abs(det) > CCW_ERRBOUND * (np.abs(detleft) + np.abs(detright))
        straddle = (ay > py) != (by > py)
        crossing = straddle & np.where(by > ay, det > 0, det < 0)
        # An edge whose sign the float cannot prove may be one p lies on, or one it crosses: decide exactly.
        doubtful = np.zeros(len(pi), dtype=bool)
        np.logical_or.at(doubtful, pair, ~sure)
        inside = np.bincount(pair, weights=crossing & sure, minlength=len(pi)).astype(np.int64) % 2 == 1
        for k in np.flatnonzero(doubtful):
            inside[k] = contains(self.features[int(fi[k])].polygon, float(xs[pi[k]]), float(ys[pi[k]]))
        for k in np.flatnonzero(inside):  # pairs in row-major order: each point's polygons ascending
            out[int(pi[k])].append(int(fi[k]))
        return out


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
        self.lanes = PolygonIndex(road.of_kind(LANE))
        self.crosswalks = PolygonIndex(road.of_kind(CROSSWALK))
        self.intersections = PolygonIndex(road.of_kind(INTERSECTION))
        self.drivable = PolygonIndex(road.of_kind(DRIVABLE_AREA))
        self._segments: dict[str, Segments | None] = {}

    def facts(self, xs, ys, headings) -> list[LaneFacts]:
        """Lane facts of points (map frame) of entities with these headings (degrees CCW from +x, map frame)."""
        xs, ys = np.asarray(xs, dtype=float), np.asarray(ys, dtype=float)
        in_lanes = self.lanes.containing(xs, ys)
        on_cross = self.crosswalks.containing(xs, ys)
        in_inter = self.intersections.containing(xs, ys)
        in_drive = self.drivable.containing(xs, ys)
        out = []
        for i, idx in enumerate(in_lanes):
            lanes = [self.lanes.features[k] for k in idx]
            chosen = self.choose_lane(lanes, float(xs[i]), float(ys[i]), float(headings[i]))
            out.append(LaneFacts(
                lanes=tuple(sorted(f.feature_id for f in lanes)),
                lane=chosen.feature_id if chosen is not None else None,
                in_intersection=bool(in_inter[i]) or any(f.is_intersection for f in lanes),
                on_crosswalk=bool(on_cross[i]),
                off_road=not lanes and not in_drive[i],
            ))
        return out

    def choose_lane(self, lanes: list[MapFeature], x: float, y: float, heading: float) -> MapFeature | None:
        """The tie rule: of the lanes containing a point, the one whose local direction (that of its centre-line
        segment nearest the point) differs least from the heading; equal differences go to the smaller id."""
        if len(lanes) <= 1:
            return lanes[0] if lanes else None

        def key(f: MapFeature) -> tuple[float, str]:
            if f.feature_id not in self._segments:
                self._segments[f.feature_id] = Segments.of(f.line)
            seg = self._segments[f.feature_id]
            d = seg.direction_near(x, y) if seg is not None else None
            diff = 180.0 if d is None else abs((heading - d + 180.0) % 360.0 - 180.0)
            return (diff, f.feature_id)

        return min(lanes, key=key)


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


def local_direction(f: MapFeature, x: float, y: float) -> float | None:
    """The heading (degrees CCW from +x) of the segment of f's line nearest (x, y); None without a segment."""
    seg = Segments.of(f.line)
    return seg.direction_near(x, y) if seg is not None else None


BANDS = 64  # at most, per polygon (about one per four edges)


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
