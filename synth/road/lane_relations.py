"""Relations between the lanes of one map (docs/dsl.md, "Lanes"): what the LANE part's witness clauses mean.

Every relation is a property of the map alone, decided once per lane and cached (LaneGraph); an entity's side of
it is its chosen lane (synth.road.lane_facts: of the lanes containing its centre, the one whose direction there is
closest to its heading, ties by id), which extraction decided exactly.

- **Continues straight.** Lane B continues lane A when the map links them (B is a successor of A, or A a
  predecessor of B) and B's direction (the chord of its centre line) is within CHAIN_ANGLE of A's direction at its
  end (its last centre-line segment).
- **Lane chain** of L: L, and every lane reached from L by continuing straight forward only (or backward only),
  where the lanes passed between L and it are at most CHAIN_LENGTH long together (centre-line lengths). The
  relation is symmetric: a forward walk from A to B is the backward walk from B to A.
- **Left / right neighbour** of L: the map's left (right) neighbour of L when it runs the same way (its centre
  line's segment nearest L's halfway point points within 90 degrees of L's there); none otherwise.
- **Oncoming lane** of L: from L, walk same-direction neighbours to the leftmost and to the rightmost lane of its
  road. A map neighbour of either that runs the opposite way (more than 90 degrees apart) is an oncoming
  candidate; so is every lane containing the probe point one lane width beyond that lane's side (halfway along
  its centre line, square to it, as synth.road.lane_geometry probes neighbours) whose direction there is within
  NEIGHBOUR_ANGLE of the reverse. The oncoming lane is the candidate whose centre line is nearest its probe point
  (ties: the smaller id); none without candidates. Both sides are probed: traffic keeps left in some maps.
- **Relations of a target's lane T with a reference's lane R** (codes, in this order; the first that holds):
  SAME: T on R's chain; LEFT: T on the chain of R's left neighbour; RIGHT: the same on the right; ONCOMING: T on
  the chain of R's oncoming lane.

Geometry here (lengths, directions, the probe) is float arithmetic on the map's coordinates, deterministic, and
the same function serves synthesis, the checker and the queries: lane relations are facts of the map, as the
lane-graph links the source gives are.
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass, field

import numpy as np

from synth.road.lane_facts import PolygonIndex, Segments
from synth.road.lane_geometry import NEIGHBOUR_ANGLE, halfway, width_at
from synth.road.roadmap import CROSSWALK, DRIVABLE_AREA, INTERSECTION, LANE, MapFeature, RoadMap

CHAIN_ANGLE = 30.0  # degrees: a successor turning more than this does not continue the lane straight
CHAIN_LENGTH = 100.0  # metres of lanes between two lanes of one chain, at most
SAME, LEFT, RIGHT, ONCOMING = 0, 1, 2, 3
RELATION_NAMES = ("same lane", "lane left", "lane right", "oncoming lane")  # index = code


def _angle(a: float, b: float) -> float:
    """The absolute difference of two headings (degrees), in [0, 180]."""
    return abs((a - b + 180.0) % 360.0 - 180.0)


@dataclass(frozen=True)
class LaneGraph:
    """One map's lanes and the relations between them, each computed on first use and cached."""

    road: RoadMap
    _cache: dict = field(default_factory=dict, repr=False, compare=False)

    # ------------------------------------------------------------------------------- per lane geometry
    def lane(self, lane_id: str) -> MapFeature | None:
        f = self.road[lane_id] if lane_id in self.road else None
        return f if f is not None and f.kind == LANE else None

    def _memo(self, key: tuple, make):
        if key not in self._cache:
            self._cache[key] = make()
        return self._cache[key]

    def segments(self, lane_id: str) -> Segments | None:
        return self._memo(("segments", lane_id), lambda: Segments.of(self.road[lane_id].line))

    def length(self, lane_id: str) -> float:
        """The length of a lane's centre line (metres)."""
        seg = self.segments(lane_id)
        return 0.0 if seg is None else float(np.sqrt(seg.length2).sum())

    def end_direction(self, lane_id: str) -> float | None:
        """The heading (degrees CCW from +x) of a lane's last non-degenerate centre-line segment."""
        seg = self.segments(lane_id)
        return None if seg is None else math.degrees(math.atan2(seg.d[-1, 1], seg.d[-1, 0])) % 360.0

    def continues(self, a: str, b: str) -> bool:
        """Does lane b continue lane a straight (linked, and turning at most CHAIN_ANGLE)?"""
        fa, fb = self.lane(a), self.lane(b)
        if fa is None or fb is None or a == b or (b not in fa.successors and a not in fb.predecessors):
            return False
        end, chord = self.end_direction(a), fb.direction
        return end is not None and chord is not None and _angle(end, chord) <= CHAIN_ANGLE

    def successors(self, lane_id: str) -> list[str]:
        """The lanes linked after a lane by either side's links, sorted (a replay's route through the lanes)."""
        return self._linked(lane_id, forward=True) if self.lane(lane_id) is not None else []

    def _linked(self, lane_id: str, forward: bool) -> list[str]:
        """The lanes linked after (forward) or before a lane, by either side's links (a source may give a link
        one way only), sorted."""
        def reverse() -> dict[tuple[str, bool], set[str]]:
            out: dict[tuple[str, bool], set[str]] = {}
            for g in self.road.lanes:
                for p in g.predecessors:
                    out.setdefault((p, True), set()).add(g.feature_id)
                for s in g.successors:
                    out.setdefault((s, False), set()).add(g.feature_id)
            return out

        f = self.road[lane_id]
        given = set(f.successors if forward else f.predecessors)
        return sorted(given | self._memo(("reverse",), reverse).get((lane_id, forward), set()))

    # ------------------------------------------------------------------------------- chains
    def chain(self, lane_id: str | None) -> frozenset[str]:
        """The lane chain of a lane (empty for None or an id that is no lane of the map)."""
        if lane_id is None or self.lane(lane_id) is None:
            return frozenset()
        return self._memo(("chain", lane_id), lambda: frozenset(
            self._walk(lane_id, forward=True) | self._walk(lane_id, forward=False)))

    def _walk(self, start: str, forward: bool) -> set[str]:
        """start and the lanes reached by continuing straight one way with at most CHAIN_LENGTH between (the
        least length over all walks: Dijkstra on the lanes passed)."""
        best = {start: 0.0}
        heap = [(0.0, start)]
        while heap:
            gap, here = heapq.heappop(heap)
            if gap > best.get(here, math.inf):
                continue
            passed = gap + (self.length(here) if here != start else 0.0)
            for nxt in self._linked(here, forward):
                ok = self.continues(here, nxt) if forward else self.continues(nxt, here)
                if ok and nxt != start and passed <= CHAIN_LENGTH and passed < best.get(nxt, math.inf):
                    best[nxt] = passed
                    heapq.heappush(heap, (passed, nxt))
        return set(best)

    # ------------------------------------------------------------------------------- neighbours
    def _halfway(self, lane_id: str) -> tuple[float, float, float, float] | None:
        return self._memo(("halfway", lane_id), lambda: halfway(self.road[lane_id].line))

    def _direction_at(self, lane_id: str, x: float, y: float) -> tuple[float, float] | None:
        """The unit direction of the segment of a lane's centre line nearest (x, y)."""
        seg = self.segments(lane_id)
        if seg is None:
            return None
        k, _ = seg.nearest(x, y)
        n = math.sqrt(seg.length2[k])
        return (float(seg.d[k, 0] / n), float(seg.d[k, 1] / n))

    def _agreement(self, lane_id: str, other: str) -> float | None:
        """cos of the angle between a lane's direction at its halfway point and other's direction nearest it."""
        mid = self._halfway(lane_id)
        d = self._direction_at(other, mid[0], mid[1]) if mid is not None else None
        return None if d is None else mid[2] * d[0] + mid[3] * d[1]

    def neighbour(self, lane_id: str | None, side: str) -> str | None:
        """The map's left / right neighbour of a lane when it runs the same way, else None."""
        return self._memo(("neighbour", lane_id, side), lambda: self._neighbour(lane_id, side))

    def _neighbour(self, lane_id: str | None, side: str) -> str | None:
        f = self.lane(lane_id) if lane_id is not None else None
        other = getattr(f, side) if f is not None else None
        if other is None or self.lane(other) is None:
            return None
        agree = self._agreement(lane_id, other)
        return other if agree is not None and agree > 0 else None

    def _outermost(self, lane_id: str, side: str) -> str:
        seen = {lane_id}
        while (nxt := self.neighbour(lane_id, side)) is not None and nxt not in seen:
            seen.add(nxt)
            lane_id = nxt
        return lane_id

    def _lane_index(self) -> PolygonIndex:
        return self._memo(("index",), lambda: PolygonIndex(self.road.lanes, self.road.packed("polygon", LANE)))

    def oncoming(self, lane_id: str | None) -> str | None:
        """The oncoming lane of a lane (see the module's rule), or None."""
        if lane_id is None or self.lane(lane_id) is None:
            return None
        return self._memo(("oncoming", lane_id), lambda: self._find_oncoming(lane_id))

    def _find_oncoming(self, lane_id: str) -> str | None:
        cos_limit = math.cos(math.radians(NEIGHBOUR_ANGLE))
        best: tuple[float, str] | None = None
        for side, sign in (("left", 1.0), ("right", -1.0)):
            edge = self._outermost(lane_id, side)
            mid = self._halfway(edge)
            if mid is None:
                continue
            x, y, ux, uy = mid
            w = width_at(self.road[edge], x, y)
            qx, qy = x - sign * w * uy, y + sign * w * ux
            linked = getattr(self.road[edge], side)
            candidates = []
            if linked is not None and self.lane(linked) is not None:
                agree = self._agreement(edge, linked)
                if agree is not None and agree < 0:
                    candidates.append(linked)
            if w > 0:
                for k in self._lane_index().containing(np.array([qx]), np.array([qy]))[0]:
                    other = self.road.lanes[k].feature_id
                    d = self._direction_at(other, qx, qy)
                    if d is not None and d[0] * ux + d[1] * uy <= -cos_limit:
                        candidates.append(other)
            for other in candidates:
                if other == lane_id:
                    continue
                gap = self.segments(other).nearest(qx, qy)[1]
                if best is None or (gap, other) < best:
                    best = (gap, other)
        return None if best is None else best[1]

    # ------------------------------------------------------------------------------- the part's relations
    def related(self, lane_id: str | None, side: str) -> frozenset[str]:
        """The lanes a target's lane must be in for a relation with a reference in `lane_id`: side is one of
        same, left, right, oncoming."""
        if side == "same":
            return self.chain(lane_id)
        if side == "oncoming":
            return self.chain(self.oncoming(lane_id))
        return self.chain(self.neighbour(lane_id, side))

    def relation(self, ref_lane: str | None, lane: str | None) -> int | None:
        """The first code (SAME, LEFT, RIGHT, ONCOMING) whose lanes hold `lane` for a reference in ref_lane."""
        if ref_lane is None or lane is None:
            return None
        return next((code for code, side in enumerate(SIDES) if lane in self.related(ref_lane, side)), None)


