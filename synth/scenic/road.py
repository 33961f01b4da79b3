"""The recorded road as Scenic regions: the part of an emitted program that holds a scene's road (docs/scenic.md,
"The road").

A scene that carries a road (scene JSON's `road`: the map features within its radius, in its ego frame) gets, in
its Scenic text, one PolygonalRegion per lane, crosswalk, intersection and drivable area, in four tables keyed
by feature id (`road__lanes['ID']`, ...), every lane's centre line (`road__centre_lines['ID']`), and helpers that
say where an object's centre is, as the lane facts say it (synth.road.lane_facts; docs/formats.md, "Lane facts"):
`road__in(road__crosswalks, obj)` the ids of the table's regions containing it, `road__lane_of(obj)` its chosen
lane (the tie rule), `road__in_intersection(obj)`, `road__on_crosswalk(obj)`, `road__off_road(obj)` (with
`road__intersection_lanes`, the ids of the intersection lanes), `road__off_lane(obj)`, and the lane relations
(`road__related[side][lane]`: synth.road.lane_relations on the scene's road) with `road__lane_related(obj, ref,
side)`. Lane clauses (synth.parts.lane) become requirements over them. Road lines bound no region and are left
out.

The features are data, written as one JSON document in one raw string literal (a feature a line) that the text
decodes, and the tables are built from it by comprehensions: Scenic's parser is slow per statement and per
token (the 60 features of an Argoverse 2 frame took 2.2 s to compile as one assignment each, 0.12 s as one
literal; a number token costs ~1.4 ms), and JSON writes floats by `repr`, which round-trips, so the regions are
the scene's exactly.
"""

from __future__ import annotations

import json

from synth.road.lane_relations import SIDES, LaneGraph
from synth.road.roadmap import CROSSWALK, DRIVABLE_AREA, INTERSECTION, LANE, MapFeature, RoadMap

# (kind, the Scenic table of its regions), in the order the text defines them.
TABLES = ((LANE, "road__lanes"), (CROSSWALK, "road__crosswalks"), (INTERSECTION, "road__intersections"),
          (DRIVABLE_AREA, "road__drivable_areas"))
CENTRE_LINES = "road__centre_lines"
INTERSECTION_LANES = "road__intersection_lanes"
RELATED = "road__related"
DATA = "road__data"

# Every emitted program carries this text as written: its two pointers to our modules keep their names from
# before synth/road/ (synth.road.lane_relations, synth.road.lane_facts now), so that the Scenic a version writes
# stays byte-identical.
ROAD_PRELUDE = '''\
# The recorded road around ego (ego frame): one region per feature, by feature id (docs/scenic.md, "The road").
import json as road__json
import math as road__math

def road__pairs(v):
    """[x, y, x, y, ...] -> ((x, y), ...)."""
    return tuple(zip(v[0::2], v[1::2]))

def road__in(regions, obj):
    """The ids of the regions of a table whose polygon contains obj's centre, sorted."""
    p = obj.position
    return sorted(i for i, r in regions.items() if r.containsPoint(p))

def road__direction_near(line, x, y):
    """The direction (degrees counter-clockwise from +x) of the segment of a line nearest (x, y); None if none."""
    best = None
    for k in range(len(line) - 1):
        ax, ay = line[k]
        dx, dy = line[k + 1][0] - ax, line[k + 1][1] - ay
        length2 = dx * dx + dy * dy
        if length2 == 0:
            continue
        t = min(1.0, max(0.0, ((x - ax) * dx + (y - ay) * dy) / length2))
        gap = road__math.hypot(ax + t * dx - x, ay + t * dy - y)
        if best is None or gap < best[0]:
            best = (gap, road__math.degrees(road__math.atan2(dy, dx)) % 360.0)
    return None if best is None else best[1]

def road__in_intersection(obj):
    """obj's centre is in an intersection, or in an intersection lane (the lane fact in_intersection)."""
    return bool(road__in(road__intersections, obj)) or any(
        lane in road__intersection_lanes for lane in road__in(road__lanes, obj))

def road__on_crosswalk(obj):
    return bool(road__in(road__crosswalks, obj))

def road__off_road(obj):
    """obj's centre is in no lane and no drivable area (the lane fact off_road)."""
    return not road__in(road__lanes, obj) and not road__in(road__drivable_areas, obj)

def road__off_lane(obj):
    """obj's centre is in no lane but in a drivable area."""
    return not road__in(road__lanes, obj) and bool(road__in(road__drivable_areas, obj))

def road__lane_related(obj, ref, side):
    """obj's lane is one of the lanes related to ref's lane by `side` (same, left, right, oncoming: the lane
    relations of synth.lane_relations, road__related[side][ref's lane])."""
    mine = road__lane_of(obj)
    return mine is not None and mine in road__related[side].get(road__lane_of(ref), ())

def road__lane_of(obj):
    """obj's lane: of the lanes containing its centre, the one whose direction at its centre-line segment nearest
    the centre differs least from obj's heading, then the smaller id; None in no lane (synth.lane_facts)."""
    here = road__in(road__lanes, obj)
    if len(here) <= 1:
        return here[0] if here else None
    x, y = obj.position.x, obj.position.y
    heading = road__math.degrees(obj.heading) + 90.0  # Scenic's heading is from +y, the directions from +x
    best = None
    for lane in here:
        d = road__direction_near(road__centre_lines[lane], x, y)
        key = (180.0 if d is None else abs((heading - d + 180.0) % 360.0 - 180.0), lane)
        if best is None or key < best:
            best = key
    return best[1]
'''


