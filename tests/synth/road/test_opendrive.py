"""synth.road.opendrive on random lane graphs (hypothesis): straight lanes between points of a grid, each lane's
successors the lanes that start where it ends, some marked intersection lanes, some links between lanes that do
not meet. Checked against the graph itself, not against the module's own rules: every recorded link is kept (the
next road of a road, or a connecting road's lane after its incoming road's, names the successor), links are
mutual and meet end to end in one heading and width (what ASAM's gap check and a driving car need), junction
connections agree with the roads' links, no road has both ends at one junction, and every road lies on the
lanes it names."""

from __future__ import annotations

import math

import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from synth.road.opendrive import network
from synth.road.roadmap import LANE, MapFeature, RoadMap

GRID = [(x * 20.0, y * 20.0) for x in range(3) for y in range(3)]


@st.composite
def lane_graphs(draw):
    edges = draw(st.lists(st.tuples(st.integers(0, 8), st.integers(0, 8)).filter(lambda e: e[0] != e[1]),
                          min_size=1, max_size=12, unique=True))
    far = draw(st.sets(st.integers(0, len(edges) - 1), max_size=2))  # lanes that start 3 m off their point
    feats = []
    for n, (i, j) in enumerate(edges):
        (x0, y0), (x1, y1) = GRID[i], GRID[j]
        if n in far:
            x0 += 3.0
        line = ((x0, y0), ((x0 + x1) / 2, (y0 + y1) / 2), (x1, y1))
        poly = tuple(shapely.LineString(line).buffer(1.75, cap_style="flat").exterior.coords)[:-1]
        succ = tuple(f"L{m}" for m, (a, _) in enumerate(edges) if a == j and m != n)
        feats.append(MapFeature("m", f"L{n}", LANE, polygon=poly, line=line, successors=succ,
                                is_intersection=draw(st.booleans())))
    return RoadMap.of("m", feats)


def _end(points, at_start: bool):
    (a, b) = (points[0], points[1]) if at_start else (points[-1], points[-2])
    return a, math.atan2(b[1] - a[1], b[0] - a[0]) if at_start else math.atan2(a[1] - b[1], a[0] - b[0])


@settings(max_examples=60, deadline=None)
@given(lane_graphs())
def test_every_recorded_link_is_kept_and_linked_roads_meet(road):
    net = network(road)
    roads = {r.id: r for r in net.roads}
    follows = set()
    for r in net.roads:
        follows.update(zip(r.lanes, r.lanes[1:]))
        nxt = r.successor
        if nxt is not None and nxt.kind == "road":
            o = roads[nxt.id]
            # the road after a connecting road names its junction; any other road names the road before it
            back = ("junction", r.junction) if r.junction != -1 else ("road", r.id)
            assert nxt.contact == "start" and (o.predecessor.kind, o.predecessor.id) == back
            follows.add((r.lanes[-1], o.lanes[0]))
            (p, h), (q, g) = _end(r.points, False), _end(o.points, True)
            assert math.dist(p, q) < 1e-9 and abs(math.remainder(h - g, math.tau)) < 1e-9
            assert abs(r.widths[-1] - o.widths[0]) < 1e-9
        assert not (r.junction == -1 and r.successor is not None and r.predecessor is not None
                    and r.successor.kind == r.predecessor.kind == "junction" and r.successor.id == r.predecessor.id)
        # every point of a road lies on the recorded lanes it names (and the gaps between them it bridges), but
        # for the straight 0.05 m at a linked end in the meeting lanes' mean heading
        named = [shapely.LineString(road[n].line) for n in r.lanes]
        named += [shapely.LineString([road[a].line[-1], road[b].line[0]]) for a, b in zip(r.lanes, r.lanes[1:])]
        world = [(x + net.offset[0], y + net.offset[1]) for x, y in r.points]  # back from the recentring
        assert shapely.distance(shapely.points(world), shapely.union_all(named)).max() < 0.06
    for j in net.junctions:
        for incoming, connecting, _ in j.connections:
            inc, con = roads[incoming], roads[connecting]
            assert inc.successor.kind == "junction" and inc.successor.id == j.id and con.junction == j.id
            assert con.predecessor.kind == "road" and con.predecessor.id == incoming
            follows.add((inc.lanes[-1], con.lanes[0]))
            (p, h), (q, g) = _end(inc.points, False), _end(con.points, True)
            assert math.dist(p, q) < 1e-9 and abs(math.remainder(h - g, math.tau)) < 1e-9
    for f in road.lanes:
        for s in f.successors:
            assert (f.feature_id, s) in follows


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(-3e-6, 3e-6), min_size=1, max_size=30), st.lists(st.floats(0.5, 30.0), min_size=31,
                                                                         max_size=31))
def test_straight_runs_leave_no_two_written_lines_in_one_heading(turns, lengths):
    """A line turning by up to a few micro-radians a segment (nearly straight: where runs merge): the runs
    written have no two in a row whose chords' headings ASAM's redundancy check (1e-6, unwrapped, as it
    compares them) would call one, they join end to end, and every point lies on them within length x 1e-6."""
    from synth.road.opendrive import straight_runs

    pts, h = [(0.0, 0.0)], 0.3
    for turn, length in zip(turns + [0.0], lengths):
        h += turn
        pts.append((pts[-1][0] + length * math.cos(h), pts[-1][1] + length * math.sin(h)))
    runs = straight_runs(pts)
    assert runs[0][0] == pts[0] and runs[-1][1] == pts[-1]
    assert all(a[1] == b[0] for a, b in zip(runs, runs[1:]))
    chords = [math.atan2(q[1] - p[1], q[0] - p[0]) for p, q in runs]
    assert all(abs(a - b) >= 1e-6 for a, b in zip(chords, chords[1:]))
    line = shapely.LineString([runs[0][0]] + [q for _, q in runs])
    assert max(line.distance(shapely.Point(p)) for p in pts) <= 1e-6 * sum(lengths) + 1e-9
