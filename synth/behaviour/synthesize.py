"""A clip to its clip program (docs/dsl.md, "Behaviour programs", what synthesis writes): the first frame's
minimum-cost relational program (synth.synthesize, with the given options) and every entity's minimum-cost
behaviour (synth.behaviour.segmentation), ego first, then in order of first appearance."""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from synth.behaviour.kinds import outward
from synth.behaviour.program import ClipProgram
from synth.behaviour.segmentation import Segmented, segment_track
from synth.behaviour.track import Clip, read_clip
from synth.config import SynthConfig, as_config
from synth.scene import Scene
from synth.synthesize import SynthResult, synthesize
from synth.version import __version__


@dataclass(frozen=True)
class ClipResult:
    """The clip program, its cost (relational plus behaviours), the first frame's result (status, lower bound,
    certificate: behaviours are always optimal, so the clip's lower bound is the frame's plus their cost), each
    track's chosen boundaries, and the clip's frames and length."""

    program: ClipProgram
    first: SynthResult
    segmented: tuple[Segmented, ...]
    frame_ids: tuple[str, ...]
    duration_s: float
    behaviours_s: float  # seconds the behaviours took
    clip: Clip = field(compare=False, repr=False)  # what they were read from (the Scenic text's parameters)

    @property
    def cost(self) -> int:
        return self.program.cost

    @property
    def status(self) -> str:
        return self.first.status

    @property
    def lower_bound(self) -> int:
        return self.first.lower_bound + sum(s.behaviour.cost for s in self.segmented)

    @property
    def header(self) -> str:
        return (f"clip {self.frame_ids[0]} to {self.frame_ids[-1]} ({len(self.frame_ids)} frames, "
                f"{self.duration_s:g} s): cost {self.cost} ({self.status}), r2sgen {__version__}")

    def to_json_dict(self) -> dict:
        return {"frame_id": self.frame_ids[0], "first_frame": self.frame_ids[0], "last_frame": self.frame_ids[-1],
                "frames": len(self.frame_ids), "duration_s": self.duration_s, "status": self.status,
                "cost": self.cost, "lower_bound": self.lower_bound, "relational_cost": self.first.cost,
                "certified": self.first.certified, "program": str(self.program),
                "boundaries": {s.behaviour.id: list(s.boundaries) for s in self.segmented},
                "behaviours_s": self.behaviours_s, "version": __version__}


def synthesize_behaviours(scenes: Sequence[Scene | Mapping[str, Any]] | Clip,
                          config: SynthConfig | Mapping[str, Any] | None = None) -> ClipResult:
    """The clip program of a clip: frames of one scene in time order, each with its time (world.timestamp_us)
    and every entity's speed. Bad input raises ClipError / WindowError / SceneError (one line)."""
    config = as_config(config)
    clip = scenes if isinstance(scenes, Clip) else read_clip(scenes)
    first = synthesize(clip.scenes[0], config)
    started = time.perf_counter()
    segmented = tuple(segment_track(t, config, None if t.from_start else outward(t.samples[0].t, t.samples[0].t))
                      for t in clip.tracks)
    took = time.perf_counter() - started
    program = ClipProgram(first.program, tuple(s.behaviour for s in segmented))
    return ClipResult(program, first, segmented, tuple(s.frame_id for s in clip.scenes), clip.duration, took, clip)
