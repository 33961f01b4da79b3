"""Simulated variants of a clip program (docs/scenic.md, "Simulated variants"; `r2s simulate`): what a variant may
vary, and the dynamic Scenic scenario that draws it.

A moving entity's speed is piecewise linear within each segment, through a knot at its half-time that makes the
profile's area the segment's recorded length (`knot`, `profile`: every segment ends where the recorded one did);
the speeds u_0 .. u_m at the boundaries are the variant's draw. They obey every pace of the behaviour (a `SpeedPlan`: each boundary's box from
the Ranges, stops and V_STOP of the segments on either side of it, and the rises and falls of at least DV of
`speeding up` / `slowing down` between two boundaries, and rows that keep each knot in its pace, dropped for an
entity whose recorded speeds do not obey them), a convex set that holds the recorded boundary speeds r.
Scenic draws a point q of the boxes and a fraction f uniformly; the variant's speeds are r + f * t * (q - r), t the
largest step in [0, 1] toward q that keeps every constraint (`feasible`), so every draw obeys the plan and the
draws cover the segment from r toward every point of the boxes.
u_0 is the recorded speed (the first frame's relational program may bound it). Durations are the recorded ones (the
boundary samples' times); each moving entity's place is the point of its recorded places at the arc length its
segment has covered (`along`, `pose_at`), its heading the recorded one there, set each step (R2sPose), so paths,
turns and `heading` Ranges hold as recorded; what this construction does not decide (the lanes between two
recorded places) Scenic requires (synth.behaviour.variant_lanes), with the pace bounds at every step
(`within_paces`). Values in, text out; the Scenic text imports `along`, `feasible`, `knot`, `pose_at` and
`within_paces` from here.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from synth.behaviour.kinds import EPS, Cruising, SlowingDown, SlowingToAStop, SpeedingUp, Stopped
from synth.behaviour.program import Behaviour
from synth.behaviour.scenic import speed_bound
from synth.behaviour.scenic_common import num, placed, track_points
from synth.behaviour.track import Clip, Track
from synth.behaviour.variant_lanes import LaneRule, lane_rule
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
    means: tuple[float | None, ...] = ()  # per segment: its mean speed (length / duration), None: unkept

    def holds(self, u: Sequence[float], eps: float = 1e-9) -> bool:
        """Does u obey the plan (within eps)?"""
        return (all(lo - eps <= x <= hi + eps for x, lo, hi in zip(u, self.lo, self.hi))
                and all(a * u[i] + b * u[j] <= c + eps for i, a, j, b, c in self.rows))

    def knots(self, u: Sequence[float]) -> list[float]:
        """Each segment's speed at its half-time (`knot`)."""
        return [knot(u[j], u[j + 1], m) for j, m in enumerate(self.means or [None] * (len(u) - 1))]


def knot(u: float, w: float, mean: float | None) -> float:
    """The speed at a segment's half-time that makes the piecewise-linear profile u -> knot -> w have the mean speed
    `mean` (its area (u + 2 knot + w) / 4 * T is the segment's length); a straight line u -> w where mean is None."""
    return (u + w) / 2 if mean is None else 2 * mean - (u + w) / 2


def profile(u: float, m: float, w: float, duration: float, tau: float) -> tuple[float, float]:
    """(speed, distance covered) at time tau in [0, duration] of a segment whose speed is linear from u to m over
    its first half and from m to w over its second (exact integrals: the car's place along its path)."""
    half = duration / 2
    if tau <= half:
        return u + (m - u) * tau / half, u * tau + (m - u) * tau * tau / duration
    x = tau - half
    return m + (w - m) * x / half, (u + m) * half / 2 + m * x + (w - m) * x * x / duration


