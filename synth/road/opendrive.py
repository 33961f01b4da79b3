"""A recorded road as a linked OpenDRIVE road network, as values (docs/formats.md, "OpenDRIVE"): which road each
lane becomes, how roads link, which form junctions, and each road's reference line and widths. Pure: the XML is
written at the edge (pipeline/export/opendrive.py).

One road per recorded lane outside junctions, with one driving lane (-1, right-hand traffic) centred on the
reference line; lanes cut where a same-direction neighbour starts or ends beside them, and pieces side by side
then made lanes of one road (synth.road.opendrive_group).

Roles. A lane is a junction's (a connecting road's piece) when the map says it is an intersection lane, or when
it could not be linked directly: OpenDRIVE links a road to one road at each end, so a lane that is one of
several successors of a lane (a fork) or that has several predecessors (a merge) is a junction's too; an
intersection lane without predecessors is an ordinary road (the area begins there). Of a fork's or merge's lane
that is not an intersection lane, followed by an ordinary lane, only the first FORK_PIECE metres are the
junction's (the rest an ordinary road that can be a lane beside its neighbours). A junction lane followed by
another junction lane, or by none, is cut at half its length, its second half an ordinary road: so every path
through a junction is one junction lane from an ordinary road to an ordinary road (chains of them multiply paths
beyond 10^5 on a Waymo map; Scenic's parser gives a path without an outgoing road no maneuver). Each such path
is one connecting road; paths that share an incoming or an outgoing road are one junction; an ordinary road
with both ends at one junction (Scenic's parser refuses it) is cut in two, linked. A recorded link between lanes
more than LINK_GAP apart is bridged by a straight junction lane.

Geometry. Reference lines are the recorded centre lines, vertex to vertex (line geometries, tolerance 0), but at
their ends: every road end meeting others (a node: a lane's end and its successors' starts) is moved to the
node's mean point, and the road's first (last) ENDING metres run straight in the node's mean heading, so that
linked lanes meet edge to edge (ASAM's check allows 0.01 m). Widths are the lane polygon's chord across the
centre line at each vertex (clamped to [MIN_WIDTH, MAX_WIDTH]; the polygon's area over the line's length where
the chord cannot be had), linear between vertices, the node's mean at a node. Coordinates are recentred: the
whole metres nearest the lanes' mean point are subtracted (`offset`, which the header keeps).

Marks and crosswalks. Each ordinary road's lane edges carry the recorded road line of a known type (ROAD_MARKS)
that runs along them (within MARK_DISTANCE of at least MARK_SHARE of the edge's points); each recorded
crosswalk is an object of the ordinary road nearest its centroid, its outline in the road's frame there.
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Sequence

import numpy as np

from synth.errors import InputError
from synth.road.opendrive_group import ALIGN, MIN_PIECE, cuts, grouped, neighbours
from synth.road.opendrive_model import NO_MARK, Crosswalk, Junction, Link, Network, Road
from synth.road.roadmap import CROSSWALK, ROAD_LINE, MapFeature, RoadMap

MAP_SUFFIX = ".xodr"  # an OpenDRIVE file's; the only map a Scenic text names (Scenic unpickles a .snet map)
MIN_WIDTH, MAX_WIDTH = 1.0, 10.0  # metres: a width outside these is a degenerate polygon's, clamped
MIN_SEGMENT = 1e-6  # metres: shorter centre-line segments (repeated points) are skipped
ENDING = 0.05  # metres: the straight piece at a road's end in its node's heading (at most a quarter of the road)
MAX_PATHS = 100_000  # connecting roads in one network at most (paths through junction lanes multiply)
END_RUNS = 4  # line geometries fewer a road may be written with, its ends moved onto a grouped lane's
MAX_PATH_LANES = 64  # junction lanes in one path at most
# the keys of a split lane's second half (no feature id holds a control character): a junction lane's, an
# ordinary lane's
TAIL, MIDDLE, BRIDGE, PART, REST = "\x00tail", "\x00middle", "\x00to\x00", "\x00part", "\x00rest"
FORK_PIECE = 5.0  # metres: a fork's or a merge's lane's piece in its junction (at most half the lane)
HEADING_TOLERANCE = 1e-6  # radians: ASAM's redundancy check's tolerance (one line for collinear segments)
LINK_GAP = 0.1  # metres: linked lane ends farther apart are bridged (nearer ones meet at their mean point)
MARK_DISTANCE = 0.5  # metres: a recorded road line this near a point of a road's edge runs along it there
MARK_SHARE = 0.5  # a road line near this share of an edge's points (sampled every MARK_STEP) marks the edge
MARK_STEP = 1.0  # metres

# A recorded road line's type (ScenarioNet's, which the nuScenes and Waymo readers keep) as an OpenDRIVE road
# mark: (type, colour, laneChange). A passing double yellow is written solid_broken with no lane change (which
# side may pass is not recorded); a road edge is a curb. An edge no such line runs along has NO_MARK.
ROAD_MARKS = {
    "ROAD_LINE_BROKEN_SINGLE_WHITE": ("broken", "white", "both"),
    "ROAD_LINE_BROKEN_DOUBLE_WHITE": ("broken_broken", "white", "both"),
    "ROAD_LINE_SOLID_SINGLE_WHITE": ("solid", "white", "none"),
    "ROAD_LINE_SOLID_DOUBLE_WHITE": ("solid_solid", "white", "none"),
    "ROAD_LINE_BROKEN_SINGLE_YELLOW": ("broken", "yellow", "both"),
    "ROAD_LINE_BROKEN_DOUBLE_YELLOW": ("broken_broken", "yellow", "both"),
    "ROAD_LINE_SOLID_SINGLE_YELLOW": ("solid", "yellow", "none"),
    "ROAD_LINE_SOLID_DOUBLE_YELLOW": ("solid_solid", "yellow", "none"),
    "ROAD_LINE_PASSING_DOUBLE_YELLOW": ("solid_broken", "yellow", "none"),
    "ROAD_EDGE_BOUNDARY": ("curb", "standard", "none"),
    "ROAD_EDGE_MEDIAN": ("curb", "standard", "none"),
}


def _clean(line: Sequence[tuple[float, float]]) -> list[tuple[float, float]]:
    pts = [tuple(line[0])] if line else []
    for p in line[1:]:
        if math.dist(pts[-1], p) > MIN_SEGMENT:
            pts.append(tuple(p))
    return pts


def lane_widths(f: MapFeature, pts: list[tuple[float, float]]) -> list[float]:
    """The lane's width at each point of its centre line: the chord of its polygon along the normal there (the
    piece through the point), the ends taking their neighbour's (a polygon's end caps lie across the normal);
    the mean width (area over length) where there is no chord."""
    import shapely

    a = np.asarray(pts, dtype=float)
    length = float(np.hypot(*np.diff(a, axis=0).T).sum())
    poly = shapely.Polygon(f.polygon) if len(f.polygon) >= 3 else None
    mean = min(MAX_WIDTH, max(MIN_WIDTH, poly.area / length)) if poly is not None and length > 0 else MIN_WIDTH
    if poly is None or not poly.is_valid or len(a) < 3:
        return [mean] * len(a)
    tangent = np.zeros_like(a)
    tangent[1:-1] = a[2:] - a[:-2]
    norm = np.hypot(tangent[:, 0], tangent[:, 1])
    norm[norm == 0] = 1.0
    normal = np.stack([-tangent[:, 1], tangent[:, 0]], axis=1) / norm[:, None]
    reach = 2 * MAX_WIDTH
    chords = shapely.linestrings(np.stack([a - reach * normal, a + reach * normal], axis=1))
    cuts = shapely.intersection(chords, poly)
    out = []
    for i, (p, cut) in enumerate(zip(a, cuts)):
        w = None
        if 0 < i < len(a) - 1 and cut is not None and not cut.is_empty:
            point = shapely.Point(p)
            pieces = getattr(cut, "geoms", [cut])
            near = [g for g in pieces if g.distance(point) < 1e-6 and g.length > 0]
            if near:
                w = near[0].length
        out.append(mean if w is None else min(MAX_WIDTH, max(MIN_WIDTH, w)))
    out[0], out[-1] = out[1], out[-2]
    return out


class _Ends:
    """Union-find over road ends (road index, 0 start / 1 end): the ends that meet are one node."""

    def __init__(self) -> None:
        self.parent: dict = {}

    def find(self, x):
        self.parent.setdefault(x, x)
        while self.parent[x] != x:
            self.parent[x] = self.parent[self.parent[x]]
            x = self.parent[x]
        return x

    def union(self, a, b) -> None:
        self.parent[self.find(a)] = self.find(b)


def lane_graph(lanes: dict[str, MapFeature]) -> tuple[dict[str, list[str]], dict[str, list[str]]]:
    """Each lane's successors and predecessors among `lanes`, a link either lane names being a link (a map may
    record it on one side only)."""
    succ = {k: [s for s in f.successors if s in lanes] for k, f in lanes.items()}
    pred = {k: [p for p in f.predecessors if p in lanes] for k, f in lanes.items()}
    for k in lanes:
        for s in succ[k]:
            if k not in pred[s]:
                pred[s].append(k)
        for p in pred[k]:
            if k not in succ[p]:
                succ[p].append(k)
    return succ, pred


def roles(lanes: dict[str, MapFeature], succ: dict[str, list[str]], pred: dict[str, list[str]]) -> set[str]:
    """The lanes that are pieces of connecting roads (module docstring, "Roles")."""
    junction = {k for k, f in lanes.items() if f.is_intersection}
    for k in lanes:  # forks and merges
        if len(succ[k]) > 1:
            junction.update(succ[k])
        if len(pred[k]) > 1:
            junction.add(k)
    junction -= {k for k in junction if not pred[k]}  # where the area starts: an incoming road
    return junction


class TooManyGeometries(InputError, ValueError):
    """A network would be more line geometries than its bound: `count` of them (at least, unless `exact`). An input
    too large: the exporter says it in one line (pipeline.export.opendrive.linked)."""

    def __init__(self, count: int, exact: bool = True) -> None:
        super().__init__(f"{'' if exact else 'at least '}{count:,} line geometries")
        self.count, self.exact = count, exact


def network(road: RoadMap, recentre: bool = True, max_geometries: int | None = None) -> Network:
    """The linked network of a road's lanes (in its frame, recentred unless `recentre` is false: then the
    offset is (0, 0); module docstring); TooManyGeometries where the roads it surely writes (before marks and
    grouping, which cost time per point) are more line geometries than `max_geometries`."""
    lanes = {f.feature_id: f for f in road.lanes if len(_clean(f.line)) >= 2}
    succ, pred = lane_graph(lanes)
    junction = roles(lanes, succ, pred)
    shape = {k: (_clean(f.line), lane_widths(f, _clean(f.line))) for k, f in lanes.items()}
    recorded = {k: (k,) for k in lanes}  # the recorded lanes each key follows (a split lane's halves name it)
    # a successor link between lanes that do not meet (Waymo's maps have a few, 2 to 20 m apart): a straight
    # junction lane from the one's end to the other's start bridges the gap
    bridges = 0
    for a in sorted(lanes):
        for b in list(succ[a]):
            gap = math.dist(shape[a][0][-1], shape[b][0][0])
            if gap <= LINK_GAP:
                continue
            bridge = a + BRIDGE + b
            shape[bridge] = ([shape[a][0][-1], shape[b][0][0]], [shape[a][1][-1], shape[b][1][0]])
            recorded[bridge] = (a, b)
            succ[a] = [bridge if s == b else s for s in succ[a]]
            pred[b] = [bridge if p == a else p for p in pred[b]]
            succ[bridge], pred[bridge] = [b], [a]
            junction.add(bridge)
            bridges += 1

    def split(k: str, mark: str, at: float | None = None) -> str:
        """Cut lane k where `at` metres of it are run (default: half its length): k keeps the first piece, a new
        key the second and k's successors."""
        new = k + mark
        shape[k], shape[new] = _halves(*shape[k], at)
        recorded[new] = recorded[k]
        succ[new], pred[new] = succ[k], [k]
        for s in succ[k]:
            pred[s] = [new if p == k else p for p in pred[s]]
        succ[k] = [new]
        return new

    # a fork's or a merge's lane the map does not call an intersection lane: its first FORK_PIECE metres (at most
    # half of it) are the junction's, the rest an ordinary road (Waymo's lanes run on for tens of metres after a
    # fork: a connecting road whole, such a lane could be no lane of one road with its neighbours)
    rest = {k: k for k in lanes if k not in junction}  # recorded lane -> the key of its ordinary part
    for k in sorted(junction & lanes.keys()):
        length = float(np.hypot(*np.diff(np.asarray(shape[k][0]), axis=0).T).sum())
        if not lanes[k].is_intersection and succ[k] and not any(s in junction for s in succ[k]):
            rest[k] = split(k, REST, min(FORK_PIECE, length / 2))
    # lanes with recorded same-direction neighbours cut where a neighbour starts or ends beside them, so that
    # pieces side by side begin and end across from each other: lanes of one road (synth.road.opendrive_group)
    joints = []  # (piece, the piece after it) of each such cut: put back together where not grouped
    cut_at, trim = cuts({k: shape[key][0] for k, key in rest.items()}, lanes)
    # a neighbour's end less than MIN_PIECE from a lane's end (AV2's lanes end on slanted stop lines): the lane's
    # piece beyond it goes to the lanes linked there, where it is all of their link at that end (put before each
    # successor; appended to each predecessor that is a junction lane: an ordinary one's neighbours were
    # measured against where it ends), so that the lane's end is across from the neighbour's; with nothing
    # linked there, the piece is a road of its own
    moved: dict[str, float] = defaultdict(float)  # recorded lane -> metres put before its line
    # the lane ends whose line a trim changed, at its start and at its end: each end takes one trim (a lane that
    # got its predecessor's piece before it may still give its own end's piece to its successors)
    touched: tuple[set[str], set[str]] = (set(), set())
    lane_of = {v: k for k, v in rest.items()}
    for k, (head, tail) in sorted(trim.items()):
        key = rest[k]
        length = _length(shape[key][0])
        if length - head - tail < MIN_PIECE:
            continue
        if head > 0 and key in touched[0]:
            pass
        elif head > 0 and not pred[key]:  # nothing linked there: the piece is a road of its own
            cut_at.setdefault(k, []).insert(0, head)
        elif head > 0 and all(p in junction and succ[p] == [key] and p not in touched[1] for p in pred[key]):
            first, shape[key] = _halves(*shape[key], head)
            for p in pred[key]:
                shape[p] = _joined(shape[p], first)
                recorded[p] = recorded[p] + (k,)  # the piece is lane k's, whatever key holds before it
            moved[k] -= head
            touched[1].update(pred[key])
            touched[0].add(key)
            length -= head
        if tail > 0 and key in touched[1]:
            pass
        elif tail > 0 and not succ[key]:
            cut_at.setdefault(k, []).append(length - tail - moved[k])
        elif tail > 0 and succ[key] and all(pred[s] == [key] and s not in touched[0] for s in succ[key]):
            shape[key], second = _halves(*shape[key], length - tail)
            for s in succ[key]:
                shape[s] = _joined(second, shape[s])
                recorded[s] = (k,) + recorded[s]
                moved[lane_of.get(s, s)] += tail
            touched[0].update(succ[key])
            touched[1].add(key)
    for k, at in cut_at.items():
        at = [s + moved[k] for s in at]
        end = _length(shape[rest[k]][0])
        at = [s for s in at if ALIGN <= s <= end - ALIGN]
        piece, done = rest[k], 0.0
        for n, s in enumerate(at):
            before, piece, done = piece, split(piece, f"{PART}{n}", s - done), s
            joints.append((before, piece))
    # a junction lane followed by another junction lane or by none: its second half is an ordinary road, so
    # that every path through a junction is one junction lane from an ordinary road to an ordinary road (paths
    # through chains of them multiply: 10^5 and more on a Waymo map; Scenic gives a path without an outgoing
    # road no maneuver)
    halved = set()  # the recorded lanes so cut: a junction's lanes, whose second halves are roads
    for k in sorted(junction):
        if not succ[k] or any(s in junction for s in succ[k]):
            split(k, TAIL)
            halved.update(x for x in recorded[k] if x in junction)  # not a lane whose piece was put before it
    ordinary = [k for k in sorted(recorded) if k not in junction]
    paths = _paths(ordinary, junction, succ)
    # an ordinary road with both ends at one junction (Scenic's parser refuses it) is cut in two, linked
    ends: dict[str, set] = defaultdict(set)
    for (inc, _, out), j in zip(paths, _junctions(paths)):
        ends[inc].add(("succ", j))
        if out is not None:
            ends[out].add(("pred", j))
    both = sorted(k for k, e in ends.items() if {j for w, j in e if w == "succ"} & {j for w, j in e if w == "pred"})
    for k in both:
        split(k, MIDDLE)
    ordinary = [k for k in sorted(recorded) if k not in junction]
    paths = _paths(ordinary, junction, succ)
    path_junction = _junctions(paths)
    notes: list[str] = []
    if bridges:
        notes.append(f"{bridges} recorded successor link(s) between lanes more than {LINK_GAP:g} m apart bridged by "
                     "a straight connecting road")
    covered = {c for _, p, _ in paths for c in p}
    left_out = sorted(junction - covered)
    if left_out:
        notes.append(f"{len(left_out)} junction lane(s) on no path from an ordinary lane left out "
                     f"(e.g. {left_out[0]!r})")
    rid = {k: i for i, k in enumerate(ordinary, start=1)}  # road ids: ordinary lanes (sorted), then paths

    # lines and widths of every road, before the ends are pinned
    lines: list[list[tuple[float, float]]] = []
    wids: list[list[float]] = []
    for k in ordinary:
        lines.append(list(shape[k][0]))
        wids.append(list(shape[k][1]))
    for _, p, _ in paths:
        pts: list = []
        ws: list = []
        for c in p:
            line, widths = shape[c]
            skip = 1 if pts and math.dist(pts[-1], line[0]) <= MIN_SEGMENT else 0
            pts += line[skip:]
            ws += widths[skip:]
        lines.append(pts)
        wids.append(ws)

    # nodes: which road ends meet (road index in `lines`, 0 start / 1 end)
    nodes = _Ends()
    n_ord = len(ordinary)
    links: dict[tuple[int, int], Link] = {}
    for i, k in enumerate(ordinary):
        nxt = [s for s in succ[k] if s not in junction]
        if nxt and len(succ[k]) == 1 and len(pred[nxt[0]]) == 1:
            j = rid[nxt[0]] - 1
            nodes.union((i, 1), (j, 0))
            links[(i, 1)] = Link("road", j + 1, "start")
            links[(j, 0)] = Link("road", i + 1, "end")
    for n, (inc, _, out) in enumerate(paths):
        i = n_ord + n
        nodes.union((rid[inc] - 1, 1), (i, 0))
        links[(i, 0)] = Link("road", rid[inc], "end")
        links[(rid[inc] - 1, 1)] = Link("junction", path_junction[n])
        if out is not None:
            nodes.union((i, 1), (rid[out] - 1, 0))
            links[(i, 1)] = Link("road", rid[out], "start")
            links[(rid[out] - 1, 0)] = Link("junction", path_junction[n])

    # each node's pose: mean point, mean heading of travel, mean width
    members: dict = defaultdict(list)
    for i in range(len(lines)):
        for end in (0, 1):
            if (i, end) in nodes.parent:
                members[nodes.find((i, end))].append((i, end))
    pose: dict = {}
    for root, ends in members.items():
        pts = np.array([lines[i][-end] if end else lines[i][0] for i, end in ends])
        heads = []
        for i, end in ends:
            a, b = (lines[i][-2], lines[i][-1]) if end else (lines[i][0], lines[i][1])
            heads.append(math.atan2(b[1] - a[1], b[0] - a[0]))
        h = math.atan2(sum(map(math.sin, heads)), sum(map(math.cos, heads)))
        w = float(np.mean([wids[i][-1] if end else wids[i][0] for i, end in ends]))
        spread = float(np.hypot(*(pts - pts.mean(axis=0)).T).max())
        pose[root] = (tuple(pts.mean(axis=0).tolist()), h, w, spread)

    all_pts = np.concatenate([np.asarray(line) for line in lines]) if lines else np.zeros((1, 2))
    offset = tuple(float(v) for v in np.round(all_pts.mean(axis=0))) if recentre else (0.0, 0.0)
    roads = []
    for i, (line, ws) in enumerate(zip(lines, wids)):
        start = pose.get(nodes.find((i, 0))) if (i, 0) in nodes.parent else None
        end = pose.get(nodes.find((i, 1))) if (i, 1) in nodes.parent else None
        pts, w = _pinned(line, ws, start, end)
        pts = [(x - offset[0], y - offset[1]) for x, y in pts]
        names = recorded[ordinary[i]] if i < n_ord else tuple(n for c in paths[i - n_ord][1] for n in recorded[c])
        roads.append(Road(i + 1, names, tuple(pts), tuple(w), -1 if i < n_ord else path_junction[i - n_ord],
                          links.get((i, 0)), links.get((i, 1))))
    junctions = defaultdict(list)
    for n, (inc, _, _) in enumerate(paths):
        junctions[path_junction[n]].append((rid[inc], n_ord + n + 1, -1))
    if max_geometries is not None:  # before the marks and the grouping, which cost time per point
        # the roads written whatever is grouped: connecting roads and the roads of lanes without a neighbour
        # their way (each end may be moved onto a grouped lane's: END_RUNS fewer runs at most); the file's own
        # count is the caller's to check
        sure = neighbours({k: f.line for k, f in lanes.items()}, lanes).keys()
        geometries = sum(len(straight_runs(r.points)) - END_RUNS for r in roads
                         if r.junction != -1 or not set(r.lanes) & sure)
        if geometries > max_geometries:
            raise TooManyGeometries(geometries, exact=False)
    roads = _marked(roads, road, offset)
    roads, joined, group_notes = grouped(roads, [Junction(j, tuple(c)) for j, c in sorted(junctions.items())], lanes,
                                         [(rid[a], rid[b]) for a, b in joints if a in rid and b in rid], halved)
    return Network(tuple(roads), tuple(joined), offset, tuple(notes) + group_notes, _crosswalks(roads, road, offset))


