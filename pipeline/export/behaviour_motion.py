"""`r2s export SCENE --steps T --program P.json`: a frame's entities moved over T steps of 0.1 s by the behaviours
of its clip program (`r2s synth A.json B.json ... --behaviours --format json`), not on at their first speed
(docs/formats.md, "Exported clips"). Kinematic, deterministic, on the scene's road (its ego frame):

- the pace sets the speed over each segment (its duration the middle of its Range): `stopped` 0, `slowing to a
  stop` linear down to 0, `cruising Range(a, b)` the speed held within [a, b], `speeding up` / `slowing down`
  linear from there to b / a; after the last segment the speed is held;
- the path sets where it goes: `following lane` along its lane's centre line (the lane of its lane fact), at the
  offset from the centre it starts at, on into the successor that turns least at each lane's end; `turning
  left` / `right` the same, into the successor that turns most that way; `changing lanes left` / `right` onto
  the neighbour's centre line, its offset from it shrinking linearly to 0 over the segment; a `heading` path, or
  an entity in no lane, straight on along its heading. The last segment's path goes on after it;
- `parked`: it stays; an entity without a behaviour goes on at its speed along its heading (as without
  --program).

Values only: no I/O."""

from __future__ import annotations

import math
from bisect import bisect_left, bisect_right
from dataclasses import dataclass

import numpy as np

from pipeline.errors import UserError
from pipeline.export.motion import BEHAVIOURS, Motion, Trajectory, steps_of
from pipeline.simulation import read_program_json
from synth.behaviour.kinds import (
    ChangingLanes,
    Cruising,
    FollowingLane,
    Pace,
    SlowingDown,
    SlowingToAStop,
    SpeedingUp,
    Stopped,
    Turning,
)
from synth.behaviour.program import Behaviour, ClipProgram
from synth.geometry import heading_vector
from synth.road.roadmap import LANE, RoadMap
from synth.scene import Entity, Scene
from synth.world import WorldPose, in_world

TIME_EPS = 1e-9  # seconds: a step's time this near a segment boundary is at it (0.1 k is not exact in floats)
MAX_LANES = 1000  # lanes a route may chain (a route of 10,000 steps at 40 m/s is 4 km: a few hundred lanes)


@dataclass(frozen=True)
class Behaviours:
    """A clip program given to `r2s export --program`, its text, and the frame it starts at (its JSON's
    `first_frame`)."""

    program: ClipProgram
    program_text: str
    first_frame: str


def read_behaviours(text: str, where: str) -> Behaviours | None:
    """--program's text as a clip program when it is JSON (r2s synth --behaviours --format json; anything else in
    JSON one line), None for DSL or Scenic text (named in the metadata only, as before)."""
    if not text.lstrip().startswith("{"):
        return None
    program, _, doc = read_program_json(text, where)
    if not isinstance(doc.get("first_frame"), str):
        raise UserError(f"{where} names no first_frame: give the JSON r2s synth A.json B.json ... --behaviours "
                        "--format json writes")
    return Behaviours(program, doc["program"], doc["first_frame"])


def check_program_of(b: Behaviours, scene: Scene, where: str) -> None:
    """The program is the recorded frame's: its clip starts at this frame, and each entity it gives a behaviour
    and that is in the frame is one of the frame's. One line otherwise."""
    if b.first_frame != scene.frame_id:
        raise UserError(f"{where} is the behaviour program of a clip starting at frame {b.first_frame!r}, not at "
                        f"{scene.frame_id!r}: give the program r2s synth --behaviours wrote for a clip starting at it")
    ids = {e.id for e in scene.entities}
    stray = next((x.id for x in b.program.behaviours if x.after is None and x.id not in ids), None)
    if stray is not None:
        raise UserError(f"{where} gives {stray!r} a behaviour from the clip's first frame, and {scene.frame_id!r} "
                        "has no such entity: give the program of this frame's clip")


def by_behaviours(scene: Scene, world: WorldPose, b: Behaviours, steps: int) -> Motion:
    """Every entity of the scene over `steps` steps of 0.1 s, moved by its behaviour (module docstring)."""
    t = steps_of(steps)
    out = []
    for e in scene.entities:
        behaviour = b.program.behaviour(e.id)
        xs, ys, hs, vs = _move(e, behaviour, scene.road, t)
        w = in_world(world, e)
        wx, wy = np.empty(steps), np.empty(steps)
        for k in range(steps):
            wx[k], wy[k] = world.point(xs[k], ys[k])
        wx[0], wy[0] = w.x, w.y  # the frame itself exactly
        yaw = np.array([world.yaw(h) for h in hs])
        out.append(Trajectory(e.id, e.type, w.length, w.width, wx, wy, yaw, vs, np.ones(steps, dtype=bool)))
    return Motion(t, tuple(out), BEHAVIOURS)


