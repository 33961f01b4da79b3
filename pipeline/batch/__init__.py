"""The batch stage: many frames at once, in worker processes, streaming and resumable (`r2s run`, `r2s extract
--jobs`). stage.run_frames is its entry point (`pipeline.run_frames`)."""
