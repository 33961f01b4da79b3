"""The batch stage: many frames at once, in worker processes, streaming and resumable (`r2s run`, `r2s extract
--jobs`). stage.run_frames is its entry point (`pipeline.run_frames`)."""

# The stage's defaults, here (not in stage.py) so that `r2s run --help` shows them without loading the stage.
DEFAULT_CHUNK_SIZE = 32  # frames per task
DEFAULT_PART_ROWS = 2048  # rows per part file (~20 MB of program text at most)