def speed_plan(behaviour: Behaviour, boundaries: Sequence[int], track: Track, config: SynthConfig,
               means: Sequence[float] | None = None) -> SpeedPlan:
    """The plan of a behaviour's segments on the track's boundary samples (module docstring). `means`: each
    segment's mean speed to keep (its recorded length along its path over its duration); kept only where the
    recorded boundary speeds obey the plan with them (else the plan is the one without, and the segment's
    length varies with the draw)."""
    r = [track.samples[b].speed for b in boundaries]
    lo, hi = [0.0] * len(r), [math.inf] * len(r)
    rows: list[Row] = []
    kept: list[Row] = []  # the rows that keep each segment's length: on its knot (knot)

    def knot_within(j: int, mean: float, low: float, high: float) -> None:
        # low <= 2 mean - (u_j + u_j+1) / 2 <= high, as two rows on u_j + u_j+1
        kept.append((j, 1.0, j + 1, 1.0, 2 * (2 * mean - low)))
        if math.isfinite(high):
            kept.append((j, -1.0, j + 1, -1.0, -2 * (2 * mean - high)))

    def knot_between(j: int, mean: float, rising: bool) -> None:
        # u_j <= knot <= u_j+1 (rising) or u_j >= knot >= u_j+1: a profile through its knot never turns back
        sign = 1.0 if rising else -1.0
        kept.append((j, sign * 1.5, j + 1, sign * 0.5, sign * 2 * mean))
        kept.append((j, -sign * 0.5, j + 1, -sign * 1.5, -sign * 2 * mean))

    def cap(k: int, low: float, high: float) -> None:
        lo[k], hi[k] = max(lo[k], low), min(hi[k], high)

    for j, seg in enumerate(behaviour.segments):
        pace = seg.pace
        mean = None if means is None else means[j]
        if mean is not None:
            if isinstance(pace, Stopped):
                knot_within(j, mean, 0.0, config.v_stop)
            elif isinstance(pace, SlowingToAStop):
                knot_within(j, mean, 0.0, math.inf)
                knot_between(j, mean, rising=False)
            elif isinstance(pace, Cruising):
                knot_within(j, mean, pace.range.lo, pace.range.hi)
                if isinstance(pace, (SpeedingUp, SlowingDown)):
                    knot_between(j, mean, rising=isinstance(pace, SpeedingUp))
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
    plan = SpeedPlan(tuple(r), tuple(lo), tuple(hi), tuple(rows + kept), tuple(means or ()))
    if means is not None and plan.holds(r, 1e-6):
        return plan
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


def along(u: float, m: float, w: float, duration: float, tau: float, length: float) -> tuple[float, float]:
    """(speed, length covered along the recorded path) at time tau in [0, duration] of a segment of recorded length
    `length`: the speed is the profile's (u -> m -> w), the place its distance scaled to the segment's length (so
    the segment ends where the recorded one ended, whatever the draw). Where the plan keeps the segment's mean
    speed the scale is 1 (the place is the speed's integral); where the recorded speeds disagree with the recorded
    places it is the ratio of the two, as in the recording; a profile that covers nothing moves at a steady rate."""
    speed, covered = profile(u, m, w, duration, tau)
    area = profile(u, m, w, duration, duration)[1]
    if area > 1e-9:
        return speed, length * covered / area
    return speed, length * (tau / duration if duration > 0 else 1.0)


def pose_at(points: Sequence[tuple[float, float]], arcs: Sequence[float], headings: Sequence[float], lo: int,
            hi: int, s: float) -> tuple[float, float, float]:
    """(x, y, heading) at arc length s along the recorded places points[lo .. hi] (arcs: each place's arc length
    along the whole path; headings: each sample's, unwrapped), both linear between two samples; s at or past
    arcs[hi] is sample hi. Within one segment's samples, so its headings are the segment's."""
    if s >= arcs[hi]:
        return points[hi][0], points[hi][1], headings[hi]
    for i in range(lo, hi):
        if s < arcs[i + 1]:
            share = max(0.0, s - arcs[i]) / (arcs[i + 1] - arcs[i])
            (x0, y0), (x1, y1) = points[i], points[i + 1]
            return (x0 + (x1 - x0) * share, y0 + (y1 - y0) * share,
                    headings[i] + (headings[i + 1] - headings[i]) * share)
    return points[hi][0], points[hi][1], headings[hi]


def arc_lengths(points: Sequence[tuple[float, float]]) -> list[float]:
    """Each place's arc length along the polyline of the places."""
    out = [0.0]
    for (x0, y0), (x1, y1) in zip(points, points[1:]):
        out.append(out[-1] + math.hypot(x1 - x0, y1 - y0))
    return out


def scenic_headings(track: Track) -> list[float]:
    """Each sample's heading in Scenic's frame (radians, 0 along +y), unwrapped by the signed turn of each step (so
    a heading between two samples turns the way the recording did)."""
    s = track.samples
    out = [math.radians(s[0].heading - 90.0)]
    for a, b in zip(s, s[1:]):
        out.append(out[-1] + math.radians(turn_of(a.heading, b.heading)))
    return out


