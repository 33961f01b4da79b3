"""`r2s simulate PROGRAM.json A.json B.json ... --n K --seed S --out DIR`: K simulated variants of a clip program
as frames, each re-checked by r2sgen's checker (pipeline.simulation; `from pipeline import simulate`).

PROGRAM is what `r2s synth A.json B.json ... --behaviours --format json` writes; A.json B.json ... are the clip's
frames it was synthesized from (their road: the simulation's, as OpenDRIVE; their times: the frames'). DIR is a
frames dataset (part-000000.parquet, its map in _maps/, summary.json): one scene per written variant, which
`r2s query`, `r2s run`, `r2s scene`, `r2s report`, `r2s render` and `r2s export` read.

Exit codes: 0 at least one variant written; 2 bad input (one line, nothing written); 4 no variant written (every
one rejected by Scenic, past --time-limit or refused by the checker; nothing written); 1 internal error.
"""

from __future__ import annotations

import argparse
import sys

from pipeline.cli.options import add_config_option, bounded_int
from pipeline.errors import UserError
from pipeline.outputs import check_apart


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("program", metavar="PROGRAM.json",
                   help="the clip program as r2s synth A.json B.json ... --behaviours --format json writes it")
    p.add_argument("scene", nargs="+", metavar="SCENE.json",
                   help="the clip's frames the program was synthesized from, in time order (scene JSON)")
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
