"""An independent reference for the LANE part (docs/dsl.md, "Lanes"): lane relations by enumerating walks and by
GEOS geometry, the optimum by dynamic programming over subsets with the lane part's weights; and random roads.

It shares nothing with synth.road.lane_relations, synth.parts or synth.search: chains are every simple walk spelled
out (not Dijkstra), directions come from shapely's project / interpolate, probe containment from GEOS's covers.
"""

from __future__ import annotations

import math
import random
from dataclasses import replace

import shapely

from synth.config import SynthConfig
from synth.road.lane_facts import RoadIndex
from synth.road.roadmap import MapFeature, RoadMap
from synth.scene import Entity, Scene, make_scene
from tests.support.bruteforce import witnesses

CHAIN_ANGLE, CHAIN_LENGTH, PROBE_ANGLE = 30.0, 100.0, 30.0


def _heading(dx: float, dy: float) -> float:
    return math.degrees(math.atan2(dy, dx)) % 360.0


def _diff(a: float, b: float) -> float:
    d = abs(a - b) % 360.0
    return min(d, 360.0 - d)


def _segments(line):
    return [(a, b) for a, b in zip(line, line[1:]) if a != b]


def _direction_near(line, x: float, y: float) -> tuple[float, float]:
    """Unit direction of the segment of `line` nearest (x, y) (the first such, as a scan finds it)."""
    best = None
    for a, b in _segments(line):
        d = shapely.LineString([a, b]).distance(shapely.Point(x, y))
        if best is None or d < best[0]:
            best = (d, a, b)
    _, a, b = best
    n = math.hypot(b[0] - a[0], b[1] - a[1])
    return ((b[0] - a[0]) / n, (b[1] - a[1]) / n)


class BruteLanes:
    """The lane relations of one road, each from its definition."""

    def __init__(self, road: RoadMap):
        self.road = road
        self.lanes = {f.feature_id: f for f in road.lanes}

    def after(self, a: str) -> set[str]:
        return set(self.lanes[a].successors) | {g for g, f in self.lanes.items() if a in f.predecessors}

    def straight(self, a: str, b: str) -> bool:
        fa, fb = self.lanes[a], self.lanes[b]
        (p, q) = _segments(fa.line)[-1]
        end = _heading(q[0] - p[0], q[1] - p[1])
        chord = (fb.line[0], fb.line[-1])
        if chord[0] == chord[1]:
            return False
        return _diff(end, _heading(chord[1][0] - chord[0][0], chord[1][1] - chord[0][1])) <= CHAIN_ANGLE

    def length(self, a: str) -> float:
        return shapely.LineString(self.lanes[a].line).length

    def chain(self, lane: str | None) -> set[str]:
        if lane is None:
            return set()
        out = {lane}
        for forward in (True, False):
            self._walk([lane], 0.0, forward, out)
        return out

    def _walk(self, path: list[str], between: float, forward: bool, out: set[str]) -> None:
        """Every simple walk continuing straight one way, `between` metres of lanes passed so far."""
        here = path[-1]
        nxt = self.after(here) if forward else {g for g in self.lanes if here in self.after(g)}
        for n in nxt:
            if n in path or not (self.straight(here, n) if forward else self.straight(n, here)):
                continue
            passed = between + (self.length(here) if len(path) > 1 else 0.0)
            if passed <= CHAIN_LENGTH + 1e-9:
                out.add(n)
                self._walk(path + [n], passed, forward, out)

    def _halfway(self, lane: str):
        line = shapely.LineString(self.lanes[lane].line)
        mid = line.interpolate(0.5, normalized=True)
        return mid.x, mid.y, _direction_near(self.lanes[lane].line, mid.x, mid.y)

    def same_way(self, lane: str, other: str) -> float:
        x, y, (ux, uy) = self._halfway(lane)
        dx, dy = _direction_near(self.lanes[other].line, x, y)
        return ux * dx + uy * dy

    def neighbour(self, lane: str | None, side: str) -> str | None:
        other = getattr(self.lanes[lane], side) if lane is not None else None
        return other if other is not None and self.same_way(lane, other) > 0 else None

    def oncoming(self, lane: str | None) -> str | None:
        if lane is None:
            return None
        found = []
        for side, sign in (("left", 1.0), ("right", -1.0)):
            edge, seen = lane, {lane}
            while (n := self.neighbour(edge, side)) is not None and n not in seen:
                edge = n
                seen.add(n)
            x, y, (ux, uy) = self._halfway(edge)
            w = 2 * shapely.Polygon(self.lanes[edge].polygon).exterior.distance(shapely.Point(x, y))
            qx, qy = x - sign * w * uy, y + sign * w * ux
            cands = []
            linked = getattr(self.lanes[edge], side)
            if linked is not None and self.same_way(edge, linked) < 0:
                cands.append(linked)
            for g, f in self.lanes.items():
                if w > 0 and shapely.Polygon(f.polygon).covers(shapely.Point(qx, qy)):
                    dx, dy = _direction_near(f.line, qx, qy)
                    if dx * ux + dy * uy <= -math.cos(math.radians(PROBE_ANGLE)):
                        cands.append(g)
            for g in cands:
                if g != lane:
                    found.append((shapely.LineString(self.lanes[g].line).distance(shapely.Point(qx, qy)), g))
        return min(found)[1] if found else None

    def related(self, ref_lane: str | None, side: str) -> set[str]:
        if ref_lane is None:
            return set()
        target = {"same": ref_lane, "left": self.neighbour(ref_lane, "left"),
                  "right": self.neighbour(ref_lane, "right"), "oncoming": self.oncoming(ref_lane)}[side]
        return self.chain(target)


