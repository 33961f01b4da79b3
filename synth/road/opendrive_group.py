"""Same-direction neighbours as lanes of one OpenDRIVE road (docs/formats.md, "OpenDRIVE", "Lanes side by
side"): the roads of synth.road.opendrive.network, one per recorded lane (or piece of one: `cuts` says where a
lane is cut so that pieces side by side begin and end across from each other), grouped where the map records two
lanes as left / right neighbours that run side by side from end to end. Pure.

A group is a chain of single-lane ordinary roads, each the recorded right neighbour of the one before (a map
records it on either side; or a lane continuing one, or a right neighbour of a lane it continues: continued_rights), in the same direction, whose ends are across from each other (each end within ALIGN
of the perpendicular through the first road's end as the cuts measure it, within END_ALIGN of the normal through
the reference line's end as fitted, or within REACH where the road linked there takes the difference and
names the lane). The first (leftmost) road's reference line, with a point at
least every STEP, is the group's; lane -1 keeps its widths; lane -k's centre is where the normal (the bisector at
a vertex) through each point of the reference line meets its centre line, and its width is what puts its centre
there (twice the distance from lane -(k-1)'s right edge). A lane whose width would leave [MIN_WIDTH, MAX_WIDTH],
or whose centre, sampled between the points, would lie farther than TOLERANCE from its centre line, ends the
chain there. Links stay per lane: a group's end links where its lanes link (one road, or one junction: the
junctions its lanes enter are joined), lane links to each lane; where its lanes lead to different roads, the end
is at a junction whose connecting roads are those roads' first (last) NECK metres. The ends of the roads linked
to a lane of a group are moved onto that lane's end (its centre, the reference line's heading, its width). A group
whose ends cannot be linked so, or that meets another group off its lanes' ends, is undone: its lanes stay roads
of their own (counted in the notes), and pieces of a lane cut for grouping that are not grouped are put back
into one road.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import shapely

from synth.road.opendrive_model import NO_MARK, Junction, Link, Road, Side
from synth.road.roadmap import MapFeature

ALIGN = 0.05  # metres: the ends of lanes side by side are this near the perpendicular through the first's end
# metres: a grouped lane's end is at most this far along its line from where the normal through the reference
# line's end meets it (the fit draws it there: the lane's Scenic centre ends that much short of or beyond its
# recorded end, the roads linked to it moved onto it, within the 0.10 m). More than ALIGN: the straight
# 0.05 m end piece in its node's mean heading turns the normal by a degree or two, 0.05-0.07 m across 3.5 m.
END_ALIGN = 0.08
# metres: farther from it (AV2's lanes end on slanted stop lines, a neighbour 0.1-0.3 m on), a grouped lane's end
# is drawn where the normal meets its line (extended straight beyond its end) if the road linked there takes the
# difference: the lane short of its recorded end, the road after (before) it moved onto it and naming both
# recorded lanes; the lane beyond its recorded end, into the one road linked there, and naming both
REACH = 0.5
STEP = 1.0  # metres: a group's reference line has a point at least this often (its lanes' centres are fitted there)
TOLERANCE = 0.05  # metres: a grouped lane's centre from its recorded centre line at most (issue 37 allows 0.10)
NECK = 1.0  # metres: a road's piece that becomes a connecting road where a group's lanes lead to different roads
MIN_NECK = 0.5  # metres: a shorter road's piece (a quarter of it: the rest stays a road) is that piece at least
POSE_TOLERANCE = 0.005  # metres: two grouped lane ends that meet are this near (ASAM allows 0.01)
MIN_WIDTH, MAX_WIDTH = 1.0, 10.0  # metres: a grouped lane's fitted width
SAME_DIRECTION = math.cos(math.radians(30))  # lanes side by side run at most 30 degrees apart
MIN_STEP = 1e-3  # metres: a road's point this near (or behind) its end piece's inner point is dropped when repinned
MIN_PIECE = 1.0  # metres: a lane is cut no nearer its ends or its other cuts (where a neighbour starts or ends)
ROUNDS = 3  # times cuts are passed on to neighbours


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.hypot(v[..., 0], v[..., 1]), 1e-12)[..., None]


def densified(points, widths) -> tuple[np.ndarray, np.ndarray]:
    """A reference line's points with points added on each segment so that none is longer than STEP (widths
    linear between), the original points kept."""
    a, w = np.asarray(points, dtype=float), np.asarray(widths, dtype=float)
    out, ws = [a[:1]], [w[:1]]
    for i in range(len(a) - 1):
        n = max(1, int(math.ceil(math.dist(a[i], a[i + 1]) / STEP)))
        f = np.arange(1, n + 1) / n
        out.append(a[i] + f[:, None] * (a[i + 1] - a[i]))
        ws.append(w[i] + f * (w[i + 1] - w[i]))
    return np.concatenate(out), np.concatenate(ws)


def normals(a: np.ndarray) -> np.ndarray:
    """The unit left normal at each point of a line: its segment's at the ends, the bisector's inside."""
    d = _unit(np.diff(a, axis=0))
    t = _unit(np.concatenate([d[:1], d[:-1] + d[1:], d[-1:]]))
    return np.stack([-t[:, 1], t[:, 0]], axis=1)


def extended(line) -> np.ndarray:
    """A line with REACH metres more at each end, straight on in its end segments' directions."""
    a = np.asarray(line, dtype=float)
    u0, u1 = _unit(a[1] - a[0]), _unit(a[-1] - a[-2])
    return np.concatenate([[a[0] - REACH * u0], a, [a[-1] + REACH * u1]])


