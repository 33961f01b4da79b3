"""A recorded clip for `r2s export --clip` and `r2s render --clip` (docs/cli.md): frames of one scene in time
order, from scene JSON files (as `r2s synth` takes a clip) or from a frames file or dataset by its scene's name
(`FRAMES --scene S`: every frame of S, in time order, each as `r2s scene` reads it, with its road). A simulated
variant of `r2s simulate` is such a scene (`SCENE-simNNN` of its output folder).

`Clip.of` is pure: the frames checked as a clip (one scene, in time order with times, one type per id, each with
its world pose), their road (every frame's, in the first frame's ego frame: synth.window.road) and every
entity's recorded trajectory in the world (pipeline/export/motion.py)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

from frames.dataset import FramesDataset
from pipeline.cli.inputs import read_scene
from pipeline.errors import UserError
from pipeline.export import slug
from pipeline.export.motion import Motion, recorded
from pipeline.scenes import scene as frame_scene
from synth.behaviour.track import ClipError, frame_times
from synth.errors import InputError
from synth.scene import Scene
from synth.window.program import clip_entities
from synth.window.road import window_road

MAX_FRAMES = 10_000  # a clip's frames at most: each is read whole (a 9 s Waymo scenario has 91, an AV2 log 150)
SCENE_COLUMNS = ("frame_id", "scene", "frame_index", "timestamp_us")


@dataclass(frozen=True, eq=False)
class Clip:
    """A recorded clip: its frames in time order, their times (seconds after the first), its first frame with the
    clip's road (every frame's road in its ego frame), its scene's name, and every entity's trajectory."""

    scenes: tuple[Scene, ...]
    times: tuple[float, ...]
    first: Scene
    scene: str
    motion: Motion

    @property
    def name(self) -> str:
        """Its scenario's name: the scene's, made a file-name part (pipeline.export.slug)."""
        return slug(self.scene)

    def to_dict(self) -> dict:
        """What a scenario's metadata says of it."""
        return {"scene": self.scene, "first_frame": self.scenes[0].frame_id, "last_frame": self.scenes[-1].frame_id,
                "frames": len(self.scenes), "duration_s": self.times[-1]}

    @classmethod
    def of(cls, scenes: Sequence[Scene]) -> Clip:
        """The frames as a clip; one line (an InputError) for what is not one: fewer than two frames, frames of
        several scenes or out of order, a frame without its world pose or time."""
        scenes = tuple(scenes)
        if len(scenes) < 2:
            raise ClipError("a clip is two or more frames of one scene in time order")
        if len(scenes) > MAX_FRAMES:
            raise ClipError(f"a clip of {len(scenes):,} frames: at most {MAX_FRAMES:,}")
        clip_entities(scenes)  # one scene (where scene JSON says it), in order, each id one type
        missing = next((s.frame_id for s in scenes if s.world is None), None)
        if missing is not None:
            raise ClipError(f"frame {missing!r} has no world pose (scene JSON `world`, which r2s scene writes): a clip's "
                            "frames are placed in the world by it")
        times = frame_times(scenes)
        first = scenes[0]
        name = first.world.scene or first.frame_id.rsplit("/", 1)[0]
        return cls(scenes, times, replace(first, road=window_road(scenes)), name, recorded(scenes, times))


def read_clip_files(paths: Sequence[str]) -> Clip:
    """A clip of scene JSON files (r2s scene's), in the order given."""
    return _clip([read_scene(str(p)) for p in paths])


def read_clip_frames(frames: str, scene_name: str, radius: float = 50.0) -> Clip:
    """Every frame of scene `scene_name` of a frames file or dataset, in time order, each as r2s scene reads it
    (its road within `radius` of ego from the maps beside the frames)."""
    dataset = FramesDataset.open(frames)
    found: dict[str, tuple[int, int]] = {}
    names: set[str] = set()
    for part in dataset.parts:
        for table in dataset.row_groups(part, SCENE_COLUMNS, ()):
            cols = table.to_pydict()
            for fid, scene, index, stamp in zip(*(cols[c] for c in SCENE_COLUMNS)):
                if scene == scene_name:
                    found[fid] = (-1 if stamp is None else stamp, index)
                elif len(names) < 3:
                    names.add(scene)
        if len(found) > MAX_FRAMES:
            raise UserError(f"scene {scene_name!r} of {frames} has more than {MAX_FRAMES:,} frames: at most that many "
                            "make a clip")
    if not found:
        raise UserError(f"{frames} has no frame of scene {scene_name!r}"
                        + (f" (its scenes include {', '.join(sorted(map(repr, names)))})" if names else ""))
    order = sorted(found, key=lambda fid: found[fid])
    return _clip([frame_scene(frames, fid, radius=radius) for fid in order])


def _clip(scenes: list[Scene]) -> Clip:
    try:
        return Clip.of(scenes)
    except InputError as exc:
        raise UserError(str(exc)) from None