# The behaviour of a variant's moving entity: its boundary speeds drawn (feasible), then per segment the speed
# through its knot and the place along the recorded path (`along`), the pose set each step by R2sPose: the
# entity moves along its recorded places and headings (`pose_at`) at the drawn speeds, within what the recording
# did, rather than steering (a Newtonian car turns at most ~3.8 deg per 0.1 s step at 3 m/s; recorded headings
# turn faster).
PRELUDE = '''
import math
from scenic.core.dynamics.actions import Action
from scenic.syntax.veneer import simulationInProgress
from synth.behaviour.variants import along, feasible, knot, pose_at, within_paces

def r2s__states(objects):
    """Each object's place, heading (its walking direction for a walker), speed: what r2s simulate writes."""
    out = []
    for o in objects:
        control = getattr(o, "control", None) or {}
        heading = control.get("heading")
        out.append((o.position.x, o.position.y, o.heading if heading is None else heading, o.velocity.norm()))
    return out

def r2s__now():
    """The simulation's step (0 while Scenic checks the requirements on the scene it drew, before simulating)."""
    return simulation().currentTime if simulationInProgress() else 0

class R2sPose(Action):
    """At the step's end the entity stands at (x, y), facing heading (a walker: walking that way) at speed: its
    velocity set along the heading and its place set one step back along it, which the step then integrates."""

    def __init__(self, x, y, heading, speed):
        self.x, self.y, self.heading, self.speed = x, y, heading, speed

    def applyTo(self, obj, sim):
        velocity = Vector(0, self.speed).rotatedBy(self.heading)
        obj.heading = self.heading
        obj.position = Vector(self.x, self.y) - velocity * sim.timestep
        obj.velocity = velocity
        if getattr(obj, "control", None) is not None:
            obj.control = {"heading": self.heading, "speed": self.speed}
        else:
            obj.steer, obj.throttle, obj.brake = 0, 0, 0

def r2s__lanes(states):
    """The lane rules (synth.behaviour.variant_lanes.LaneWatch, the parameter r2s_lanes) at this step."""
    return not simulationInProgress() or globalParameters.r2s_lanes.holds(simulation().currentTime, states)

behavior R2sStill(x, y, heading):
    while True:
        take R2sPose(x, y, heading, 0)

behavior R2sVariant(ends, recorded, lo, hi, rows, means, q, f, path, arcs, headings, samples):
    speeds = feasible(recorded, lo, hi, rows, q, f)
    dt = simulation().timestep
    for j in range(len(ends) - 1):
        a, b = ends[j], ends[j + 1]
        first, last = samples[j], samples[j + 1]
        duration = (b - a) * dt
        length = arcs[last] - arcs[first]
        middle = knot(speeds[j], speeds[j + 1], means[j])
        for k in range(a, b):
            speed, covered = along(speeds[j], middle, speeds[j + 1], duration, (k + 1 - a) * dt, length)
            x, y, heading = pose_at(path, arcs, headings, first, last, arcs[first] + covered)
            take R2sPose(x, y, heading, speed)
    x, y, heading = pose_at(path, arcs, headings, samples[-1], samples[-1], arcs[samples[-1]])
    while True:
        take R2sPose(x, y, heading, 0)
'''


def pace_bounds(behaviour: Behaviour, config: SynthConfig) -> list[tuple[float, float]]:
    """Each segment's speed bounds over its whole time (m/s): its Range (cruising, speeding up, slowing down), up
    to V_STOP where stopped, none where it slows to a stop (its fall is the profile's by construction; the entity's
    top speed is required apart: speed_bound)."""
    out = []
    for seg in behaviour.segments:
        if isinstance(seg.pace, Cruising):
            out.append((seg.pace.range.lo, seg.pace.range.hi))
        elif isinstance(seg.pace, Stopped):
            out.append((0.0, config.v_stop))
        else:
            out.append((0.0, math.inf))
    return out


def within_paces(step: int, speed: float, ends: Sequence[int], bounds: Sequence[tuple[float, float]]) -> bool:
    """Is `speed` at simulation step `step` within the bounds of every segment whose steps hold it (both at a
    boundary; none after the last), within the checker's EPS? What Scenic requires always of a moving entity."""
    return all(lo - EPS <= speed <= hi + EPS for a, b, (lo, hi) in zip(ends, ends[1:], bounds) if a <= step <= b)


def listed(values: Sequence[float]) -> str:
    return "[" + ", ".join(num(v) for v in values) + "]"


@dataclass(frozen=True)
class Simulated:
    """A clip's variant scenario: its Scenic text, the entities it places (in order: the records' order), the
    simulation step (s) and the step of each of the clip's frames."""

    text: str
    placed: tuple[str, ...]
    timestep: float
    frame_steps: tuple[int, ...]
    offset: tuple[float, float] = (0.0, 0.0)  # the road file's origin in the world: Scenic's (0, 0)
    lane_rules: tuple[LaneRule, ...] = ()  # what Scenic requires of lanes (the parameter r2s_lanes: a LaneWatch)

    @property
    def steps(self) -> int:
        return self.frame_steps[-1]


def segment_means(points: Sequence[tuple[float, float]], boundaries: Sequence[int],
                  ends: Sequence[int], dt: float) -> list[float]:
    """Each segment's mean speed in the simulation: its recorded length along the path (the polyline through the
    points, as R2sVariant measures it) over its simulated duration (its steps times dt)."""
    arcs = arc_lengths(points)
    return [(arcs[b] - arcs[a]) / max((e1 - e0) * dt, dt)
            for a, b, e0, e1 in zip(boundaries, boundaries[1:], ends, ends[1:])]


