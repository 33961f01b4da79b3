"""Simulated variants of a clip program (docs/scenic.md, "Simulated variants"; `r2s simulate`): what a variant may
vary, and the dynamic Scenic scenario that draws it.

A moving entity's speed is piecewise linear between its segments' boundaries; the speeds u_0 .. u_m at the
boundaries are the variant's draw. They obey every pace of the behaviour (a `SpeedPlan`: each boundary's box from
the Ranges, stops and V_STOP of the segments on either side of it, and the rises and falls of at least DV of
`speeding up` / `slowing down` between two boundaries), a convex set that holds the recorded boundary speeds r.
Scenic draws a point q of the boxes and a fraction f uniformly; the variant's speeds are r + f * t * (q - r), t the
largest step in [0, 1] toward q that keeps every constraint (`feasible`), so every draw obeys the plan and the
draws cover the segment from r toward every point of the boxes. u_0 is the recorded speed (the first frame's
relational program may bound it). Durations and turns are the recorded ones (the boundary samples' times and the
summed signed turn of each segment's steps). Values in, text out; the Scenic text imports `feasible` from here.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from synth.behaviour.kinds import Cruising, SlowingDown, SlowingToAStop, SpeedingUp, Stopped
from synth.behaviour.kinds import Heading as HeadingPath
from synth.behaviour.program import Behaviour
from synth.behaviour.scenic import STEER, num, placed, speed_bound
from synth.behaviour.track import Clip, Track
from synth.config import SynthConfig
from synth.patterns.temporal import turn_of

# A row (i, a, j, b, c): a * u_i + b * u_j <= c.
Row = tuple[int, float, int, float, float]


@dataclass(frozen=True)
class SpeedPlan:
    """The boundary speeds a variant of one behaviour may take: recorded speeds r, boxes [lo, hi] (lo = hi = r at
    the first boundary), and rows a * u_i + b * u_j <= c between neighbours."""

    recorded: tuple[float, ...]
    lo: tuple[float, ...]
    hi: tuple[float, ...]
    rows: tuple[Row, ...]

    def holds(self, u: Sequence[float], eps: float = 1e-9) -> bool:
        """Does u obey the plan (within eps)?"""
        return (all(lo - eps <= x <= hi + eps for x, lo, hi in zip(u, self.lo, self.hi))
                and all(a * u[i] + b * u[j] <= c + eps for i, a, j, b, c in self.rows))


def speed_plan(behaviour: Behaviour, boundaries: Sequence[int], track: Track, config: SynthConfig) -> SpeedPlan:
    """The plan of a behaviour's segments on the track's boundary samples (module docstring)."""
    r = [track.samples[b].speed for b in boundaries]
    lo, hi = [0.0] * len(r), [math.inf] * len(r)
    rows: list[Row] = []

    def cap(k: int, low: float, high: float) -> None:
        lo[k], hi[k] = max(lo[k], low), min(hi[k], high)

    for j, seg in enumerate(behaviour.segments):
        pace = seg.pace
        if isinstance(pace, Stopped):
            cap(j, 0.0, config.v_stop)
            cap(j + 1, 0.0, config.v_stop)
        elif isinstance(pace, SlowingToAStop):
            # above V_STOP at its start (strictly: halfway from V_STOP to the recorded speed), at most at its end;
            # a linear fall between never rises
            cap(j, (config.v_stop + r[j]) / 2, math.inf)
            cap(j + 1, 0.0, config.v_stop)
        elif isinstance(pace, Cruising):  # speeding up and slowing down too: every speed in the Range
            cap(j, pace.range.lo, pace.range.hi)
            cap(j + 1, pace.range.lo, pace.range.hi)
            if isinstance(pace, SpeedingUp):  # u_j - u_{j+1} <= -DV: a linear rise never falls
                rows.append((j, 1.0, j + 1, -1.0, -config.dv))
            elif isinstance(pace, SlowingDown):
                rows.append((j + 1, 1.0, j, -1.0, -config.dv))
    lo[0] = hi[0] = r[0]
    # A boundary no pace bounds above (none between two paces can be: a stop and a start share none) keeps r.
    hi = [h if math.isfinite(h) else max(x, low) for h, x, low in zip(hi, r, lo)]
    return SpeedPlan(tuple(r), tuple(lo), tuple(hi), tuple(rows))


def feasible(recorded: Sequence[float], lo: Sequence[float], hi: Sequence[float], rows: Sequence[Row],
             q: Sequence[float], f: float) -> list[float]:
    """r + f * t * (q - r), t the largest step in [0, 1] from the recorded speeds r toward q that keeps the boxes and
    the rows (each is linear: t is the least ratio of a constraint's slack to its growth along q - r)."""
    r = list(recorded)
    d = [a - b for a, b in zip(q, r)]
    t = 1.0
    limits = [(k, 1.0, k, 0.0, h) for k, h in enumerate(hi)] + [(k, -1.0, k, 0.0, -x) for k, x in enumerate(lo)]
    for i, a, j, b, c in [*limits, *rows]:
        grows = a * d[i] + b * d[j]
        if grows > 0:
            t = min(t, max(0.0, c - (a * r[i] + b * r[j])) / grows)
    return [x + f * t * y for x, y in zip(r, d)]


def turns(boundaries: Sequence[int], track: Track) -> list[float]:
    """Each segment's summed signed turn (radians CCW) between its boundary samples."""
    s = track.samples
    return [math.radians(sum(turn_of(s[k].heading, s[k + 1].heading) for k in range(a, b)))
            for a, b in zip(boundaries, boundaries[1:])]


# The behaviour of a variant's moving entity: its boundary speeds drawn (feasible), then per segment the speed
# linear from one boundary's to the next's and the heading turning at a steady rate, at the boundaries' steps.
PRELUDE = STEER + '''
from synth.behaviour.variants import feasible

def r2s__states(objects):
    """Each object's place, heading (its walking direction for a walker), speed: what r2s simulate writes."""
    out = []
    for o in objects:
        control = getattr(o, "control", None) or {}
        heading = control.get("heading")
        out.append((o.position.x, o.position.y, o.heading if heading is None else heading, o.velocity.norm()))
    return out

def r2s__along(path, s):
    """The point at arc length s along a polyline ((x, y), ...), past its end straight on along its last piece."""
    for i in range(len(path) - 1):
        x0, y0 = path[i]
        x1, y1 = path[i + 1]  # (not `by`: a Scenic keyword)
        piece = math.hypot(x1 - x0, y1 - y0)
        if s <= piece or i == len(path) - 2:
            share = s / piece if piece > 0 else 0
            return x0 + (x1 - x0) * share, y0 + (y1 - y0) * share
        s -= piece
    return path[-1]

behavior R2sVariant(ends, turns, recorded, lo, hi, rows, q, f, walks, path):
    speeds = feasible(recorded, lo, hi, rows, q, f)
    heading = self.heading
    travelled = 0
    dt = simulation().timestep
    for j in range(len(turns)):
        start, a, b = heading, ends[j], ends[j + 1]
        for k in range(a, b):
            share = (k + 1 - a) / (b - a)
            speed = speeds[j] + (speeds[j + 1] - speeds[j]) * share
            heading = start + turns[j] * share
            if path is not None:
                # along the recorded path: where this step ends (the car moves on its present heading), aim at the
                # path's point one more step on
                travelled += speed * dt
                ahead = self.position + Vector(0, speed).rotatedBy(self.heading) * dt
                tx, ty = r2s__along(path, travelled + speed * dt)
                if math.hypot(tx - ahead.x, ty - ahead.y) > 1e-6:
                    heading = math.atan2(-(tx - ahead.x), ty - ahead.y)
            if walks:
                take SetWalkingDirectionAction(heading), SetWalkingSpeedAction(speed)
            else:
                error = (heading - self.heading + math.pi) % (2 * math.pi) - math.pi
                take SetSpeedAction(speed), SetSteerAction(r2s__steer(self, speed, error / dt))
    while True:
        take SetSpeedAction(0) if not walks else SetWalkingSpeedAction(0)
'''


@dataclass(frozen=True)
class Simulated:
    """A clip's variant scenario: its Scenic text, the entities it places (in order: the records' order), the
    simulation step (s) and the step of each of the clip's frames."""

    text: str
    placed: tuple[str, ...]
    timestep: float
    frame_steps: tuple[int, ...]

    @property
    def steps(self) -> int:
        return self.frame_steps[-1]


def path_of(behaviour: Behaviour, track: Track, clip: Clip) -> str:
    """The recorded path a moving vehicle follows by arc length (its world positions at its samples, Scenic text), so
    that a variant at other speeds keeps the recording's lanes; `None` (heading by time, the recorded turns) where
    some segment is a `heading` Range, which only the recorded arc of headings keeps, and for a walker."""
    if track.type == "Pedestrian" or any(isinstance(s.path, HeadingPath) for s in behaviour.segments):
        return "None"
    rows = [scene.ego if track.id == "ego" else scene.by_id().get(track.id) for scene in clip.scenes]
    points = [scene.world.point(e.x, e.y) for scene, e in zip(clip.scenes, rows) if e is not None]
    return "[" + ", ".join(f"({num(x)}, {num(y)})" for x, y in points) + "]"


def simulation_step(times: Sequence[float], most: float = 0.1) -> float:
    """The simulation step: the clip's least frame interval divided into equal steps of at most `most` seconds, so
    every frame falls on a step (within half a step: recorded intervals jitter)."""
    least = min((b - a for a, b in zip(times, times[1:])), default=most)
    return least / math.ceil(least / most - 1e-9)


def variant_scenic(header: str, behaviours: Sequence[Behaviour], boundaries: Sequence[Sequence[int]], clip: Clip,
                   xodr: str, config: SynthConfig) -> Simulated:
    """The dynamic Scenic scenario of a clip program's variants (module docstring): every entity of the clip's first
    frame at its recorded pose in the world (as synth.behaviour.scenic places it), each moving one (not parked, a
    car or a pedestrian) running R2sVariant with its plan and its draws, `require always` its speed bound,
    `terminate after` the clip's length. `behaviours` and `boundaries`: one each per track of the clip, in order."""
    first = clip.scenes[0]
    dt = simulation_step(clip.times)
    frame_steps = tuple(round(t / dt) for t in clip.times)
    lines = [f"# {header}",
             "# Simulated variants (r2s simulate; docs/scenic.md): every entity of the first frame at its recorded pose "
             "in the world, each moving one's boundary speeds drawn within its paces.",
             f"param map = {xodr!r}", "param render = False",
             "model scenic.simulators.newtonian.driving_model", "", PRELUDE]
    by_id, names = first.by_id(), []
    for behaviour, bounds, track in zip(behaviours, boundaries, clip.tracks):
        if not track.from_start:
            continue
        e = first.ego if track.id == "ego" else by_id[track.id]
        cls, where = placed(e, first.world)
        if not behaviour.parked and cls != "Object":
            plan = speed_plan(behaviour, bounds, track, config)
            ends = [frame_steps[clip.times.index(track.samples[b].t)] for b in bounds]
            draws = ", ".join(num(lo) if lo == hi else f"Range({num(lo)}, {num(hi)})" for lo, hi in zip(plan.lo, plan.hi))
            args = [repr(ends), "[" + ", ".join(num(t) for t in turns(bounds, track)) + "]",
                    *("[" + ", ".join(num(v) for v in vs) + "]" for vs in (plan.recorded, plan.lo, plan.hi)),
                    "[" + ", ".join(f"({i}, {num(a)}, {j}, {num(b)}, {num(c)})" for i, a, j, b, c in plan.rows) + "]",
                    f"[{draws}]", "Range(0, 1)", "True" if cls == "Pedestrian" else "False", path_of(behaviour, track, clip)]
            where += f", with speed {num(plan.recorded[0])}, with behavior R2sVariant({', '.join(args)})"
        lines.append(f"{track.id} = {where}")
        names.append(track.id)
        if cls != "Object":
            top = speed_bound(behaviour, track, config.v_stop)
            lines.append(f"require always {track.id}.speed <= {num(top + 0.01)}  # its paces")
    lines.append(f"record r2s__states([{', '.join(names)}]) as r2s_states")
    lines.append(f"terminate after {num(frame_steps[-1] * dt)} seconds")
    return Simulated("\n".join(lines) + "\n", tuple(names), dt, frame_steps)
