"""The pipeline: the `r2s` verbs and the batch stage. Every verb has a Python API (docs/api.md), imported on first
use so that `r2s synth` never pays for pandas or pyarrow: `pipeline.extract` (r2s extract), `pipeline.scene`
(r2s scene), `pipeline.run_frames` (r2s run, the batch stage), `pipeline.sample` (r2s sample), `pipeline.render`
(r2s render; `pipeline.render_clip` of a clip), `pipeline.simulate` (r2s simulate, in pipeline.simulation; `pipeline.simulate_run` of every clip of a run, in
pipeline.batch.simulations), and in the rooms of the same name (so not
here) `pipeline.query.query` and `pipeline.report.report`."""

import importlib

_API = {"extract": "pipeline.batch.extract", "scene": "pipeline.scenes", "run_frames": "pipeline.batch.stage",
        "sample": "pipeline.variants.sample", "render": "pipeline.variants.picture",
        "render_clip": "pipeline.variants.clip_picture",
        "simulate": "pipeline.simulation", "simulate_run": "pipeline.batch.simulations"}


def __getattr__(name: str):
    if name in _API:
        return getattr(importlib.import_module(_API[name]), name)
    raise AttributeError(f"module 'pipeline' has no attribute {name!r}")