def centre_offsets(ref: np.ndarray, line) -> tuple[np.ndarray, tuple[float, float]] | None:
    """The signed offset (left positive) along each point's normal of where it meets `line` (nearest the
    point); at the ends, of `line`'s end point's projection on the normal where that end is within END_ALIGN of
    the normal, else (within REACH) of where the normal meets the line extended (`extended`); and how far the
    line runs on beyond each end of the normal (negative: the normal is beyond the line's end). None where a
    normal misses it or an end is farther than REACH."""
    n = normals(ref)
    other = shapely.LineString(line)
    reach = 3 * MAX_WIDTH
    rays = shapely.linestrings(np.stack([ref - reach * n, ref + reach * n], axis=1))
    cuts = shapely.intersection(rays, other)
    out = np.empty(len(ref))
    for i in range(1, len(ref) - 1):
        if cuts[i].is_empty:
            return None
        pts = shapely.get_coordinates(cuts[i])
        rel = pts - ref[i]
        out[i] = (rel @ n[i])[np.argmin(np.hypot(rel[:, 0], rel[:, 1]))]
    beyond = []
    longer = shapely.LineString(extended(line))
    for i, p, sign in ((0, line[0], -1.0), (len(ref) - 1, line[-1], 1.0)):
        rel = np.asarray(p, dtype=float) - ref[i]
        d = sign * float(rel @ np.array([n[i][1], -n[i][0]]))
        beyond.append(d)
        if abs(d) <= END_ALIGN:
            out[i] = rel @ n[i]
            continue
        meets = shapely.get_coordinates(shapely.intersection(rays[i], longer))
        if abs(d) > REACH or not len(meets):
            return None
        rel = meets - ref[i]
        out[i] = (rel @ n[i])[np.argmin(np.abs(rel @ np.array([n[i][1], -n[i][0]])))]
    return out, (beyond[0], beyond[1])


def lane_centres(ref: np.ndarray, offsets: np.ndarray, samples: int = 4) -> np.ndarray:
    """Points of a lane's centre as OpenDRIVE draws it: each point moved by its offset along its normal, and
    `samples` - 1 points between each two (offset linear, the segment's normal)."""
    n = normals(ref)
    seg = np.stack([-_unit(np.diff(ref, axis=0))[:, 1], _unit(np.diff(ref, axis=0))[:, 0]], axis=1)
    f = np.arange(1, samples) / samples
    inner = (ref[:-1, None] + f[None, :, None] * np.diff(ref, axis=0)[:, None]
             + (offsets[:-1, None] + f[None] * np.diff(offsets)[:, None])[..., None] * seg[:, None])
    return np.concatenate([ref + offsets[:, None] * n, inner.reshape(-1, 2)])


def right_neighbours(lanes: dict[str, MapFeature]) -> dict[str, set[str]]:
    """Each lane's recorded right neighbours among `lanes`: its own, and the lanes naming it their left."""
    rights: dict[str, set[str]] = {}
    for k, f in lanes.items():
        if f.right in lanes:
            rights.setdefault(k, set()).add(f.right)
        if f.left in lanes:
            rights.setdefault(f.left, set()).add(k)
    return rights


def continued_rights(lanes: dict[str, MapFeature]) -> dict[str, set[str]]:
    """Each lane's recorded right neighbours (right_neighbours) and the lanes that continue them (their
    predecessors and successors), and the right neighbours of the lanes it continues: where a neighbour ends a
    metre or two before (after) a lane, the lane's piece beyond it runs beside the neighbour's successor's
    (predecessor's) piece, which the map records as no neighbour of it."""
    rights = right_neighbours(lanes)
    links: dict[str, set[str]] = {k: set() for k in lanes}
    for k, f in lanes.items():
        for x in (*f.successors, *f.predecessors):
            if x in lanes:
                links[k].add(x)
                links[x].add(k)
    out: dict[str, set[str]] = {}
    for k in lanes:
        near = set(rights.get(k, ()))
        near |= {c for n in rights.get(k, ()) for c in links[n]}
        near |= {n for x in links[k] for n in rights.get(x, ())}
        near.discard(k)
        if near:
            out[k] = near
    return out


