"""`r2s simulate PROGRAM.json A.json B.json ... --n K --seed S --out DIR`: K simulated variants of a clip program
as frames, each re-checked by r2sgen's checker (pipeline.simulation; `from pipeline import simulate`).

PROGRAM is what `r2s synth A.json B.json ... --behaviours --format json` writes; A.json B.json ... are the clip's
frames it was synthesized from (their road: the simulation's, as OpenDRIVE; their times: the frames'). DIR is a
frames dataset (part-000000.parquet, its map in _maps/, summary.json): one scene per written variant, which
`r2s query`, `r2s run`, `r2s scene`, `r2s report`, `r2s render` and `r2s export` read.

`r2s simulate RUN_OUTPUT --frames FRAMES --out DIR` does it for every clip program of an `r2s run FRAMES --clip S
--lanes` output, one task per clip in parallel workers (pipeline.batch.simulations: the batch stage's pool, limits,
resume and progress; `from pipeline import simulate_run`): DIR is a frames dataset of every clip's written variants
and a row per clip in DIR/_simulations, resumed when run again.

Exit codes: 0 at least one variant written (RUN_OUTPUT: the run ended, whatever its clips' outcomes); 2 bad input (one line, nothing written); 4 no variant written (every
one rejected by Scenic, past --time-limit or refused by the checker; nothing written); 1 internal error.
"""

from __future__ import annotations

import argparse
import signal
import sys

from pipeline.cli.options import add_config_option, bounded_int
from pipeline.errors import UserError
from pipeline.outputs import check_apart
from synth.errors import ExitCode


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("program", metavar="PROGRAM.json|RUN_OUTPUT",
                   help="the clip program as r2s synth A.json B.json ... --behaviours --format json writes it; or, "
                        "with --frames, the clip programs of r2s run FRAMES --clip S --lanes (its output)")
    p.add_argument("scene", nargs="*", metavar="SCENE.json",
                   help="the clip's frames the program was synthesized from, in time order (scene JSON)")
    g = p.add_argument_group("every clip of a run (r2s simulate RUN_OUTPUT --frames FRAMES --out DIR)")
    g.add_argument("--frames", metavar="FRAMES", help="the frames file or dataset the run was made from (with its "
                   "maps): each clip's frames and road")
    g.add_argument("--jobs", type=int, metavar="N", help="parallel workers, one clip at a time each (default: all "
                   "cores)")
    g.add_argument("--backend", choices=("loky", "dask"), default="loky",
                   help="loky: local worker processes (default); dask: a dask.distributed cluster")
    g.add_argument("--scheduler", metavar="ADDR", help="dask scheduler address (as r2s run's)")
    g.add_argument("--memory-limit", type=float, metavar="MB", help="resident memory per clip's simulations: with "
                   "loky a hard cap 50%% (at least 256 MB) above it; a clip past it is a memout row (default: none)")
    g.add_argument("--log-every", type=float, default=30.0, metavar="S",
                   help="without a terminal, a progress line every S seconds (default 30)")
    p.add_argument("--n", type=bounded_int(1, 10_000), default=1, metavar="K", help="variants to simulate")
    p.add_argument("--seed", type=bounded_int(0, 2**32 - 1), default=0, metavar="S",
                   help="variant k's scene is drawn with a seed from S and k: the same S, the same bytes")
    p.add_argument("--time-limit", type=float, metavar="SECONDS",
                   help="wall seconds per simulation; one past it is not written (default: none)")
    add_config_option(p, ": the tolerances the program was synthesized with")
    p.add_argument("--motion", action="store_const", const=True, default=None,
                   help="as given to r2s synth (the checker's configuration)")
    p.add_argument("--lanes", action="store_const", const=True, default=None,
                   help="as given to r2s synth (the checker's configuration)")
    p.add_argument("--out", required=True, metavar="DIR",
                   help="frames dataset of the written variants (replaced whole: r2s simulate's files only)")


def run(args: argparse.Namespace) -> int:
    from pipeline.cli.inputs import load_config
    from pipeline.simulation import progress_line, simulate

    if args.frames is not None:
        return _run_clips(args)
    batch = [o for o, v in (("--jobs", args.jobs), ("--backend", args.backend != "loky" or None),
                            ("--scheduler", args.scheduler), ("--memory-limit", args.memory_limit)) if v is not None]
    if batch:
        raise UserError(f"{batch[0]} is for the clips of a run: r2s simulate RUN_OUTPUT --frames FRAMES --out DIR")
    if len(args.scene) < 2:
        raise UserError("give the clip's frames: two or more scene JSON files, in time order (those of r2s synth "
                        "--behaviours); or a run's clip programs with --frames FRAMES")
    check_apart(args.out, [("program", args.program), *(("scene", s) for s in args.scene), ("config", args.config)],
                directory=True)
    if "-" in args.scene:
        raise UserError("a clip is read from files: standard input (-) holds one scene")
    config = load_config(args.config).with_(motion=args.motion, lanes=args.lanes)
    result = simulate(args.program, args.scene, args.out, n=args.n, seed=args.seed, time_limit=args.time_limit,
                      config=config, report=progress_line)
    seconds = ", ".join(f"{k} {v:.1f} s" for k, v in result.seconds.items())
    print(f"wrote {result.written} variants of {result.frames} frames to {args.out}: {result.line()} ({seconds})")
    if result.not_simulated:
        sys.stderr.write(f"r2s simulate: not simulated (first seen after the clip's first frame): "
                         f"{', '.join(result.not_simulated)}\n")
    return 0


def _run_clips(args: argparse.Namespace) -> int:
    """r2s simulate RUN_OUTPUT --frames FRAMES --out DIR (pipeline.batch.simulations)."""
    from pipeline.batch.simulations import simulate_run
    from pipeline.cli.inputs import load_config

    if args.scene:
        raise UserError("r2s simulate RUN_OUTPUT --frames FRAMES takes no scene files: each clip's frames are FRAMES'")
    check_apart(args.out, [("run output", args.program), ("frames", args.frames), ("config", args.config)],
                directory=True)
    config = load_config(args.config).with_(motion=args.motion, lanes=True, memory_limit=args.memory_limit)
    # SIGTERM (a scheduler's stop) ends the run like Ctrl-C, as r2s run's: the finished clips are kept, and it says so
    previous = signal.signal(signal.SIGTERM, lambda *_: sys.exit(ExitCode.TERMINATED))
    try:
        simulate_run(args.program, args.frames, args.out, config, n=args.n, seed=args.seed,
                     time_limit=args.time_limit, jobs=args.jobs, backend=args.backend, scheduler=args.scheduler,
                     log_every_s=args.log_every)
    finally:
        signal.signal(signal.SIGTERM, previous)
    return 0
