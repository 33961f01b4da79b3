"""A clip's frames as one track per entity (docs/dsl.md, "Behaviour programs": tracks): the samples of each
entity (time, speed, heading in the world, lane facts) in the frames it is in, and the clip's road as one lane
graph. Frames where an entity is absent are gaps, skipped. Values in, values out."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from synth.geometry import normalize
from synth.road.lane_relations import LaneGraph
from synth.scene import Scene, SceneError, as_scene
from synth.window.program import clip_entities
from synth.window.road import window_road


class ClipError(SceneError):
    """Frames that are not a clip a behaviour can be read from (no time, time not increasing, no speed). One
    line."""


@dataclass(frozen=True)
class Sample:
    """One row of a track: seconds after the clip's first frame, speed (m/s), heading in the world (degrees CCW
    from +x, in [0, 360)), the chosen lane (None: in no lane, or frames without lane facts), in an intersection."""

    t: float
    speed: float
    heading: float
    lane: str | None = None
    in_intersection: bool = False


@dataclass(frozen=True)
class Steps:
    """What the lane graph says of each step (k, k+1) of a track: the lane kept (lane(k+1) on lane(k)'s chain),
    moved left, moved right (on the chain of lane(k)'s left / right neighbour). False where a sample has no lane."""

    keep: tuple[bool, ...]
    left: tuple[bool, ...]
    right: tuple[bool, ...]

    @classmethod
    def of(cls, samples: Sequence[Sample], graph: LaneGraph | None) -> Steps:
        def related(side: str) -> tuple[bool, ...]:
            return tuple(graph is not None and s.lane is not None and n.lane is not None
                         and n.lane in graph.related(s.lane, side) for s, n in zip(samples, samples[1:]))

        return cls(related("same"), related("left"), related("right"))


@dataclass(frozen=True)
class Track:
    """An entity's samples over the clip (ego's id is `ego`), their steps' lane relations, and whether it is in
    the clip's first frame."""

    id: str
    type: str
    samples: tuple[Sample, ...]
    steps: Steps
    from_start: bool

    @property
    def n(self) -> int:
        return len(self.samples)


@dataclass(frozen=True)
class Clip:
    """A clip read for behaviours: its frames (ids, in order, as Scenes), each frame's time (seconds after the
    first), every entity's track (ego first, then in order of first appearance) and the clip's road as a lane
    graph (None without a road)."""

    scenes: tuple[Scene, ...]
    times: tuple[float, ...]
    tracks: tuple[Track, ...]
    graph: LaneGraph | None

    @property
    def duration(self) -> float:
        return self.times[-1]

    def track(self, entity_id: str) -> Track | None:
        return next((t for t in self.tracks if t.id == entity_id), None)


def frame_times(scenes: Sequence[Scene]) -> tuple[float, ...]:
    """Each frame's time in seconds after the first (its world's timestamp_us), refused in one line where a frame
    has none or a time does not increase."""
    stamps = []
    for s in scenes:
        stamp = s.world.timestamp_us if s.world is not None else None
        if stamp is None:
            raise ClipError(f"frame {s.frame_id!r} has no time (scene JSON world.timestamp_us, which r2s scene "
                            "writes for extracted frames): a behaviour needs each frame's time")
        if stamps and stamp <= stamps[-1]:
            raise ClipError(f"frame {s.frame_id!r} is not later than the frame before it (world.timestamp_us "
                            f"{stamp} <= {stamps[-1]}): give a clip's frames in time order")
        stamps.append(stamp)
    return tuple((x - stamps[0]) / 1e6 for x in stamps)


def read_clip(scenes: Sequence[Scene | Mapping[str, Any]]) -> Clip:
    """The clip's tracks (docs/dsl.md, "Behaviour programs"). Refuses (ClipError / WindowError, one line) what is
    not frames of one scene in time order with times, and an entity without a speed in some frame."""
    scenes = tuple(as_scene(s) for s in scenes)
    ids, present = clip_entities(scenes)  # one scene, in order, one type per id
    times = frame_times(scenes)
    road = window_road(scenes)
    graph = None if road is None else LaneGraph(road)
    rows = [s.by_id() for s in scenes]
    tracks = []
    for eid in ("ego", *ids):
        frames = range(len(scenes)) if eid == "ego" else present[eid]
        samples = []
        for k in frames:
            scene = scenes[k]
            e = scene.ego if eid == "ego" else rows[k][eid]
            if e.speed is None:
                raise ClipError(f"entity {eid!r} has no speed in frame {scene.frame_id!r}: a behaviour reads "
                                "every entity's speed (extract with speeds)")
            samples.append(Sample(times[k], e.speed, normalize(scene.world.heading + e.heading), e.lane,
                                  bool(e.in_intersection)))
        e0 = scenes[0].ego if eid == "ego" else rows[frames[0]][eid]
        tracks.append(Track(eid, e0.type, tuple(samples), Steps.of(samples, graph), frames[0] == 0))
    return Clip(scenes, times, tuple(tracks), graph)