def simulation_step(times: Sequence[float], most: float = 0.1) -> float:
    """The simulation step: the clip's least frame interval divided into equal steps of at most `most` seconds, so
    every frame falls on a step (within half a step: recorded intervals jitter)."""
    least = min((b - a for a, b in zip(times, times[1:])), default=most)
    return least / math.ceil(least / most - 1e-9)


def variant_scenic(header: str, behaviours: Sequence[Behaviour], boundaries: Sequence[Sequence[int]], clip: Clip,
                   xodr: str, config: SynthConfig, offset: tuple[float, float] = (0.0, 0.0)) -> Simulated:
    """The dynamic Scenic scenario of a clip program's variants (module docstring): every entity of the clip's first
    frame at its recorded pose in the world (as synth.behaviour.scenic places it), each moving one (not parked)
    running R2sVariant with its plan and its draws, each parked one R2sStill; `require always` its speed bound, its
    segments' pace bounds and their lane rules (the LaneWatch of `lane_rules`), `terminate after` the clip's
    length. `behaviours` and `boundaries`: one each per track of the clip, in order."""
    first = clip.scenes[0]
    dt = simulation_step(clip.times)
    frame_steps = tuple(round(t / dt) for t in clip.times)
    lines = [f"# {header}",
             "# Simulated variants (r2s simulate; docs/scenic.md): every entity of the first frame at its recorded pose "
             "in the world, each moving one's boundary speeds drawn within its paces.",
             f"param map = {xodr!r}", "param render = False",
             "param r2s_lanes = None",
             "model scenic.simulators.newtonian.driving_model", "", PRELUDE]
    by_id, names, rules = first.by_id(), [], []
    for behaviour, bounds, track in zip(behaviours, boundaries, clip.tracks):
        if not track.from_start:
            continue
        e = first.ego if track.id == "ego" else by_id[track.id]
        _, where = placed(e, first.world, offset)
        if not behaviour.parked:
            ends = [frame_steps[clip.times.index(track.samples[b].t)] for b in bounds]
            points = track_points(track, clip, offset)
            plan = speed_plan(behaviour, bounds, track, config, segment_means(points, bounds, ends, dt))
            means = plan.means or [None] * (len(bounds) - 1)
            draws = ", ".join(num(lo) if lo == hi else f"Range({num(lo)}, {num(hi)})" for lo, hi in zip(plan.lo, plan.hi))
            args = [repr(ends), *(listed(vs) for vs in (plan.recorded, plan.lo, plan.hi)),
                    "[" + ", ".join(f"({i}, {num(a)}, {j}, {num(b)}, {num(c)})" for i, a, j, b, c in plan.rows) + "]",
                    "[" + ", ".join("None" if m is None else num(m) for m in means) + "]",
                    f"[{draws}]", "Range(0, 1)",
                    "[" + ", ".join(f"({num(x)}, {num(y)})" for x, y in points) + "]",
                    listed(arc_lengths(points)), listed(scenic_headings(track)), repr(list(bounds))]
            where += f", with speed {num(plan.recorded[0])}, with behavior R2sVariant({', '.join(args)})"
            rule = lane_rule(track.id, len(names), [clip.times.index(x.t) for x in track.samples], bounds,
                             [seg.path for seg in behaviour.segments])
            rules += [rule] if rule is not None else []
        else:
            # still at its place, at its recorded first speed in the first frame (the relational program reads it)
            x, y = track_points(track, clip, offset)[0]
            where += (f", with speed {num(track.samples[0].speed)}, with behavior R2sStill({num(x)}, {num(y)}, "
                      f"{num(scenic_headings(track)[0])})")
        lines.append(f"{track.id} = {where}")
        names.append(track.id)
        if not behaviour.parked:
            # the speed the checker reads (the velocity's norm, as recorded) at every step, not only the frames'
            paces = ", ".join(f"({num(lo)}, {'math.inf' if math.isinf(hi) else num(hi)})"
                              for lo, hi in pace_bounds(behaviour, config))
            lines.append(f"require always within_paces(r2s__now(), {track.id}.velocity.norm(), "
                         f"{ends!r}, [{paces}])  # each segment's pace")
        top = speed_bound(behaviour, track, config.v_stop)
        lines.append(f"require always {track.id}.speed <= {num(top + 0.01)}  # its paces")
    lines.append(f"record r2s__states([{', '.join(names)}]) as r2s_states")
    if rules:
        lines.append(f"require always r2s__lanes(r2s__states([{', '.join(names)}]))  # each segment's lanes")
    lines.append(f"terminate after {num(frame_steps[-1] * dt)} seconds")
    return Simulated("\n".join(lines) + "\n", tuple(names), dt, frame_steps, offset, tuple(rules))