def _edges(r: Road) -> tuple[np.ndarray, np.ndarray]:
    """A road's left and right lane edges: its reference line moved half its width along the normal at each
    point (the mean of its two segments' normals inside)."""
    a = np.asarray(r.points, dtype=float)
    d = np.diff(a, axis=0)
    d /= np.hypot(d[:, 0], d[:, 1])[:, None]
    tangent = np.concatenate([d[:1], d[:-1] + d[1:], d[-1:]])
    tangent /= np.maximum(np.hypot(tangent[:, 0], tangent[:, 1]), 1e-12)[:, None]
    normal = np.stack([-tangent[:, 1], tangent[:, 0]], axis=1) * (np.asarray(r.widths) / 2)[:, None]
    return a + normal, a - normal


def _marked(roads: list[Road], road: RoadMap, offset: tuple[float, float]) -> list[Road]:
    """Each ordinary road with the recorded road lines along its edges as marks: the line of a known type
    (ROAD_MARKS) within MARK_DISTANCE of the most of the edge's points sampled every MARK_STEP, if that is at
    least MARK_SHARE of them; connecting roads are left unmarked (junctions rarely paint their lanes)."""
    import shapely

    lines = [f for f in road.features if f.kind == ROAD_LINE and f.source_type in ROAD_MARKS and len(f.line) >= 2]
    if not lines:
        return roads
    tree = shapely.STRtree([shapely.LineString(np.asarray(f.line) - offset) for f in lines])
    out = []
    for r in roads:
        if r.junction != -1 or len(r.points) < 2:
            out.append(r)
            continue
        marks = []
        for edge in _edges(r):
            run = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(edge, axis=0).T))])
            n = max(3, int(run[-1] / MARK_STEP) + 1)
            # the samples by one pass along the edge (shapely's line_interpolate_point walks the line from its
            # start for each sample: quadratic, 5.4 s on a 100,000-point lane)
            at = np.linspace(0, run[-1], n + 2)[1:-1]
            samples = shapely.points(np.interp(at, run, edge[:, 0]), np.interp(at, run, edge[:, 1]))
            _, near = tree.query(samples, predicate="dwithin", distance=MARK_DISTANCE)
            counts = np.bincount(near, minlength=len(lines))
            best = int(counts.argmax())
            marks.append(ROAD_MARKS[lines[best].source_type] if counts[best] >= MARK_SHARE * n else NO_MARK)
        out.append(Road(r.id, r.lanes, r.points, r.widths, r.junction, r.predecessor, r.successor,
                        (marks[0], marks[1])))
    return out


