"""`r2s run FRAMES --out PROGRAMS`: one program per frame (with --window, per window of a scene's frames), in
parallel, each frame under its own time and memory limit, written in atomic part files so that a stopped run
resumes where it stopped.

The verb only reads its options; the work is pipeline.batch.stage.run_frames (the Python API). Heavy modules (pandas,
pyarrow, joblib, dask) are imported inside run(), so that the other verbs do not pay for them.
"""

from __future__ import annotations

import argparse
import signal
import sys

from pipeline.batch import DEFAULT_CHUNK_SIZE, DEFAULT_PART_ROWS
from pipeline.cli.options import add_synthesis_options, synthesis_config
from pipeline.outputs import check_apart
from synth.errors import ExitCode


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("frames", help="frames Parquet file, or a directory of them (r2s extract)")
    p.add_argument("--out", required=True, metavar="PATH",
                   help="programs dataset directory (part files, readable as one table), or one file if PATH "
                        "ends in .parquet; an existing output is resumed: frames done with the same config are kept")
    p.add_argument("--jobs", type=int, metavar="N", help="parallel workers (default: all cores; "
                   "with --backend dask and --scheduler: all workers of the cluster)")
    add_synthesis_options(p, {
        "time_limit": "seconds of search per frame; the best program found and a proven lower bound are recorded "
                      "(status feasible or timeout; default: no limit)",
        "memory_limit": "resident memory per frame: the search stops past it (status memout, its best program "
                        "kept); with loky a hard cap 50%% (at least 256 MB) above it ends the frame (default: no "
                        "limit)",
        "motion": "statements also say how fast entities move, as in r2s synth (needs the frames' speed column; a "
                  "frame with an entity lacking speed is an error row naming it)",
        "uncertainty": "robust synthesis, as in r2s synth (frames' pos_sigma / heading_sigma / speed_sigma columns "
                       "override)",
    })
    p.add_argument("--backend", choices=("loky", "dask"), default="loky",
                   help="loky: local worker processes (default); dask: a dask.distributed cluster")
    p.add_argument("--scheduler", metavar="ADDR", help="dask scheduler address (tcp://host:8786); without it, "
                   "--backend dask starts a local cluster of --jobs single-threaded worker processes")
    p.add_argument("--chunk-size", type=int, default=DEFAULT_CHUNK_SIZE, metavar="K",
                   help=f"frames per task (default {DEFAULT_CHUNK_SIZE}; fewer when the run is small)")
    p.add_argument("--part-rows", type=int, default=DEFAULT_PART_ROWS, metavar="N",
                   help=f"rows per part file (default {DEFAULT_PART_ROWS}); a part is also written 30 s after its "
                        "first row, so a kill loses at most the frames in flight and the last 30 s of rows")
    p.add_argument("--log-every", type=float, default=30.0, metavar="S",
                   help="without a terminal, a progress line every S seconds (default 30)")
    g = p.add_argument_group("programs over a window (docs/dsl.md, \"Programs over a window\")")
    g.add_argument("--window", type=float, metavar="S",
                   help="one program per window of S seconds of a scene's frames (by timestamp_us), holding in each "
                        "of its frames, instead of one per frame; rows: docs/formats.md, \"Window programs\"")
    g.add_argument("--stride", type=float, metavar="S",
                   help="seconds from one window's (or clip's) start to the next (default: the window: consecutive "
                        "windows)")
    g.add_argument("--max-gap", type=float, metavar="S",
                   help="no window (or clip) spans a gap of more than S seconds between consecutive frames (default: "
                        "none)")
    g.add_argument("--clip", type=float, metavar="S",
                   help="one clip program per clip of S seconds of a scene's frames, tiled as --window tiles windows "
                        "(docs/dsl.md, \"Behaviour programs\"; the frames need speeds); rows: docs/formats.md, "
                        "\"Clip programs\"")


def run(args: argparse.Namespace) -> int:
    from pipeline.batch.stage import run_frames

    check_apart(args.out, [("config", args.config)], directory=not str(args.out).endswith(".parquet"))  # and the frames: run_frames checks them
    config = synthesis_config(args)
    # SIGTERM (a scheduler's stop) ends the run like Ctrl-C: the finished rows are kept, and it says so.
    # The previous handler comes back afterwards: `main(["run", ...])` called in a process that goes on (a test, a
    # notebook) must not leave that process exiting on a later SIGTERM from inside whatever it runs next.
    previous = signal.signal(signal.SIGTERM, lambda *_: sys.exit(ExitCode.TERMINATED))
    try:
        run_frames(args.frames, args.out, config, jobs=args.jobs, backend=args.backend, scheduler=args.scheduler,
                   chunk_size=args.chunk_size, part_rows=args.part_rows, log_every_s=args.log_every,
                   window_s=args.window, stride_s=args.stride, max_gap_s=args.max_gap, clip_s=args.clip)
    finally:
        signal.signal(signal.SIGTERM, previous)
    return 0