def neighbours(lines: dict[str, list], lanes: dict[str, MapFeature]) -> dict[str, set[str]]:
    """Each lane of `lines` -> its recorded neighbours (either side) among them that run its way (lines: each
    lane's centre line)."""
    near: dict[str, set[str]] = {}
    for a, bs in right_neighbours(lanes).items():
        for b in bs:
            if a in lines and b in lines and _same_direction(lines[a], lines[b]):
                near.setdefault(a, set()).add(b)
                near.setdefault(b, set()).add(a)
    return near


def cuts(lines: dict[str, list], lanes: dict[str, MapFeature]) -> tuple[dict[str, list[float]], dict[str, tuple]]:
    """Where to cut each lane of `lines` (distances along its line, increasing) so that its pieces begin and end
    across from where its recorded same-direction neighbours (either side) begin, end or are cut: the foot on it
    of each such point, at least MIN_PIECE from its ends and its other cuts, ROUNDS times over (a cut passes on
    to the next neighbour); and where a foot is nearer an end than that but farther than ALIGN, how much of the
    lane to trim at its start and at its end (the most such a foot asks: (head, tail) metres; the trimmed
    piece goes to the lanes linked there, synth.road.opendrive)."""
    near = neighbours(lines, lanes)
    geo = {k: shapely.LineString(lines[k]) for k in near}
    at: dict[str, list[float]] = {k: [] for k in near}
    trim: dict[str, tuple[float, float]] = {}
    points = {k: [tuple(lines[k][0]), tuple(lines[k][-1])] for k in near}
    for _ in range(ROUNDS):
        new = False
        for a in sorted(near):
            for b in sorted(near[a]):
                for p in list(points[b]):
                    point = shapely.Point(p)
                    s = geo[a].project(point)
                    if geo[a].distance(point) > 2 * MAX_WIDTH:
                        continue
                    length = geo[a].length
                    if ALIGN < min(s, length - s) < MIN_PIECE:
                        head, tail = trim.get(a, (0.0, 0.0))
                        trim[a] = (max(head, s), tail) if s < length / 2 else (head, max(tail, length - s))
                        continue
                    if not MIN_PIECE <= s <= length - MIN_PIECE:
                        continue
                    if any(abs(s - x) < MIN_PIECE for x in at[a]):
                        continue
                    at[a].append(s)
                    points[a].append(tuple(shapely.get_coordinates(geo[a].interpolate(s))[0]))
                    new = True
        if not new:
            break
    return {k: sorted(v) for k, v in at.items() if v}, trim