SIDES = ("same", "left", "right", "oncoming")  # index = code


# ------------------------------------------------------------------------------------------------ robust places
# Robust synthesis (docs/dsl.md): an entity may be anywhere within its position bound of its recorded centre and
# face anywhere within its heading bound. Where it may then be on the road is decided on GEOS's float distances
# with a slack that only ever makes the answer more cautious (a lane it might be in is never missed, a place it
# is claimed to be surely in has the slack to spare): REACH_SLACK metres, beyond any float error at map scale.
REACH_SLACK = 1e-6


@dataclass(frozen=True)
class Places:
    """Where a perturbed entity may be: every lane its chosen lane may become (`lanes`), whether it may be in no
    lane (`laneless`), and the lane facts that hold wherever it is (`sure`: in intersection, on crosswalk, off
    road, off lane)."""

    lanes: frozenset[str]
    laneless: bool
    sure: frozenset[str]


def _union(features) -> object:
    import shapely

    return shapely.union_all([shapely.Polygon(f.polygon) for f in features]) if features else None


def places(graph: LaneGraph, x: float, y: float, lane: str | None, lanes: tuple[str, ...], facts: frozenset[str],
           radius: float, heading_free: bool) -> Places:
    """The Places of an entity at (x, y) (the road's frame) with lane facts (`lane`, `lanes`, `facts`: the flags
    that hold) whose centre may move up to `radius` metres and whose heading may turn (`heading_free`)."""
    if radius == 0.0:
        # Only the heading moves: the lanes containing the centre stay, any of them may be the chosen one.
        return Places(frozenset(lanes) if heading_free else frozenset({lane} - {None}), lane is None, facts)
    import shapely

    def memo(key, make):
        return graph._memo(("union", key), make)

    road = graph.road
    point = shapely.Point(x, y)
    reach = radius + REACH_SLACK * (1.0 + radius)
    near = frozenset(f.feature_id for f in road.lanes if shapely.Polygon(f.polygon).distance(point) <= reach)
    all_lanes = memo("lanes", lambda: _union(road.lanes))
    drivable = memo("drivable", lambda: _union(road.lanes + road.of_kind(DRIVABLE_AREA)))
    crossing = memo("crosswalk", lambda: _union(road.of_kind(CROSSWALK)))
    inter = memo("intersection", lambda: _union(road.of_kind(INTERSECTION) + tuple(
        f for f in road.lanes if f.is_intersection)))

    def surely_in(area) -> bool:
        return area is not None and area.contains(point) and area.boundary.distance(point) > reach

    def clear_of(area) -> bool:
        return area is None or area.distance(point) > reach

    sure = set()
    if surely_in(inter):
        sure.add("intersection")
    if surely_in(crossing):
        sure.add("crosswalk")
    if clear_of(drivable):
        sure.add("off road")
    if clear_of(all_lanes) and surely_in(memo("drivable only", lambda: _union(road.of_kind(DRIVABLE_AREA)))):
        sure.add("off lane")
    return Places(near, not surely_in(all_lanes), frozenset(sure))
