"""The pipeline: the `r2s` verbs and the batch stage. `pipeline.run_frames` is the batch stage's Python API
(pipeline.batch.stage); it is imported on first use, so that `r2s synth` never pays for pandas or pyarrow."""


def __getattr__(name: str):
    if name == "run_frames":
        from pipeline.batch.stage import run_frames

        return run_frames
    raise AttributeError(f"module 'pipeline' has no attribute {name!r}")