def _same_direction(a, b) -> bool:
    """Whether line b runs the way line a does where they are side by side: their directions within 30 degrees
    at the middle one of a's points within MAX_WIDTH of b and its foot on b (False where none is)."""
    la, lb = shapely.LineString(a), shapely.LineString(b)
    pts = shapely.points(np.asarray(a, dtype=float))
    near = np.flatnonzero(shapely.distance(pts, lb) <= MAX_WIDTH)
    if not len(near):
        return False
    p = pts[near[len(near) // 2]]
    return float(_tangent(la, la.project(p)) @ _tangent(lb, lb.project(p))) >= SAME_DIRECTION


def _tangent(line, s: float) -> np.ndarray:
    """A line's unit direction around s (over a metre)."""
    p, q = (shapely.get_coordinates(line.interpolate(x))[0] for x in (max(0.0, s - 0.5), min(line.length, s + 0.5)))
    return _unit(q - p)


def pairs(roads, lanes: dict[str, MapFeature]) -> dict[int, int]:
    """Each single-lane ordinary road's right partner: the road of a recorded right neighbour of a lane it
    follows (or of a lane naming it as its left neighbour) in the same direction with its ends across (ALIGN),
    nearest."""
    by_lane: dict[str, list] = {}
    for r in roads:  # a road may follow a lane's piece put before (after) another's (synth.road.opendrive)
        if r.junction == -1 and len(r.points) >= 2 and not r.side:
            for lane in r.lanes:
                by_lane.setdefault(lane, []).append(r)
    rights = continued_rights(lanes)
    out: dict[int, int] = {}
    taken: set[int] = set()
    for k in sorted(rights):
        for a in by_lane.get(k, ()):
            line = shapely.LineString(a.points)
            best = None
            for b in (b for n in sorted(rights[k]) for b in by_lane.get(n, ())):
                if b.id in taken or b.id == a.id:
                    continue
                s0, s1 = line.project(shapely.Point(b.points[0])), line.project(shapely.Point(b.points[-1]))
                if s0 > ALIGN or line.length - s1 > ALIGN or not _same_direction(a.points, b.points):
                    continue
                gap = line.distance(shapely.LineString(b.points).interpolate(0.5, normalized=True))
                if gap <= 2 * MAX_WIDTH and (best is None or gap < best[0]):
                    best = (gap, b.id)
            if best is not None:
                out[a.id] = best[1]
                taken.add(best[1])
    return out


def chains(roads, lanes: dict[str, MapFeature]) -> list[list[int]]:
    """Chains of road ids, left to right, each the right partner of the one before (pairs), two or more."""
    right = pairs(roads, lanes)
    has_left = set(right.values())
    out = []
    for a in sorted(right):
        if a in has_left:
            continue
        chain, seen = [a], {a}
        while chain[-1] in right and right[chain[-1]] not in seen:
            chain.append(right[chain[-1]])
            seen.add(chain[-1])
        out.append(chain)
    return out


def fit(chain: list, by_id: dict) -> tuple[np.ndarray, list[np.ndarray], list[np.ndarray], list[tuple]]:
    """A chain's reference line (its first road's, densified), and each lane's centre offsets and widths at its
    points and how far its line runs on beyond each end of the road (centre_offsets), for the longest prefix of
    the chain whose lanes keep the rules (module docstring)."""
    ref, w1 = densified(by_id[chain[0]].points, by_id[chain[0]].widths)
    offsets, widths, beyond = [np.zeros(len(ref))], [w1], [(0.0, 0.0)]
    edge = -w1 / 2  # lane -1's right edge
    for rid in chain[1:]:
        line = np.asarray(by_id[rid].points, dtype=float)
        fitted = centre_offsets(ref, line)
        if fitted is None:
            break
        c, ends = fitted
        w = 2 * (edge - c)
        if w.min() < MIN_WIDTH or w.max() > MAX_WIDTH:
            break
        drawn = shapely.points(lane_centres(ref, c))
        along = shapely.LineString(extended(line) if max(map(abs, ends)) > END_ALIGN else line)
        if float(shapely.distance(drawn, along).max()) > TOLERANCE:
            break
        offsets.append(c)
        widths.append(w)
        beyond.append(ends)
        edge = edge - w
    return ref, offsets, widths, beyond


def end_pose(ref: np.ndarray, offset: np.ndarray, width: np.ndarray, end: int) -> tuple:
    """A grouped lane's pose at the start (0) or end (1) of its road: point, heading, width."""
    i = -1 if end else 0
    n = normals(ref)[i]
    d = ref[-1] - ref[-2] if end else ref[1] - ref[0]
    return (tuple((ref[i] + offset[i] * n).tolist()), math.atan2(d[1], d[0]), float(width[i]))


def repinned(points, widths, end: int, pose) -> tuple[tuple, tuple]:
    """A road's line and widths with the start (0) or end (1) moved onto a pose: its point there, the next one
    the ENDING piece's length on in its heading (the road's points not beyond that one dropped: a pose moved
    along the road)."""
    p = [tuple(x) for x in points]
    w = list(widths)
    if len(p) == 2:  # one segment: a point a quarter of it from the moved end keeps the rest's heading
        f = 0.75 if end else 0.25
        p.insert(1, tuple((np.asarray(p[0]) + f * (np.asarray(p[1]) - np.asarray(p[0]))).tolist()))
        w.insert(1, w[0] + f * (w[1] - w[0]))
    (q, h, width) = pose
    d = np.array([math.cos(h), math.sin(h)])
    if end:
        e = math.dist(p[-1], p[-2])
        keep = [i for i in range(len(p) - 2) if i == 0 or float((np.asarray(q) - p[i]) @ d) > e + MIN_STEP]
        p = [p[i] for i in keep] + [tuple((np.asarray(q) - e * d).tolist()), tuple(q)]
        w = [w[i] for i in keep] + [width, width]
    else:
        e = math.dist(p[0], p[1])
        keep = [i for i in range(2, len(p)) if i == len(p) - 1 or float((np.asarray(p[i]) - q) @ d) > e + MIN_STEP]
        p = [tuple(q), tuple((np.asarray(q) + e * d).tolist())] + [p[i] for i in keep]
        w = [width, width] + [w[i] for i in keep]
    return tuple(p), tuple(w)


def grouped(roads: list[Road], junctions: list[Junction], lanes: dict[str, MapFeature],
            joints: list[tuple[int, int]] = (), halved: set[str] = frozenset()
            ) -> tuple[list[Road], list[Junction], tuple[str, ...]]:
    """The roads with recorded same-direction neighbours side by side grouped into roads of several lanes, the
    junctions' connections from their lanes, and a note on the neighbours left roads of their own (module
    docstring). `joints`: (road, the road after it) where a lane was cut for a neighbour (synth.road.opendrive's
    cuts): one road again where neither piece is grouped; `halved`: the recorded lanes that are a junction's though
    their second halves are roads (synth.road.opendrive: a junction lane followed by another or by none)."""
    by_id = {r.id: r for r in roads}
    fits = {}
    by_lanes = {r.id: r.lanes for r in roads}
    chained, fitted = set(), set()  # the recorded lanes of chains, and of chains fitted (why lanes stay apart)
    for chain in chains(roads, lanes):
        ref, offsets, widths, beyond = fit(chain, by_id)
        chained.update(lane for rid in chain for lane in by_lanes[rid])
        if len(offsets) >= 2:
            fits[chain[0]] = (chain[:len(offsets)], ref, offsets, widths, beyond)
            fitted.update(lane for rid in chain[:len(offsets)] for lane in by_lanes[rid])
    while True:  # undo groups whose ends cannot be linked until none is left
        owner = {rid: (g, -k - 1) for g, (chain, *_) in fits.items() for k, rid in enumerate(chain)}
        root = _joined(fits, by_id)
        bad = [g for g in sorted(fits) if not _linkable(g, fits, by_id, owner, root)]
        bad += _both_ends(roads, fits, by_id, owner, root)
        bad += _necked_twice(fits, by_id, owner, root)
        if not bad:
            break
        del fits[bad[0]]
    # ends whose lanes lead to different roads: through a junction, each such road's first (last) NECK metres
    # its connecting road
    extra: dict[int, list] = {}
    next_junction = max([j.id for j in junctions] + [0]) + 1
    next_road = max(by_id) + 1
    for g in sorted(fits):
        for end in (0, 1):
            necks = _necks(g, end, fits, by_id, owner, root)
            if not necks:
                continue
            joined = {root.get(link.id, link.id) for rid in fits[g][0]
                      if (link := _link(by_id[rid], end)) is not None and link.kind == "junction"}
            if joined:
                j = joined.pop()
            else:
                j, next_junction = next_junction, next_junction + 1
            for rid, x in necks:
                road = by_id[x]
                if end:  # the road after lane rid: its first NECK metres lead from the lane into it
                    (p0, w0), (p1, w1) = _cut(road.points, road.widths, _neck(road))
                    neck = Road(next_road, road.lanes, p0, w0, j, Link("road", rid, "end"), Link("road", x, "start"))
                    by_id[x] = replace(road, points=p1, widths=w1, predecessor=Link("junction", j))
                    by_id[rid] = replace(by_id[rid], successor=Link("junction", j))
                    extra.setdefault(j, []).append((rid, next_road, -1))
                else:  # the road before lane rid: its last NECK metres lead from it into the lane
                    (p0, w0), (p1, w1) = _cut(road.points, road.widths, _length(road.points) - _neck(road))
                    neck = Road(next_road, road.lanes, p1, w1, j, Link("road", x, "end"), Link("road", rid, "start"))
                    by_id[x] = replace(road, points=p0, widths=w0, successor=Link("junction", j))
                    by_id[rid] = replace(by_id[rid], predecessor=Link("junction", j))
                    extra.setdefault(j, []).append((x, next_road, -1))
                by_id[next_road] = neck
                next_road += 1
    junction_of = {}
    for j in junctions + [Junction(j, tuple(c)) for j, c in extra.items()]:
        for inc, _, _ in j.connections:
            junction_of.setdefault(inc, j.id)
    into: dict[int, int] = {}  # a piece put back -> the road it is part of now
    for a, b in joints:
        a = into.get(a, a)
        if a in owner or b in owner or a not in by_id or b not in by_id:
            continue
        ra, rb = by_id[a], by_id[b]
        pre, suc = ra.predecessor, rb.successor
        if ra.successor != Link("road", b, "start") or rb.predecessor != Link("road", a, "end") or (
                pre is not None and suc is not None and pre.kind == suc.kind == "junction"
                and root.get(pre.id, pre.id) == root.get(suc.id, suc.id)):
            continue
        by_id[a] = replace(ra, points=ra.points + rb.points[1:], widths=ra.widths + rb.widths[1:], successor=suc)
        del by_id[b]
        into[b] = a
        for k, r in by_id.items():
            if r.predecessor is not None and r.predecessor.kind == "road" and r.predecessor.id == b:
                by_id[k] = replace(r, predecessor=Link("road", a, r.predecessor.contact))
        for j, conns in extra.items():
            extra[j] = [(a if inc == b else inc, conn, lane) for inc, conn, lane in conns]
        junctions = [Junction(j.id, tuple((a if inc == b else inc, conn, lane) for inc, conn, lane in j.connections))
                     if b in junction_of and junction_of[b] == j.id else j for j in junctions]
    roads = [by_id[k] for k in sorted(by_id)]
    poses = {}  # (road id, end) of a grouped lane right of lane -1 -> its pose in the group
    runs_on = set()  # (road id, end) of a grouped lane whose recorded line runs on beyond its road's end (REACH)
    for chain, ref, offsets, widths, beyond in fits.values():
        for k, rid in enumerate(chain[1:], start=1):
            for end in (0, 1):
                poses[(rid, end)] = end_pose(ref, offsets[k], widths[k], end)
                if beyond[k][end] > END_ALIGN:
                    runs_on.add((rid, end))
    out = []
    for r in roads:
        if r.id in owner and owner[r.id][0] != r.id:
            continue  # a grouped lane right of lane -1: written with its group's road
        if r.id in fits:
            out.append(_group_road(fits[r.id], by_id, owner, root))
            continue
        points, widths_, names = r.points, r.widths, r.lanes
        for end, link in ((0, r.predecessor), (1, r.successor)):
            there = None if link is None or link.kind != "road" else (link.id, 0 if link.contact == "start" else 1)
            if there in poses:
                points, widths_ = repinned(points, widths_, end, poses[there])
            if there in runs_on:  # the grouped lane's piece beyond its road's end is this road's: it names it
                lane = _end_lane(by_id[link.id], there[1])
                names = names + (lane,) if end else (lane,) + names
        pre, pre_lane = _moved(r.predecessor, owner, root)
        suc, suc_lane = _moved(r.successor, owner, root)
        out.append(replace(r, lanes=names, points=points, widths=widths_, predecessor=pre, successor=suc,
                           junction=root.get(r.junction, r.junction), lane_links=((pre_lane, suc_lane),)))
    connections: dict[int, list] = {}
    for j in junctions + [Junction(j, tuple(c)) for j, c in extra.items()]:
        connections.setdefault(root.get(j.id, j.id), []).extend(
            (owner.get(inc, (inc, lane))[0], conn, owner.get(inc, (inc, lane))[1]) for inc, conn, lane in j.connections)
    moved = [Junction(j, tuple(c)) for j, c in sorted(connections.items())]
    kept = {lane for chain, *_ in fits.values() for rid in chain for lane in by_lanes[rid]}
    return out, moved, _apart(roads, lanes, kept, chained, fitted, halved)


APART = ("a junction's lane", "beside junction lanes only", "ends not across", "fitted ends, width or centre off",
         "links not kept in one road")  # why a lane with a recorded same-direction neighbour is a road of its own


def apart_reasons(roads, lanes: dict[str, MapFeature], kept: set, chained: set, fitted: set, halved: set
                  ) -> dict[str, str]:
    """Each recorded lane with a same-direction neighbour that is a lane of no road with one -> why (APART): it
    is a connecting road's (a junction's lane: a fork's, a merge's, an intersection's; `halved`: one whose second
    half is a road), its neighbours are
    (beside junction lanes only), no piece of it is across from a neighbour's piece (ends not across), a chain
    with it was cut short by the fit (fitted ends, width or centre off), or its group was undone (links)."""
    ordinary = {lane for r in roads if r.junction == -1 for lane in r.lanes} - halved
    near = neighbours({k: f.line for k, f in lanes.items()}, lanes)
    out = {}
    for k in sorted(set(near) - kept):
        if k not in ordinary:
            out[k] = APART[0]
        elif not near[k] & ordinary:
            out[k] = APART[1]
        elif k in fitted:
            out[k] = APART[4]
        elif k in chained:
            out[k] = APART[3]
        else:
            out[k] = APART[2]
    return out


def _apart(roads, lanes, kept, chained, fitted, halved) -> tuple[str, ...]:
    """The note on the lanes with a recorded same-direction neighbour left roads of their own, by reason."""
    why = apart_reasons(roads, lanes, kept, chained, fitted, halved)
    if not why:
        return ()
    beside = len(why) + len(kept & {x for a, bs in right_neighbours(lanes).items() for x in (a, *bs)})
    counts = ", ".join(f"{sum(v == r for v in why.values())} {r}" for r in APART if r in why.values())
    return (f"{len(why)} of {beside} lane(s) with a recorded same-direction neighbour are a lane of no road with it "
            f"({counts}; e.g. " + ", ".join(map(repr, sorted(why)[:3])) + ")",)


def _necked_twice(fits, by_id, owner, root) -> list[int]:
    """The groups one of whose ends would cut a connecting road off a road another group end cuts one off too
    (the second cut would find the road changed: shorter, or its other end at a junction)."""
    seen: dict[int, int] = {}
    out = []
    for g in sorted(fits):
        for end in (0, 1):
            for _, x in _necks(g, end, fits, by_id, owner, root) or ():
                if seen.setdefault(x, g) != g:
                    out.append(g)
    return out


def _joined(fits, by_id) -> dict[int, int]:
    """Junction id -> the junction it is joined into: the junctions a group's lanes lead into (or come from) at
    one end are one junction (a road links to one junction at each end)."""
    parent: dict[int, int] = {}

    def find(x: int) -> int:
        while parent.get(x, x) != x:
            x = parent[x]
        return x

    for chain, *_ in fits.values():
        for end in (0, 1):
            ids = sorted({link.id for rid in chain
                          if (link := by_id[rid].successor if end else by_id[rid].predecessor) is not None
                          and link.kind == "junction"})
            for j in ids[1:]:
                a, b = find(ids[0]), find(j)
                if a != b:
                    parent[max(a, b)] = min(a, b)
    return {j: find(j) for j in parent}


def _both_ends(roads, fits, by_id, owner, root) -> list[int]:
    """The groups whose joining of junctions leaves a road (a group's, or one of its own) with both ends at one
    junction (Scenic's parser refuses it)."""
    out = []
    for r in roads:
        if r.junction != -1 or r.predecessor is None or r.successor is None:
            continue
        if r.id in owner:
            chain = fits[owner[r.id][0]][0]
            pre = {_moved(by_id[x].predecessor, owner, root)[0] for x in chain} - {None}
            suc = {_moved(by_id[x].successor, owner, root)[0] for x in chain} - {None}
        else:
            pre, suc = {_moved(r.predecessor, owner, root)[0]}, {_moved(r.successor, owner, root)[0]}
        if {x.id for x in pre if x.kind == "junction"} & {x.id for x in suc if x.kind == "junction"}:
            joined = {j for j, k in root.items() if k in {x.id for x in pre | suc}} | {x.id for x in pre | suc}
            out += [g for g, (chain, *_) in fits.items() if any(
                (link := getattr(by_id[x], side)) is not None and link.kind == "junction" and link.id in joined
                for x in chain for side in ("predecessor", "successor"))]
    return sorted(set(out))


def _end_lane(road: Road, end: int) -> str:
    """The recorded lane a road follows at its start (0) or end (1)."""
    return road.lanes[-1] if end else road.lanes[0]


def _link(road: Road, end: int) -> Link | None:
    return road.successor if end else road.predecessor


def _length(points) -> float:
    return float(np.hypot(*np.diff(np.asarray(points, dtype=float), axis=0).T).sum())


def _cut(points, widths, at: float) -> tuple[tuple[tuple, tuple], tuple[tuple, tuple]]:
    """A line and its widths cut `at` metres along it, inside a segment (so that both pieces have one heading
    where they meet)."""
    a = np.asarray(points, dtype=float)
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(a, axis=0).T))])
    i = min(int(np.searchsorted(s, at, side="right")) - 1, len(a) - 2)
    f = min(max((at - s[i]) / (s[i + 1] - s[i]), 0.01), 0.99)
    p = tuple((a[i] + f * (a[i + 1] - a[i])).tolist())
    w = widths[i] + f * (widths[i + 1] - widths[i])
    first = (tuple(map(tuple, a[:i + 1].tolist())) + (p,), tuple(widths[:i + 1]) + (w,))
    second = ((p,) + tuple(map(tuple, a[i + 1:].tolist())), (w,) + tuple(widths[i + 1:]))
    return first, second


