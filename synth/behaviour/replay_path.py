"""The path a car's replay drives (docs/scenic.md, "Behaviour programs"): per segment, the polyline its PATH kind
names on the clip's road, not the recording's places. Values in, values out.

- `following lane`, `turning left/right` and `stopped` (no PATH: where it stands): the centre lines of the
  recorded lanes the segment visits (its samples' lane facts, the segment's recorded parameters) along the
  road's links: a route from its first sample's lane, extended by each later sample's lane linked after it
  (`_parts`: in an intersection lane facts flip between overlapping lanes, the route keeps to linked ones), cut
  between the projections of its first sample on its first lane and of its last on that sample's lane (the
  point of the first where that would go backward). Samples in no lane (a turn's, in an intersection) are
  skipped.
- `changing lanes left/right`: the lanes before the segment's first lane move (source) and after its last one
  (target), each a route as above, blended linearly from the source's to the target's over the segment: the
  target's centre line between the segment's first and last samples' projections, its point at share u moved
  to (1 - u) times its nearest point of the source's plus u times itself (both extended straight past their
  ends).
- `heading Range`, a segment whose samples name no lane of the clip's road, and a car with none:
  the recorded places, as before.

The path starts where its first piece starts (the car, placed at its recorded pose, is brought onto it by the
steering). Each segment's length is the length of its piece along the path, from the previous piece's end (the
pieces join). Coordinates are those of the places given (the world less the road file's offset, as the scenario's)."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from shapely.geometry import LineString, Point
from shapely.ops import substring

from synth.behaviour.kinds import ChangingLanes, FollowingLane, Path, Turning
from synth.behaviour.scenic_common import track_points
from synth.behaviour.segmentation import Segmented
from synth.behaviour.track import Clip, Track

XY = tuple[float, float]
BLEND_STEP_M = 1.0  # metres between the points of a lane change's blend (the steering aims 2 m ahead)


@dataclass(frozen=True)
class ReplayPath:
    """A car's replay path (a polyline) and each segment's length along it (metres)."""

    points: tuple[XY, ...]
    lengths: tuple[float, ...]


def _line(points: Sequence[XY]) -> LineString | None:
    unique = [p for k, p in enumerate(points) if k == 0 or p != points[k - 1]]
    return LineString(unique) if len(unique) >= 2 else None


ROUTE_LANES = 4  # the most lanes a route adds at once to reach a sample's lane (a turn: intersection, exit)


@dataclass(frozen=True)
class Lanes:
    """The road's lanes as a replay path reads them: each lane's centre line (None: no lane of the road, or
    one too short to have a direction) and the lanes linked after it."""

    line: Callable[[str], LineString | None]
    successors: Callable[[str], Sequence[str]]

    def route(self, start: str, goal: str) -> list[str] | None:
        """The fewest lanes from start to goal along the links (both ends included, at most ROUTE_LANES added;
        ties: the least ids, breadth first over sorted successors); None where no such route links them."""
        paths = {start: [start]}
        frontier = [start]
        for _ in range(ROUTE_LANES):
            if goal in paths:
                break
            nxt = []
            for lane in frontier:
                for n in self.successors(lane):
                    if n not in paths and self.line(n) is not None:
                        paths[n] = paths[lane] + [n]
                        nxt.append(n)
            frontier = nxt
        return paths.get(goal)


def _parts(visited: Sequence[tuple[int, str]], lanes: Lanes) -> list[tuple[list[str], int, int]]:
    """A segment's laned samples as parts, each a route along the road's links and its first and last sample.
    A sample's lane on the route, or linked after its end, extends it; a lane neither (a lane fact flipping to
    an overlapping lane in an intersection) is passed over while a later sample's lane extends the route, else
    (links the road does not hold) a new part starts there."""
    parts: list[tuple[list[str], int, int]] = []
    route, first, last = [visited[0][1]], visited[0][0], visited[0][0]

    def extends(lane: str) -> list[str] | None:
        return [] if lane in route else (lanes.route(route[-1], lane) or [None])[1:] or None

    for j, (k, lane) in enumerate(visited[1:], start=1):
        more = extends(lane)
        if more is not None:
            route += more
            last = k
        elif not any(extends(later) is not None for _, later in visited[j + 1:]):
            parts.append((route, first, last))
            route, first, last = [lane], k, k
    parts.append((route, first, last))
    return parts


def _lane_piece(places: Sequence[XY], visited: Sequence[tuple[int, str]], lanes: Lanes) -> list[XY]:
    """The centre lines of a segment's routes (_parts), each cut between the projections of its first sample on
    its first lane and of its last sample on that sample's lane; [] without a laned sample. visited: (sample,
    lane) of the segment's samples in a lane of the road."""
    if not visited:
        return []
    at = dict(visited)
    out: list[XY] = []
    for route, first, last in _parts(visited, lanes):
        coords: list[XY] = []
        offset = {}
        for lane in route:
            line = lanes.line(lane)
            offset[lane] = _length(coords + [line.coords[0]])
            coords += [tuple(c) for c in line.coords]
        whole = _line(coords)
        s0 = lanes.line(route[0]).project(Point(places[first]))
        end = at[last]
        s1 = offset[end] + lanes.line(end).project(Point(places[last]))
        if whole is None or s1 <= s0:  # going nowhere along it (stopped; a lane fact one step back)
            p = lanes.line(route[0]).interpolate(s0)
            out.append((p.x, p.y))
        else:
            out += [tuple(c) for c in substring(whole, s0, s1).coords]
    return out