SIDES = ("same", "left", "right", "oncoming")


def lane_fallback_cost(e: Entity) -> int:
    """1 if a cost-1 lane fact holds of e, else 2 (its lane by id)."""
    off_lane = not e.lanes and not e.off_road
    return 1 if (e.in_intersection or e.on_crosswalk or e.off_road or off_lane) else 2


def lane_optimal_cost(scene: Scene, config: SynthConfig) -> int:
    """The optimum over position, heading and lane, by DP over subsets (entities up to ~12)."""
    pos, head = witnesses(scene, config)
    brute = BruteLanes(scene.road)
    others = scene.others
    refs = [(-1, scene.ego)] + list(enumerate(others))
    lane_w = [{j for j, r in refs if j != i and e.lane is not None and r.lane is not None
               and any(e.lane in brute.related(r.lane, s) for s in SIDES)} for i, e in enumerate(others)]
    weight = [lane_fallback_cost(e) for e in others]
    n = len(others)

    def c(e: int, declared: int) -> int:
        avail = {-1} | {r for r in range(n) if declared >> r & 1}
        return (not pos[e] & avail) + (not head[e] & avail) + (0 if lane_w[e] & avail else weight[e])

    best = [0] * (1 << n)
    for s in range(1, 1 << n):
        best[s] = min(best[s & ~(1 << e)] + c(e, s & ~(1 << e)) for e in range(n) if s >> e & 1)
    return best[-1]


# ------------------------------------------------------------------------------------------------ random roads


def _rect(x0: float, x1: float, y0: float, y1: float):
    return ((x0, y0), (x1, y0), (x1, y1), (x0, y1))