def _neck(road: Road) -> float:
    """How much of a road led to from a group's lane becomes a connecting road: NECK, at most a quarter of it."""
    return min(NECK, _length(road.points) / 4)


def _necks(g, end: int, fits, by_id, owner, root) -> list[tuple[int, int]] | None:
    """A group end whose lanes lead to different roads, as (lane's road, road) pairs whose roads' first (last)
    NECK metres become connecting roads of one junction at that end; [] where the end needs none; None where it
    cannot be had: a road led to is grouped, shorter than 4 NECK, or would have both ends at that junction, or
    the group's other end is at it."""
    chain = fits[g][0]
    targets = [t for t in _targets(chain, by_id, owner, root, end) if t is not None]
    into = [lane for _, lane in targets if lane is not None]
    if len({t for t, _ in targets}) <= 1 and len(into) == len(set(into)):
        return []
    joined = {t[1] for t, _ in targets if t[0] == "junction"}
    other = {t[1] for t, _ in (x for x in _targets(chain, by_id, owner, root, 1 - end) if x is not None)
             if t[0] == "junction"}
    if len(joined) > 1 or joined & other:
        return None
    out = []
    for rid in chain:
        link = _link(by_id[rid], end)
        if link is None or link.kind != "road":
            continue
        x = by_id[link.id]
        far = _link(x, end)
        if link.id in owner or x.junction != -1 or _length(x.points) < 4 * MIN_NECK or len(x.points) < 4 or (
                far is not None and far.kind == "junction" and root.get(far.id, far.id) in joined):
            return None
        out.append((rid, link.id))
    return out


