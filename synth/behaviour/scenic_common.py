"""What the dynamic Scenic scenarios of a clip share (the replay, synth.behaviour.scenic; the variants,
synth.behaviour.variants): Scenic text for steering a Newtonian car and for a point along a polyline, numbers as
Scenic text, and an entity's placement at its recorded pose on the road file's frame (its header's offset taken
off). Values in, text out."""

from __future__ import annotations

from synth.behaviour.track import Clip, Track
from synth.scene import VEHICLE_CLASSES, Entity
from synth.world import WorldPose

STEER = '''\
import math

def r2s__steer(car, speed, yaw_rate):
    """The steering whose Newtonian yaw rate (-speed * sin(steer * pi / 2) / length) is yaw_rate (rad/s) at the
    speed set in the same step (the simulator turns the car at its new speed)."""
    speed = max(speed, 0.1)
    return 2 / math.pi * math.asin(max(-1, min(1, -yaw_rate * car.length / speed)))
'''
ALONG = '''
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
'''
def num(v: float) -> str:
    return repr(round(v, 6))


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


def track_points(track: Track, clip: Clip, offset: tuple[float, float] = (0.0, 0.0)) -> list[tuple[float, float]]:
    """A track's recorded places in the world less `offset` (the road file's origin), one per sample."""
    rows = [scene.ego if track.id == "ego" else scene.by_id().get(track.id) for scene in clip.scenes]
    points = [scene.world.point(e.x, e.y) for scene, e in zip(clip.scenes, rows) if e is not None]
    return [(x - offset[0], y - offset[1]) for x, y in points]
