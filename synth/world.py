"""Where a scene is in its source's world: the ego's recorded pose, and the way back from the ego frame to it.

A scene lives in its ego frame (+x right, +y forward, headings in degrees CCW from +y). Its `world` (scene JSON,
docs/formats.md) is the ego's pose in the frame its source records tracks and maps in (ScenarioNet's scenario
frame, nuScenes' global frame, Argoverse 2's city frame, a log's fixed frame): x, y in metres and the heading in
degrees CCW from +x, with the scenario / log, frame index and map it came from. Exporting a scene or a variant
(pipeline.export) puts every entity and the road back there; a scene without a world is exported with the ego
frame as its world (WorldPose.identity: ego at the origin facing +y), so coordinates stay as they are.

Values only, no I/O.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from functools import cached_property
from typing import Any, Protocol

from synth.errors import InputError
from synth.geometry import normalize
from synth.pose import SE2
from synth.road.roadmap import Points, RoadMap

WORLD_KEYS = ("source", "scene", "frame_index", "timestamp_us", "map_id", "x", "y", "heading")
MAX_TIMESTAMP_US = 2**62  # microseconds: any recording's clock, far below int64's end
MAX_WORLD_COORDINATE = 1e9  # metres: UTM northings are ~5e6; beyond 1e9 a float's step is past a millimetre
MAX_NAME = 256


class WorldError(InputError, ValueError):
    """A scene's `world` that is not what scene JSON says. One line."""


@dataclass(frozen=True)
class WorldPose:
    """The ego's pose in its source's world frame (x, y metres; heading degrees CCW from +x, in [0, 360)) and
    what it came from: the source (extractor), the scene (scenario / log), the frame's index in it, its map."""

    x: float
    y: float
    heading: float
    source: str | None = None
    scene: str | None = None
    frame_index: int | None = None
    map_id: str | None = None
    timestamp_us: int | None = None  # the frame's time (a clip's behaviours read it: synth.behaviour)

    @classmethod
    def identity(cls) -> WorldPose:
        """The ego frame as a world: ego at the origin facing +y (heading 90 from +x), so points stay put."""
        return cls(0.0, 0.0, 90.0)

    @cached_property
    def frame(self) -> SE2:
        """This pose's ego frame in its world (synth.pose: the one transform)."""
        return SE2.ego(self.x, self.y, math.radians(self.heading))

    def point(self, x: float, y: float) -> tuple[float, float]:
        """A point of the ego frame in the world (the inverse of extractors.base.global_to_ego)."""
        return self.frame.apply(x, y)

    def local(self, x: float, y: float) -> tuple[float, float]:
        """A point of the world in this pose's ego frame (extractors.base.global_to_ego; the inverse of point)."""
        return self.frame.local(x, y)

    def yaw(self, heading: float) -> float:
        """An ego-frame heading (degrees CCW from +y) as a world yaw in radians CCW from +x, in [-pi, pi)."""
        return math.remainder(math.radians(self.heading + heading), math.tau)

    def points(self, pts: Points) -> Points:
        return tuple(self.point(x, y) for x, y in pts)

    def to_dict(self) -> dict[str, Any]:
        return {k: v for k in WORLD_KEYS if (v := getattr(self, k)) is not None}


@dataclass(frozen=True)
class WorldEntity:
    """An entity of a scene placed in the world: centre (metres), yaw (radians CCW from +x), box, speed."""

    id: str
    type: str
    x: float
    y: float
    yaw: float
    length: float
    width: float
    speed: float | None


class Placed(Protocol):
    """What in_world reads of an entity (synth.scene.Entity; not imported: synth.scene reads worlds from here)."""

    id: str
    type: str
    x: float
    y: float
    heading: float
    speed: float | None

    def dimensions(self) -> tuple[float, float]: ...


def in_world(pose: WorldPose, e: Placed) -> WorldEntity:
    """One entity of a scene in its world (the box is the recorded one, else the type's typical size)."""
    x, y = pose.point(e.x, e.y)
    length, width = e.dimensions()
    return WorldEntity(e.id, e.type, x, y, pose.yaw(e.heading), length, width, e.speed)


def road_in_world(pose: WorldPose, road: RoadMap) -> RoadMap:
    """A scene's road (in its ego frame) back in the world frame."""
    return RoadMap.of(road.map_id, [replace(f, polygon=pose.points(f.polygon), line=pose.points(f.line))
                                    for f in road.features])


def world_from_dict(raw: Any) -> WorldPose:
    """Scene JSON's `world`, validated: x, y finite metres within MAX_WORLD_COORDINATE, heading finite (made
    [0, 360)), the names printable strings, frame_index and timestamp_us non-negative integers; any other key refused."""
    if not isinstance(raw, Mapping):
        raise WorldError("world must be an object with x, y and heading")
    unknown = sorted(str(k) for k in raw if k not in WORLD_KEYS)
    if unknown:
        raise WorldError(f"world has unknown key {unknown[0]!r} (keys: {', '.join(WORLD_KEYS)})")
    missing = [k for k in ("x", "y", "heading") if raw.get(k) is None]
    if missing:
        raise WorldError(f"world lacks {', '.join(missing)}")
    nums = {}
    for key in ("x", "y", "heading"):
        v = raw[key]
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise WorldError(f"world {key} must be a number, got {type(v).__name__}")
        try:
            f = float(v)
        except OverflowError:
            raise WorldError(f"world {key} is an integer beyond floats") from None
        if not math.isfinite(f) or (key != "heading" and abs(f) > MAX_WORLD_COORDINATE):
            raise WorldError(f"world {key} must be finite{'' if key == 'heading' else ' and within 1e9 m'}, got {v!r}")
        nums[key] = f
    names = {}
    for key in ("source", "scene", "map_id"):
        v = raw.get(key)
        if v is not None and (not isinstance(v, str) or not v or len(v) > MAX_NAME or not v.isprintable()):
            raise WorldError(f"world {key} must be a printable string of 1 to {MAX_NAME} characters")
        names[key] = v
    index = raw.get("frame_index")
    if index is not None and (isinstance(index, bool) or not isinstance(index, int) or not 0 <= index < 2**31):
        raise WorldError(f"world frame_index must be an integer from 0 to 2^31 - 1, got {index!r}")
    stamp = raw.get("timestamp_us")
    if stamp is not None and (isinstance(stamp, bool) or not isinstance(stamp, int)
                              or not 0 <= stamp < MAX_TIMESTAMP_US):
        raise WorldError(f"world timestamp_us must be an integer from 0 to 2^62 - 1 microseconds, got {stamp!r}")
    return WorldPose(nums["x"], nums["y"], normalize(nums["heading"]), frame_index=index, timestamp_us=stamp,
                     **names)