def _moved(link: Link | None, owner: dict, root: dict) -> tuple[Link | None, int | None]:
    """A link to a road as a link to the road its lane is grouped into, and that lane (-1 for a road of one lane;
    None for a junction or no link); a link to a junction as one to the junction it is joined into."""
    if link is not None and link.kind == "junction":
        return Link("junction", root.get(link.id, link.id)), None
    if link is None or link.kind != "road":
        return link, None
    if link.id not in owner:
        return link, -1
    g, lane = owner[link.id]
    return Link("road", g, link.contact), lane


def _targets(chain, by_id, owner, root, end: int) -> list:
    """What each lane of a chain links to at one end: (kind, id, contact) with the lane, or None."""
    out = []
    for rid in chain:
        link = by_id[rid].successor if end else by_id[rid].predecessor
        moved, lane = _moved(link, owner, root)
        out.append(None if moved is None else ((moved.kind, moved.id, moved.contact), lane))
    return out


def _linkable(g, fits, by_id, owner, root) -> bool:
    """Whether a group's ends link as one road's can (one target for all its lanes at each end, each lane to a
    lane of its own) and meet the grouped lanes they link to (POSE_TOLERANCE)."""
    chain, ref, offsets, widths, beyond = fits[g]
    for end in (0, 1):
        targets = [t for t in _targets(chain, by_id, owner, root, end) if t is not None]
        into = [lane for _, lane in targets if lane is not None]
        necks = _necks(g, end, fits, by_id, owner, root)
        if (len({t for t, _ in targets}) > 1 or len(into) != len(set(into))) and necks is None:
            return False
        for k, rid in enumerate(chain):
            link = _link(by_id[rid], end)
            d = beyond[k][end]
            if abs(d) > END_ALIGN and (link is None or d < 0 and (
                    link.kind != "road" or necks or _length(by_id[link.id].points) < -d + MIN_PIECE)):
                return False  # no road there takes the lane's piece beyond (short of) the road's end
        for k, rid in enumerate(chain):
            link = by_id[rid].successor if end else by_id[rid].predecessor
            if link is None or link.kind != "road" or link.id not in owner or owner[link.id][0] == g:
                continue
            other = fits[owner[link.id][0]]
            there = 0 if link.contact == "start" else 1
            a = end_pose(ref, offsets[k], widths[k], end)
            b = end_pose(other[1], other[2][-owner[link.id][1] - 1], other[3][-owner[link.id][1] - 1], there)
            if math.dist(a[0], b[0]) > POSE_TOLERANCE or abs(a[2] - b[2]) > POSE_TOLERANCE:
                return False
    return True