def _crosswalks(roads: list[Road], road: RoadMap, offset: tuple[float, float]) -> tuple[Crosswalk, ...]:
    """Each recorded crosswalk (a polygon of 3 points or more) on the ordinary road whose reference line is
    nearest its centroid (Crosswalk)."""
    import shapely

    ordinary = [r for r in roads if r.junction == -1 and len(r.points) >= 2]
    walks = [f for f in road.features if f.kind == CROSSWALK and len(f.polygon) >= 3]
    if not ordinary or not walks:
        return ()
    refs = [shapely.LineString(r.points) for r in ordinary]
    tree = shapely.STRtree(refs)
    out = []
    for f in walks:
        ring = np.asarray(f.polygon, dtype=float) - offset
        c = shapely.Polygon(ring).centroid
        if c.is_empty:
            continue
        r = ordinary[int(tree.nearest(c))]
        s, t, base, tangent = _station(r, c.x, c.y, exact=False)  # type: ignore[misc]
        normal = np.array([-tangent[1], tangent[0]])
        rel = ring - (base + t * normal)
        outline = tuple((float(u), float(v)) for u, v in zip(rel @ tangent, rel @ normal))
        out.append(Crosswalk(f.feature_id, r.id, s, t, outline))
    return tuple(out)


def _paths(ordinary: list[str], junction: set[str], succ: dict[str, list[str]]
           ) -> list[tuple[str, tuple[str, ...], str | None]]:
    """Every path through junction lanes: (its incoming lane, its junction lanes, its outgoing lane or None
    where the lanes stop), in a stable order."""
    paths: list[tuple[str, tuple[str, ...], str | None]] = []
    for k in ordinary:
        stack = [(s,) for s in reversed(succ[k]) if s in junction]
        while stack:
            path = stack.pop()
            last = path[-1]
            ends = [s for s in succ[last] if s not in junction]
            more = [s for s in succ[last] if s in junction and s not in path]
            paths += [(k, path, s) for s in ends]
            if not ends and not more:
                paths.append((k, path, None))
            if len(path) < MAX_PATH_LANES:
                stack += [path + (s,) for s in reversed(more)]
            if len(paths) > MAX_PATHS:
                raise ValueError(f"more than {MAX_PATHS:,} paths through junctions")
    return paths