def _extended_at(line: LineString, s: float) -> np.ndarray:
    """The point at arc length s along a line, straight on past either end along its end piece."""
    xy = np.asarray(line.coords)
    if s < 0:
        d = xy[0] - xy[1]
        return xy[0] + d / np.linalg.norm(d) * -s
    if s > line.length:
        d = xy[-1] - xy[-2]
        return xy[-1] + d / np.linalg.norm(d) * (s - line.length)
    p = line.interpolate(s)
    return np.array([p.x, p.y])


def _projection(line: LineString, p: XY) -> float:
    """The arc length of p's projection on a line extended straight past its ends (negative before its start)."""
    xy = np.asarray(line.coords)
    s = line.project(Point(p))
    if s <= 0:
        d = (xy[1] - xy[0]) / np.linalg.norm(xy[1] - xy[0])
        return float(min(0.0, np.dot(np.asarray(p) - xy[0], d)))
    if s >= line.length:
        d = (xy[-1] - xy[-2]) / np.linalg.norm(xy[-1] - xy[-2])
        return line.length + float(max(0.0, np.dot(np.asarray(p) - xy[-1], d)))
    return s


def _blend(source: LineString, target: LineString, first: XY, last: XY) -> list[XY]:
    """From the source lane's centre line to the target's, linearly over the span of first .. last (module
    docstring): the target's centre line from first's projection to last's, a point every BLEND_STEP_M or so,
    each at share u of it moved to (1 - u) times its nearest point of the source's line plus u times itself
    (nearest points, not equal shares: on a curve the inner lane is the shorter)."""
    t0, t1 = _projection(target, first), _projection(target, last)
    n = max(2, math.ceil(max(t1 - t0, 0.0) / BLEND_STEP_M) + 1)
    out = []
    for k in range(n):
        u = k / (n - 1)
        q = _extended_at(target, t0 + (t1 - t0) * u)
        p = (1 - u) * _extended_at(source, _projection(source, (float(q[0]), float(q[1])))) + u * q
        out.append((float(p[0]), float(p[1])))
    return out