def _group_road(fitted, by_id, owner, root) -> Road:
    """A group's road: its first road's id, marks and links, its fitted reference line and lanes."""
    chain, ref, offsets, widths, beyond = fitted
    first = by_id[chain[0]]
    ends = [_targets(chain, by_id, owner, root, end) for end in (0, 1)]
    link = []
    for targets in ends:
        kinds = [t for t in targets if t is not None]
        link.append(None if not kinds else Link(kinds[0][0][0], kinds[0][0][1], kinds[0][0][2]))
    lane_links = tuple((p[1] if p is not None else None, s[1] if s is not None else None)
                       for p, s in zip(*ends))
    side = []
    for k, rid in enumerate(chain[1:], start=1):
        r = by_id[rid]
        mark = r.marks[1]
        names = r.lanes
        for end, linked in ((0, r.predecessor), (1, r.successor)):
            if beyond[k][end] < -END_ALIGN:  # drawn on beyond its recorded end, over the road linked there
                there = _end_lane(by_id[linked.id], 0 if linked.contact == "start" else 1)
                names = names + (there,) if end else (there,) + names
        side.append(Side(names, tuple(widths[k].tolist()), mark))
    between = first.marks[1] if first.marks[1] != NO_MARK else by_id[chain[1]].marks[0]
    return Road(first.id, first.lanes, tuple(map(tuple, ref.tolist())), tuple(widths[0].tolist()), -1, link[0],
                link[1], (first.marks[0], between), tuple(side), lane_links)
