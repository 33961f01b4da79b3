"""A clip program as a dynamic Scenic scenario for Scenic's Newtonian simulator (docs/scenic.md, "Behaviour
programs"): `scenic.simulators.newtonian.driving_model` on the clip's road as OpenDRIVE (r2s export's .xodr, in
the world frame), every entity of the clip's first frame at its recorded pose there, each behaving entity driven
by r2sgen's own Scenic behaviour `R2sSegments`, one step of it per segment with the segment's recorded
parameters (duration, speed at its ends, turn), the program's speed bounds as `require always`, and `terminate
after` the clip's length. Values in, text out."""

from __future__ import annotations

import math

from synth.behaviour.kinds import Cruising, SlowingToAStop, Stopped
from synth.behaviour.program import Behaviour
from synth.behaviour.replay_path import replay_path
from synth.behaviour.scenic_common import ALONG, STEER, num, placed
from synth.behaviour.segmentation import Segmented
from synth.behaviour.synthesize import ClipResult
from synth.behaviour.track import Track
from synth.patterns.temporal import turn_of
from synth.syntax import fmt_number

# A car with a replay path (`path`, its polyline: synth.behaviour.replay_path, the centre lines of the lanes its
# program names; `lengths`, each segment's length along it) follows the path by arc length: the segment's speed
# goes linearly between its recorded boundary speeds, scaled so the segment covers its length in its recorded
# duration, and the car steers at the path's point one step
# past where that profile has it at the step's end, or LOOKAHEAD_M past it where that is farther (pure pursuit:
# a lane path has corners where its pieces join, and aiming at 0.1-0.5 m ahead turned them into overshoots of up to
# 9 m; bench/results/behaviours-replay.md). Without a path (walkers) the heading turns at the segment's steady rate.
PRELUDE = STEER + ALONG + '''
LOOKAHEAD_M = 2.0

behavior R2sSegments(segments, walks, path=None, lengths=None, top=None):
    heading = self.heading
    done = 0  # the path's length at the segment's start
    dt = simulation().timestep
    for j, (duration, v0, v1, turn) in enumerate(segments):
        if duration <= 0:
            continue  # a track of one sample: its segment lasts no time (and has length 0)
        steps = max(1, round(duration / dt))
        start = heading
        linear = (v0 + v1) / 2 * duration
        scale = lengths[j] / linear if lengths is not None and linear > 1e-6 else 1
        for k in range(steps):
            f = (k + 1) / steps
            speed = (v0 + (v1 - v0) * f) * scale
            if top is not None:
                speed = min(speed, top)  # within the program's speed bound (its `require always`)
            heading = start + turn * f
            if path is not None and not walks:
                t = f * duration
                covered = (v0 * t + (v1 - v0) * t * t / (2 * duration)) * scale
                ahead = self.position + Vector(0, speed).rotatedBy(self.heading) * dt
                tx, ty = r2s__along(path, done + covered + max(speed * dt, LOOKAHEAD_M))
                if math.hypot(tx - ahead.x, ty - ahead.y) > 1e-6:
                    heading = math.atan2(-(tx - ahead.x), ty - ahead.y)
            if walks:
                take SetWalkingDirectionAction(heading), SetWalkingSpeedAction(speed)
            else:
                error = (heading - self.heading + math.pi) % (2 * math.pi) - math.pi
                take SetSpeedAction(speed), SetSteerAction(r2s__steer(self, speed, error / dt))
        if lengths is not None:
            done += lengths[j]
    while True:
        take SetSpeedAction(0) if not walks else SetWalkingSpeedAction(0)
'''


def segment_parameters(segmented: Segmented, track: Track) -> list[tuple[float, float, float, float]]:
    """(duration s, speed at start, speed at end, turn radians CCW) of each segment, as recorded at its boundary
    samples (stopped: 0 m/s; slowing to a stop: to 0)."""
    s, bounds, out = track.samples, segmented.boundaries, []
    for seg, a, b in zip(segmented.behaviour.segments, bounds, bounds[1:]):
        turn = sum(turn_of(s[k].heading, s[k + 1].heading) for k in range(a, b))
        v0, v1 = s[a].speed, s[b].speed
        if isinstance(seg.pace, Stopped):
            v0 = v1 = 0.0
        elif isinstance(seg.pace, SlowingToAStop):
            v1 = 0.0
        out.append((s[b].t - s[a].t, v0, v1, math.radians(turn)))
    return out


def speed_bound(behaviour: Behaviour, track: Track, v_stop: float) -> float:
    """The most its behaviour lets the entity go (m/s): its Range paces' upper bounds, its recorded speed where a
    segment slows to a stop, V_STOP where it is stopped or parked."""
    top = v_stop
    for seg in behaviour.segments:
        if isinstance(seg.pace, Cruising):
            top = max(top, seg.pace.range.hi)
        elif not isinstance(seg.pace, Stopped):
            top = max(top, max(x.speed for x in track.samples))
    return top


def clip_scenic(result: ClipResult, xodr: str, v_stop: float = 0.5,
                offset: tuple[float, float] = (0.0, 0.0)) -> str:
    """The dynamic Scenic scenario of a clip program (module docstring). `xodr`: the path of the clip's road as
    OpenDRIVE in the world frame (r2s export --to openscenario writes it for the clip's first frame); `offset`: its
    header's offset (pipeline.export.opendrive.header_frame), Scenic's (0, 0) in the world."""
    clip = result.clip
    first = clip.scenes[0]
    world = first.world
    lines = [f"# {result.header}",
             "# A dynamic scenario for Scenic's Newtonian simulator, headless: compile in 2D mode "
             "(scenic.scenarioFromFile(F, mode2D=True)) and simulate; every entity of the first frame at its recorded "
             "pose in the world, each behaviour's segments with their recorded parameters (docs/scenic.md).",
             f"param map = {xodr!r}", "param render = False",
             "model scenic.simulators.newtonian.driving_model", "", PRELUDE]
    late = [t.id for t in clip.tracks if not t.from_start]
    if late:
        lines.append(f"# Not placed (first seen after the clip's first frame): {', '.join(late)}")
    by_id = first.by_id()
    for segmented, track in zip(result.segmented, clip.tracks):  # both ego first, then in order of appearance
        if not track.from_start:
            continue
        behaviour = segmented.behaviour
        e = first.ego if track.id == "ego" else by_id[track.id]
        cls, where = placed(e, world, offset)
        if not behaviour.parked and cls != "Object":
            segments = ", ".join(f"({', '.join(num(v) for v in p)})" for p in segment_parameters(segmented, track))
            walks = "True" if cls == "Pedestrian" else "False"
            path = "None"
            lengths = "None"
            if cls != "Pedestrian":
                drive = replay_path(segmented, track, clip, offset)
                path = "[" + ", ".join(f"({num(x)}, {num(y)})" for x, y in drive.points) + "]"
                lengths = "[" + ", ".join(num(v) for v in drive.lengths) + "]"
            where += (f", with speed {num(track.samples[0].speed)}, "
                      f"with behavior R2sSegments([{segments}], {walks}, {path}, {lengths}, "
                      f"{num(speed_bound(behaviour, track, v_stop))})")
        lines.append(f"{track.id} = {where}")
        if cls != "Object":
            top = speed_bound(behaviour, track, v_stop)
            lines.append(f"require always {track.id}.speed <= {fmt_number(top + 0.01)}  # {behaviour.id}: its paces")
    lines.append(f"terminate after {num(clip.duration)} seconds")
    return "\n".join(lines) + "\n"
