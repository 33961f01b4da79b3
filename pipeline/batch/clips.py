"""`r2s run --clip S`: one clip program (docs/dsl.md, "Behaviour programs") per clip of S seconds of a scene's
frames, tiled as `r2s run --window` tiles windows (pipeline.batch.windows: the same tiling, bounds, plan, resume,
pool and parts), each clip synthesized by synth.behaviour.synthesize in a worker as `r2s synth A.json ...
--behaviours` does. A clip's durations depend on its frames' timestamps, which frames.frame_hash does not hash:
its row's frame_hash covers every one of them too, so a changed timestamp redoes the clip.
"""

from __future__ import annotations

import hashlib
import json
import time

import numpy as np

from pipeline.batch.window_task import WindowTask
from pipeline.batch.windows import WindowSpec, WindowUnit, window_hash
from pipeline.programs import CLIP_SCHEMA, result_row
from synth.behaviour.synthesize import synthesize_behaviours


class ClipSpec(WindowSpec):
    """How clips tile a scene: a window's tiling under another option's name, with its own config hash."""

    name = "clip"

    def unit_hash(self, unit: WindowUnit, frame_ids, lane0: np.ndarray, lane1: np.ndarray) -> str:
        """window_hash and every frame's timestamp (32 hex digits)."""
        h = hashlib.blake2b(window_hash(unit, frame_ids, lane0, lane1).encode(), digest_size=16)
        for stamp in unit.timestamps_us:
            h.update(b"\0" + str(stamp).encode())
        return h.hexdigest()


class ClipTask(WindowTask):
    """Clips to synthesize in one go: a WindowTask whose units are clips and whose rows are clip rows."""

    schema = CLIP_SCHEMA

    def synthesize(self, scenes: list, unit: WindowUnit, digest: str) -> dict:
        """The row of a clip whose frames are `scenes`: `r2s synth --behaviours --format json`'s document as
        columns (the program column holds the clip program; its Scenic text needs a road file: none here)."""
        started = time.perf_counter()
        result = synthesize_behaviours(scenes, self.config)
        doc = result.to_json_dict()
        row = result_row(result.first, digest)
        row.update(status=doc["status"], cost=doc["cost"], lower_bound=doc["lower_bound"], program=doc["program"],
                   scenic=None, runtime_s=time.perf_counter() - started, duration_s=doc["duration_s"],
                   relational_cost=doc["relational_cost"], boundaries=json.dumps(doc["boundaries"]),
                   behaviours_s=doc["behaviours_s"])
        return {**row, **self._window_fields(unit), "config_hash": self.config_hash}

    def _window_fields(self, unit: WindowUnit) -> dict:
        fields = super()._window_fields(unit)
        del fields["window_s"]
        return {**fields, "clip_s": self.spec.window_s, "timestamps_us": list(unit.timestamps_us)}