def _junctions(paths: list[tuple[str, tuple[str, ...], str | None]]) -> list[int]:
    """Each path's junction (1, 2, ...): paths that share an incoming road are one junction (a road has one
    successor), and so are paths that share an outgoing road."""
    group = _Ends()
    for i, (inc, _, out) in enumerate(paths):
        group.union(("path", i), ("in", inc))
        if out is not None:
            group.union(("path", i), ("out", out))
    jid: dict = {}
    return [jid.setdefault(group.find(("path", i)), len(jid) + 1) for i in range(len(paths))]


def _halves(line: list, widths: list, at: float | None = None) -> tuple[tuple[list, list], tuple[list, list]]:
    """A centre line and its widths cut where `at` metres of it are run (default: half its length): the point
    there (widths interpolated) ends the first piece and starts the second."""
    a = np.asarray(line, dtype=float)
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(a, axis=0).T))])
    half = s[-1] / 2 if at is None else at
    i = int(np.searchsorted(s, half, side="right")) - 1  # the segment [i, i + 1] holding the cut
    t = (half - s[i]) / (s[i + 1] - s[i])
    p = tuple((a[i] + t * (a[i + 1] - a[i])).tolist())
    w = widths[i] + t * (widths[i + 1] - widths[i])
    first = [tuple(x) for x in line[:i + 1]] + ([p] if t > 0 else [])
    second = [p] + [tuple(x) for x in line[i + 1:]]
    return (first, list(widths[:i + 1]) + ([w] if t > 0 else [])), (second, [w] + list(widths[i + 1:]))