def random_road(rng: random.Random) -> RoadMap:
    """A two-way road along y in the scene's frame (+x right, +y forward): 1-2 lanes each way, 3.5 m wide, cut
    into segments at random places (linked as successors), a right turn off the last northbound segment, an
    intersection, a crosswalk and a drivable area wider than the lanes; opposite lanes are linked as neighbours
    half the time (as Argoverse 2 does)."""
    w, per_way = 3.5, rng.choice([1, 2])
    cuts = sorted(rng.sample(range(-30, 40, 5), 2))
    spans = list(zip([-50.0] + [float(c) for c in cuts], [float(c) for c in cuts] + [60.0]))
    feats: list[MapFeature] = []
    ids = {}
    for way in ("n", "s"):
        for k in range(per_way):
            for j in range(len(spans)):
                ids[way, k, j] = f"{way}{k}_{j}"
    for way, sign in (("n", 1.0), ("s", -1.0)):
        for k in range(per_way):
            x0, x1 = (k * w, (k + 1) * w) if sign > 0 else (-(k + 1) * w, -k * w)
            xc = (x0 + x1) / 2
            for j, (y0, y1) in enumerate(spans):
                line = ((xc, y0), (xc, (y0 + y1) / 2), (xc, y1)) if sign > 0 else ((xc, y1), (xc, (y0 + y1) / 2),
                                                                                     (xc, y0))
                nxt = j + 1 if sign > 0 else j - 1
                succ = (ids[way, k, nxt],) if 0 <= nxt < len(spans) else ()
                inner = ids["s" if sign > 0 else "n", 0, j] if k == 0 and rng.random() < 0.5 else None
                left = ids[way, k - 1, j] if k > 0 else inner
                right = ids[way, k + 1, j] if k + 1 < per_way else None
                feats.append(MapFeature("m", ids[way, k, j], "lane", _rect(x0, x1, y0, y1), line, left=left,
                                        right=right, successors=succ))
    # a right turn off the outer northbound lane's last segment, as an intersection lane
    k, j = per_way - 1, len(spans) - 1
    x1 = per_way * w
    turn = ((x1 - w / 2, 60.0), (x1 + 2, 64.0), (x1 + 8, 66.25))
    feats.append(MapFeature("m", "turn", "lane", ((x1 - w, 60.0), (x1, 60.0), (x1 + 8, 64.5), (x1 + 8, 68.0),
                                                   (x1 - w, 62.0)), turn, predecessors=(ids["n", k, j],),
                            is_intersection=True))
    iy = rng.uniform(-20, 30)
    feats.append(MapFeature("m", "x1", "intersection", _rect(-per_way * w, per_way * w, iy, iy + 8)))
    cy = rng.uniform(-40, 40)
    feats.append(MapFeature("m", "c1", "crosswalk", _rect(-per_way * w - 2, per_way * w + 2, cy, cy + 3)))
    feats.append(MapFeature("m", "d1", "drivable_area", _rect(-per_way * w - 3, per_way * w + 3, -55, 70)))
    # ego (the origin) drives in the middle of the inner northbound lane
    return RoadMap.of("m", [replace(f, polygon=tuple((x - w / 2, y) for x, y in f.polygon),
                                    line=tuple((x - w / 2, y) for x, y in f.line)) for f in feats])


def placed(road: RoadMap, entities: list[dict]) -> list[Entity]:
    """Entities (dicts of id, type, x, y, heading) with their lane facts from the road (the scene's frame is the
    road's: a heading from +y is a direction from +x plus 90 degrees)."""
    index = RoadIndex(road)
    facts = index.facts([e["x"] for e in entities], [e["y"] for e in entities],
                        [e["heading"] + 90.0 for e in entities])
    return [Entity(e["id"], e["type"], e["x"], e["y"], e["heading"], lanes=f.lanes, lane=f.lane,
                   in_intersection=f.in_intersection, on_crosswalk=f.on_crosswalk, off_road=f.off_road)
            for e, f in zip(entities, facts)]


def random_lane_scene(rng: random.Random, n: int) -> Scene:
    """A random road and n entities on it: most on lanes facing their way (or the other way), some anywhere."""
    road = random_road(rng)
    lanes = [f for f in road.lanes if not f.is_intersection]
    ents = [{"id": "ego", "type": "Car", "x": 0.0, "y": 0.0, "heading": 0.0}]
    counts: dict[str, int] = {}
    for _ in range(n):
        kind = rng.choice(["Car", "Car", "Car", "Pedestrian"])
        counts[kind] = counts.get(kind, 0) + 1
        if kind == "Car" and rng.random() < 0.85:
            f = rng.choice(lanes)
            (xa, ya), (xb, yb) = f.line[0], f.line[-1]
            t = rng.random()
            x, y = xa + t * (xb - xa) + rng.uniform(-1, 1), ya + t * (yb - ya)
            heading = (0.0 if yb > ya else 180.0) + rng.uniform(-10, 10)
        else:
            x, y, heading = rng.uniform(-12, 12), rng.uniform(-50, 65), rng.uniform(0, 360)
        ents.append({"id": f"{kind.lower()}{counts[kind]}", "type": kind, "x": round(x, 2), "y": round(y, 2),
                     "heading": round(heading, 1)})
    return make_scene(f"lanes-{rng.random():.6f}", placed(road, ents), road)