def _json(value: object) -> str:
    """JSON that a raw triple-quoted Python literal holds as is: ASCII, and the quote ' escaped as JSON's
    \\u0027, so that nothing ends the literal early (JSON never ends in a backslash)."""
    return json.dumps(value, ensure_ascii=True, separators=(",", ":")).replace("'", "\\u0027")


def _feature(f: MapFeature) -> str:
    """One feature of the data: `"ID":{"polygon":[x,y,...]}`, a lane with its centre line and intersection flag."""
    value: dict = {"polygon": [c for p in f.polygon for c in p]}
    if f.kind == LANE:
        value.update(line=[c for p in f.line for c in p], intersection=f.is_intersection)
    return f"{_json(f.feature_id)}:{_json(value)}"


def _related(road: RoadMap) -> str:
    """The lane relations (synth.road.lane_relations.LaneGraph.related) as data: for each side (same, left, right,
    oncoming), each lane that has related lanes -> the lanes a target's lane must be in for that relation with a
    reference in it (sorted), a side a line."""
    graph = LaneGraph(road)
    rows = []
    for side in SIDES:
        table = {f.feature_id: sorted(r) for f in road.lanes if (r := graph.related(f.feature_id, side))}
        rows.append(f"\n{_json(side)}:{_json(table)}")
    return "{" + ",".join(rows) + "}"


def road_scenic(road: RoadMap) -> list[str]:
    """The lines that define a scene's road in Scenic: the helpers, the data (a feature a line, in map order),
    the tables built from it."""
    sections = [f'"{table}":{{' + ",".join(f"\n{_feature(f)}" for f in road.of_kind(kind)) + "}"
                for kind, table in TABLES]
    sections.append(f'"{RELATED}":{_related(road)}')
    lines = [ROAD_PRELUDE, f"# map {road.map_id!r}", f"{DATA} = road__json.loads(r'''{{{','.join(sections)}}}''')"]
    lines += [f"{table} = {{i: PolygonalRegion(road__pairs(f['polygon'])) for i, f in {DATA}['{table}'].items()}}"
              for _, table in TABLES]
    lines += [f"{CENTRE_LINES} = {{i: road__pairs(f['line']) for i, f in {DATA}['road__lanes'].items()}}",
              f"{INTERSECTION_LANES} = frozenset(i for i, f in {DATA}['road__lanes'].items() if f['intersection'])",
              f"{RELATED} = {DATA}['{RELATED}']",
              ""]
    return lines