def _length(line) -> float:
    return float(np.hypot(*np.diff(np.asarray(line, dtype=float), axis=0).T).sum())


def _joined(a: tuple[list, list], b: tuple[list, list]) -> tuple[list, list]:
    """Two centre lines with their widths as one, b after a (b's first point left out where it is a's last)."""
    skip = 1 if math.dist(a[0][-1], b[0][0]) <= MIN_SEGMENT else 0
    return list(a[0]) + list(b[0][skip:]), list(a[1]) + list(b[1][skip:])


def _pinned(line, ws, start, end):
    """A road's points and widths with its ends at their nodes' poses: the node's point, then ENDING metres in its
    heading (points of the recorded line within twice that of an end dropped)."""
    pts = [np.asarray(p, dtype=float) for p in line]
    w = list(ws)
    length = sum(math.dist(a, b) for a, b in zip(line, line[1:]))
    e = min(ENDING, length / 4)
    if start is not None:
        (p0, h0, w0, _) = start
        p0 = np.asarray(p0)
        d0 = np.array([math.cos(h0), math.sin(h0)])
        keep = [k for k in range(1, len(pts)) if math.dist(pts[k], p0) > 2 * e]
        pts, w = [p0, p0 + e * d0] + [pts[k] for k in keep], [w0, w0] + [w[k] for k in keep]
    if end is not None:
        (p1, h1, w1, _) = end
        p1 = np.asarray(p1)
        d1 = np.array([math.cos(h1), math.sin(h1)])
        first = 2 if start is not None else 1
        keep = [k for k in range(len(pts) - 1) if k < first or math.dist(pts[k], p1) > 2 * e]
        keep = [k for k in keep if k < first or k < len(pts) - 1]
        pts, w = [pts[k] for k in keep] + [p1 - e * d1, p1], [w[k] for k in keep] + [w1, w1]
    out_p, out_w = [tuple(pts[0].tolist())], [w[0]]
    for p, x in zip(pts[1:], w[1:]):
        if math.dist(out_p[-1], p) > MIN_SEGMENT:
            out_p.append(tuple(p.tolist()))
            out_w.append(x)
    return out_p, out_w