# ------------------------------------------------------------------------------------------------------ pace
def _speeds(pace_segments: list[tuple[Pace, float]], v0: float, t: np.ndarray) -> np.ndarray:
    """The speed at each time: each segment's pace from the speed it starts at, over its duration."""
    ends, starts, v = [], [], v0
    for pace, d in pace_segments:
        starts.append(v)
        v = _pace_at(pace, v, d, d)
        ends.append(v)
    bounds = np.cumsum([d for _, d in pace_segments]) if pace_segments else np.array([])
    out = np.empty(len(t))
    for k, tk in enumerate(t):
        i = bisect_left(list(bounds), tk - TIME_EPS)  # a boundary's time ends its segment (the checker's too)
        if i >= len(pace_segments):
            out[k] = ends[-1] if ends else v0
        else:
            t0 = bounds[i - 1] if i else 0.0
            out[k] = _pace_at(pace_segments[i][0], starts[i], tk - t0, pace_segments[i][1])
    return out


def _pace_at(pace: Pace, v0: float, tau: float, d: float) -> float:
    """The speed `tau` seconds into a segment of `d` seconds that starts at v0."""
    a = min(1.0, tau / d) if d > 0 else 1.0
    if isinstance(pace, Stopped):
        return 0.0
    if isinstance(pace, SlowingToAStop):
        return v0 * (1.0 - a)
    assert isinstance(pace, Cruising)
    r = pace.range
    start = min(max(v0, r.lo), r.hi)
    if isinstance(pace, SpeedingUp):
        return start + (r.hi - start) * a
    if isinstance(pace, SlowingDown):
        return start + (r.lo - start) * a
    return start


# ------------------------------------------------------------------------------------------------------ path
@dataclass
class _Route:
    """A chain of lanes' centre lines as one polyline (ego frame), growing as it is driven."""

    road: RoadMap
    lanes: list[str]
    pts: np.ndarray  # (n, 2)
    s: np.ndarray  # arc length at each point

    @classmethod
    def of(cls, road: RoadMap, lane: str) -> _Route:
        pts = np.asarray(road[lane].line, dtype=float)
        return cls(road, [lane], pts, _arc(pts))

    def extend(self, side: str) -> bool:
        """Chain the last lane's successor that turns least (side `straight`) or most to `side`; False at a dead
        end (no successor on the road, or MAX_LANES chained)."""
        nexts = [n for n in self.road[self.lanes[-1]].successors if n in self.road and self.road[n].kind == LANE
                 and len(self.road[n].line) >= 2]
        if not nexts or len(self.lanes) >= MAX_LANES:
            return False
        key = {"straight": lambda n: abs(_turn(self.road[n].line)), "left": lambda n: -_turn(self.road[n].line),
               "right": lambda n: _turn(self.road[n].line)}[side]
        lane = min(sorted(nexts), key=key)
        pts = np.asarray(self.road[lane].line, dtype=float)
        if np.allclose(pts[0], self.pts[-1]):
            pts = pts[1:]
        if not len(pts):
            return False
        self.lanes.append(lane)
        self.pts = np.vstack([self.pts, pts])
        self.s = _arc(self.pts)
        return True

    def project(self, x: float, y: float) -> tuple[float, float]:
        """(arc length, signed offset to the left) of the point's nearest foot on the polyline."""
        a, b = self.pts[:-1], self.pts[1:]
        ab = b - a
        L2 = np.maximum((ab ** 2).sum(axis=1), 1e-12)
        u = np.clip(((np.array([x, y]) - a) * ab).sum(axis=1) / L2, 0.0, 1.0)
        foot = a + ab * u[:, None]
        d2 = ((foot - [x, y]) ** 2).sum(axis=1)
        i = int(np.argmin(d2))
        cross = ab[i, 0] * (y - a[i, 1]) - ab[i, 1] * (x - a[i, 0])
        return float(self.s[i] + u[i] * math.sqrt(L2[i])), math.copysign(math.sqrt(d2[i]), cross)

    def at(self, s: float, offset: float, side: str) -> tuple[float, float, float]:
        """The point `offset` metres left of the line at arc length s, and the line's direction there (radians
        from +x); beyond a dead end, straight on along the last piece."""
        while s > self.s[-1] and self.extend(side):
            pass
        i = min(max(int(np.searchsorted(self.s, s, side="right")) - 1, 0), len(self.pts) - 2)
        a, b = self.pts[i], self.pts[i + 1]
        seg = max(self.s[i + 1] - self.s[i], 1e-12)
        u = (s - self.s[i]) / seg  # beyond the ends: extrapolated along the first / last piece
        ang = math.atan2(b[1] - a[1], b[0] - a[0])
        px, py = a + (b - a) * u
        return px - offset * math.sin(ang), py + offset * math.cos(ang), ang