def _change_piece(places: Sequence[XY], visited: Sequence[tuple[int, str]], lanes: Lanes,
                  moved: Sequence[bool], a: int, b: int) -> list[XY]:
    """A lane change's blend from the lanes before its first move to those after its last (module docstring)."""
    steps = [k for k in range(a, b) if moved[k]]
    source = _line(_lane_piece(places, [v for v in visited if v[0] <= steps[0]], lanes))
    target = _line(_lane_piece(places, [v for v in visited if v[0] > steps[-1]], lanes))
    # a run too short to give a direction: its lane's centre line whole
    source = source or lanes.line(dict(visited)[steps[0]])
    target = target or lanes.line(dict(visited)[steps[-1] + 1])
    return _blend(source, target, places[a], places[b])


def replay_points(places: Sequence[XY], lanes_of: Sequence[str | None], lanes: Lanes, kinds: Sequence[str],
                  moved: Sequence[bool], boundaries: Sequence[int]) -> ReplayPath:
    """The replay path of a track (module docstring). places, lanes_of: per sample (a lane None or without a
    centre line in `lanes`: in no lane); kinds: per segment, "lane" (following lane, turning, stopped), "change"
    (changing lanes) or "recorded"; moved: per step, whether it moves to a neighbour lane's chain and does not
    keep the lane; boundaries: the segments' boundary samples."""
    laned = [lane if lane is not None and lanes.line(lane) is not None else None for lane in lanes_of]
    points: list[XY] = []
    lengths = []
    for kind, a, b in zip(kinds, boundaries, boundaries[1:]):
        visited = [(k, laned[k]) for k in range(a, b + 1) if laned[k] is not None]
        piece: list[XY] = []
        if kind == "change" and len(visited) == b - a + 1 and any(moved[a:b]):
            piece = _change_piece(places, visited, lanes, moved, a, b)
        elif kind in ("lane", "change"):
            piece = _lane_piece(places, visited, lanes)
        if not piece:
            piece = list(places[a:b + 1])
        lengths.append(_length(points[-1:] + piece))  # from the previous piece's end: the pieces join
        points += piece
    kept = [p for k, p in enumerate(points) if k == 0 or p != points[k - 1]]
    return ReplayPath(tuple(kept), tuple(lengths))


def _length(points: Sequence[XY]) -> float:
    return float(sum(math.hypot(x1 - x0, y1 - y0) for (x0, y0), (x1, y1) in zip(points, points[1:])))


def segment_kind(path: Path | None) -> str:
    """What a segment's PATH lets the replay drive: "lane" (following lane, turning, and stopped: the recorded
    lanes' centre lines), "change" (changing lanes: a blend), "recorded" (heading Range: the recorded places)."""
    if path is None or isinstance(path, (FollowingLane, Turning)):
        return "lane"
    return "change" if isinstance(path, ChangingLanes) else "recorded"


def replay_path(segmented: Segmented, track: Track, clip: Clip,
                offset: tuple[float, float] = (0.0, 0.0)) -> ReplayPath:
    """A car's replay path on the clip's road (the road its frames hold, the one its .xodr is fitted to), in the
    world less `offset` (the road file's origin): module docstring."""
    graph, world = clip.graph, clip.scenes[0].world
    lines: dict[str, LineString | None] = {}

    def line(lane: str) -> LineString | None:
        if lane not in lines:
            f = graph.lane(lane) if graph is not None else None
            lines[lane] = None if f is None else _line(
                [(x - offset[0], y - offset[1]) for x, y in (world.point(*p) for p in f.line)])
        return lines[lane]

    lanes = Lanes(line, graph.successors if graph is not None else lambda lane: ())
    steps = track.steps
    moved = [(left or right) and not keep for keep, left, right in zip(steps.keep, steps.left, steps.right)]
    kinds = [segment_kind(s.path) for s in segmented.behaviour.segments]
    return replay_points(track_points(track, clip, offset), [s.lane for s in track.samples], lanes, kinds, moved,
                         segmented.boundaries)


__all__ = ["Lanes", "ReplayPath", "replay_path", "replay_points", "segment_kind"]