def lane_position(net: Network, lane: str, x: float, y: float) -> tuple[int, float, float] | None:
    """Where a point of the network's frame is on a road that follows recorded lane `lane`: (road id, s, t), s
    along the reference line as written and t the signed distance to its left (lane -1's centre is the reference
    line, so t is the offset from the lane's centre), on the road whose written line has a perpendicular foot of
    the point nearest it, so that (s, t) gives the point back exactly; None where no road follows the lane or
    none has such a foot (a point beyond a bend's outer corner)."""
    best = None
    for r in net.roads:
        if lane in r.lanes and len(r.points) >= 2:
            at = _station(r, x, y, exact=True)
            if at is not None and (best is None or abs(at[1]) < abs(best[2])):
                best = (r.id, at[0], at[1])
    return best


def straight_runs(points) -> list[tuple[tuple[float, float], tuple[float, float]]]:
    """A reference line's segments, runs of them in one direction (within HEADING_TOLERANCE) as one line (ASAM's
    check flags two line geometries in a row with the same heading as redundant): the line geometries written."""
    runs: list[tuple[tuple[float, float], tuple[float, float]]] = []
    start, heading = None, None
    for a, b in zip(points, points[1:]):
        h = math.atan2(b[1] - a[1], b[0] - a[0])
        if start is not None and abs(math.remainder(h - heading, math.tau)) < HEADING_TOLERANCE:
            runs[-1] = (start, b)
            continue
        start, heading = a, h
        runs.append((a, b))
    # ASAM compares the headings as written, each run's chord's, which drift from its first segment's: runs
    # whose chords are within the tolerance are one, until none are (a Waymo map had one such pair)
    merged = True
    while merged:
        merged, out = False, []
        for run in runs:
            if out and abs(math.remainder(_chord(out[-1]) - _chord(run), math.tau)) < HEADING_TOLERANCE:
                out[-1] = (out[-1][0], run[1])
                merged = True
            else:
                out.append(run)
        runs = out
    return runs