def _arc(pts: np.ndarray) -> np.ndarray:
    return np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))])


def _turn(line) -> float:
    """A lane's signed turn (radians, left positive): its last piece's direction less its first's."""
    (x0, y0), (x1, y1) = line[0], line[1]
    (x2, y2), (x3, y3) = line[-2], line[-1]
    return math.remainder(math.atan2(y3 - y2, x3 - x2) - math.atan2(y1 - y0, x1 - x0), math.tau)


def _move(e: Entity, behaviour: Behaviour | None, road: RoadMap | None, t: np.ndarray):
    """(x, y, heading in degrees CCW from +y, speed) at each time, in the scene's ego frame."""
    n = len(t)
    v0 = e.speed or 0.0
    if behaviour is not None and behaviour.parked:
        return [e.x] * n, [e.y] * n, [e.heading] * n, np.zeros(n)
    segments = [] if behaviour is None else [(s, (s.duration.lo + s.duration.hi) / 2.0) for s in behaviour.segments]
    speeds = _speeds([(s.pace, d) for s, d in segments], v0, t) if segments else np.full(n, v0)
    bounds = list(np.cumsum([d for _, d in segments]))
    xs, ys, hs = [e.x], [e.y], [e.heading]
    route, along, offset, side, change = None, 0.0, 0.0, "straight", None
    lane = e.lane if road is not None and e.lane in road and road[e.lane].kind == LANE \
        and len(road[e.lane].line) >= 2 else None
    current = -1
    for k in range(1, n):
        i = min(bisect_right(bounds, t[k - 1] + TIME_EPS), len(segments) - 1)  # the segment the step starts in
        if i != current and segments:  # a segment starts: its path decides the route
            current = i
            path = segments[i][0].path
            side = path.side if isinstance(path, Turning) else "straight"
            if isinstance(path, (FollowingLane, Turning, ChangingLanes)) and lane is not None:
                if route is None:
                    route = _Route.of(road, lane)
                    along, offset = route.project(xs[-1], ys[-1])
                if isinstance(path, ChangingLanes):
                    here = route.lanes[min(bisect_right(list(_starts(route)), along) - 1, len(route.lanes) - 1)]
                    target = road[here].left if path.side == "left" else road[here].right
                    if target is not None and target in road and len(road[target].line) >= 2:
                        route = _Route.of(road, target)
                        along, offset = route.project(xs[-1], ys[-1])
                        t0 = bounds[i - 1] if i else 0.0
                        change = (t0, segments[i][1], offset)
            else:
                route = None
        step = (speeds[k - 1] + speeds[k]) / 2.0 * (t[k] - t[k - 1])
        if route is None:
            fx, fy = heading_vector(hs[-1])
            xs.append(xs[-1] + fx * step)
            ys.append(ys[-1] + fy * step)
            hs.append(hs[-1])
            continue
        along += step
        if change is not None:
            t0, d, d0 = change
            offset = d0 * max(0.0, 1.0 - (t[k] - t0) / d) if d > 0 else 0.0
        x, y, ang = route.at(along, offset, side)
        xs.append(x)
        ys.append(y)
        hs.append(math.degrees(ang) - 90.0)
    return xs, ys, hs, speeds


def _starts(route: _Route) -> list[float]:
    """The arc length at which each lane of the route starts."""
    out, s = [], 0.0
    for lane in route.lanes:
        out.append(s)
        s += float(_arc(np.asarray(route.road[lane].line, dtype=float))[-1])
    return out
