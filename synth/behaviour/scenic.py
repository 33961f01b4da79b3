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
from synth.behaviour.segmentation import Segmented
from synth.behaviour.synthesize import ClipResult
from synth.behaviour.track import Track
from synth.patterns.temporal import turn_of
from synth.scene import VEHICLE_CLASSES, Entity
from synth.syntax import fmt_number
from synth.world import WorldPose

# The behaviour every moving entity runs: per segment (seconds, speed at its start and end in m/s, turn in
# degrees CCW), the speed goes linearly from one end to the other and the heading turns at a steady rate, both
# steered step by step toward where they should be (cars: speed set along the heading and a steering angle
# whose Newtonian yaw rate closes the heading error in one step; pedestrians: walking speed and direction).
STEER = '''\
import math

def r2s__steer(car, speed, yaw_rate):
    """The steering whose Newtonian yaw rate (-speed * sin(steer * pi / 2) / length) is yaw_rate (rad/s) at the
    speed set in the same step (the simulator turns the car at its new speed)."""
    speed = max(speed, 0.1)
    return 2 / math.pi * math.asin(max(-1, min(1, -yaw_rate * car.length / speed)))
'''
PRELUDE = STEER + '''
behavior R2sSegments(segments, walks):
    heading = self.heading
    for duration, v0, v1, turn in segments:
        steps = max(1, round(duration / simulation().timestep))
        start = heading
        for k in range(steps):
            f = (k + 1) / steps
            speed = v0 + (v1 - v0) * f
            heading = start + turn * f
            if walks:
                take SetWalkingDirectionAction(heading), SetWalkingSpeedAction(speed)
            else:
                error = (heading - self.heading + math.pi) % (2 * math.pi) - math.pi
                take SetSpeedAction(speed), SetSteerAction(r2s__steer(self, speed, error / simulation().timestep))
    while True:
        take SetSpeedAction(0) if not walks else SetWalkingSpeedAction(0)
'''


def num(v: float) -> str:
    return repr(round(v, 6))


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


def placed(e: Entity, world: WorldPose, offset: tuple[float, float] = (0.0, 0.0)) -> tuple[str, str]:
    """The Scenic class and the specifiers of an entity at its recorded pose in the world, less `offset`: the road
    file's origin in the world (its header's offset, which Scenic's OpenDRIVE reader does not apply), so that the
    entity stands on Scenic's road where it stood on the recorded one."""
    x, y = world.point(e.x, e.y)
    x, y = x - offset[0], y - offset[1]
    heading = world.heading + e.heading - 90.0  # Scenic's 0 is +y; the world's yaw is from +x
    length, width = e.dimensions()
    cls = "Pedestrian" if e.type == "Pedestrian" else "Car" if e.type in VEHICLE_CLASSES else "Object"
    return cls, (f"new {cls} at ({num(x)}, {num(y)}), facing {num(heading)} deg, with length {num(length)}, "
                 f"with width {num(width)}, with regionContainedIn None, with allowCollisions True, "
                 "with requireVisible False")


def clip_scenic(result: ClipResult, xodr: str, v_stop: float = 0.5) -> str:
    """The dynamic Scenic scenario of a clip program (module docstring). `xodr`: the path of the clip's road as
    OpenDRIVE in the world frame (r2s export --to openscenario writes it for the clip's first frame)."""
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
        cls, where = placed(e, world)
        if not behaviour.parked and cls != "Object":
            segments = ", ".join(f"({', '.join(num(v) for v in p)})" for p in segment_parameters(segmented, track))
            walks = "True" if cls == "Pedestrian" else "False"
            where += f", with speed {num(track.samples[0].speed)}, with behavior R2sSegments([{segments}], {walks})"
        lines.append(f"{track.id} = {where}")
        if cls != "Object":
            top = speed_bound(behaviour, track, v_stop)
            lines.append(f"require always {track.id}.speed <= {fmt_number(top + 0.01)}  # {behaviour.id}: its paces")
    lines.append(f"terminate after {num(clip.duration)} seconds")
    return "\n".join(lines) + "\n"