def _chord(run: tuple[tuple[float, float], tuple[float, float]]) -> float:
    (x0, y0), (x1, y1) = run
    return math.atan2(y1 - y0, x1 - x0)


def _station(r: Road, x: float, y: float, exact: bool) -> tuple[float, float, np.ndarray, np.ndarray] | None:
    """A point's (s, t) on a road's reference line as written (its straight runs, s summed over their lengths),
    with the reference point and unit direction there: on the run with the point's perpendicular foot nearest
    it; where no run has one (a point beyond a bend's outer corner or an end), None if `exact`, else its
    nearest point's run."""
    runs = straight_runs(r.points)
    a = np.array([p for p, _ in runs], dtype=float)
    b = np.array([q for _, q in runs], dtype=float)
    length = np.hypot(*(b - a).T)
    tangent = (b - a) / length[:, None]
    rel = np.array([x, y]) - a
    u = (rel * tangent).sum(axis=1)
    t = tangent[:, 0] * rel[:, 1] - tangent[:, 1] * rel[:, 0]
    inside = (u >= 0) & (u <= length)
    if inside.any():
        i = int(np.where(inside, np.abs(t), np.inf).argmin())
    elif exact:
        return None
    else:
        u = np.clip(u, 0, length)
        i = int(np.hypot(*(rel - u[:, None] * tangent).T).argmin())
    start = float(np.concatenate([[0.0], np.cumsum(length)])[i])
    return start + float(u[i]), float(t[i]), a[i] + u[i] * tangent[i], tangent[i]
