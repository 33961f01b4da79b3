"""`r2s sample PROGRAM.scenic --n K --seed S --out DIR`: K variants of a recorded scene, as scene JSON.

Writes DIR/sample_000.json ... (same entity ids as the program, ego included, types from the classes, headings
in degrees [0, 360), each entity's length and width). The same program, seed and sampler give byte-identical
files; sample k does not depend on K. Or `--program P.dsl --scene S.json`: the DSL program and the scene it
describes; or `--programs PROGRAMS FRAME`: the program `r2s run` wrote for that frame (its scenic column).
What it does is pipeline.variants.sample.sample (`from pipeline import sample`). Every variant is checked against the DSL semantics, and in every variant two boxes overlap only if
they overlap in the recorded scene (the collision rule the emitted text states).

Samplers (`--sampler`, see pipeline.variants.sample): `gibbs` (default) is r2sgen's Metropolis-within-Gibbs chain over the
program's Ranges, started at the recording (`--burn-in`, `--thin` in sweeps); `scenic` is the Scenic compiler's
rejection sampler over whole scenes (`--max-iterations` per scene): the same distribution, exact, but only for
small scenes. A hand-edited file (`--trusted`) can only be sampled by Scenic.

Exit codes: 0 written; 2 bad input (a file that is not r2sgen's, does not compile, bad options; one line, nothing
written); 4 sampling failed: no variant satisfies the program and the collision rule within the budget (one
line naming the pairs of entities that collide; nothing written, since all K scenes are drawn before the first
file); 1 internal error.
"""

from __future__ import annotations

import argparse
import re
from pathlib import Path

from pipeline.cli.options import add_config_option, add_sampling_options, bounded_int, sample_options
from pipeline.errors import UserError
from pipeline.outputs import check_apart, staged_files


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("scenic_file", nargs="?", metavar="PROGRAM.scenic",
                   help="Scenic program written by r2sgen, unedited (anything else is refused: compiling runs it); "
                        "with --programs, the frame id instead")
    p.add_argument("--programs", metavar="PROGRAMS",
                   help="sample the program r2s run wrote for frame FRAME (the positional argument) in this programs "
                        "file or dataset: r2s sample --programs programs scene-0061/0 --out variants")
    p.add_argument("--trusted", action="store_true",
                   help="sample a hand-written or edited Scenic file too, with Scenic (it runs as Python: only "
                        "files you checked)")
    p.add_argument("--program", dest="dsl_file", metavar="P.dsl", help="sample from a DSL program instead (with --scene)")
    p.add_argument("--scene", metavar="S.json", help="the scene the DSL program was synthesized for (ego, sizes)")
    add_config_option(p, ": the tolerances, for the DSL route")
    p.add_argument("--n", type=bounded_int(1, 100_000), default=1, metavar="K", help="number of scenes (default 1)")
    p.add_argument("--out", required=True, metavar="DIR", help="directory for sample_000.json ...")
    add_sampling_options(p)


def run(args: argparse.Namespace) -> int:
    from pipeline.cli.inputs import load_config, read_program, read_scene, read_text_file
    from pipeline.variants.sample import ProgressReport, sample, sample_scenic

    out = Path(args.out)
    check_apart(out, [("program", None if args.programs else args.scenic_file), ("program", args.dsl_file),
                      ("scene", args.scene), ("config", args.config), ("programs", args.programs)], directory=True)
    if out.exists() and not out.is_dir():
        raise UserError(f"--out {args.out} exists and is not a directory")
    options = sample_options(args, args.n)
    routes = sum((args.programs is not None, args.dsl_file is not None,
                  args.scenic_file is not None and args.programs is None))
    if routes != 1:
        raise UserError("give either PROGRAM.scenic or --program P.dsl --scene S.json (or --programs PROGRAMS FRAME)")
    if args.programs is not None and (args.scenic_file is None or args.scene or args.config or args.trusted):
        raise UserError("--programs PROGRAMS takes the frame id (r2s sample --programs programs scene-0061/0 ...), "
                        "and no --scene, --config or --trusted")
    keywords = {f: getattr(options, f) for f in ("n", "seed", "max_iterations", "allow_collisions", "sampler",
                                                 "burn_in", "thin")}
    progress = ProgressReport("r2s sample")
    try:
        if args.programs is not None:
            samples = sample(programs=args.programs, frame_id=args.scenic_file, progress=progress, **keywords)
        elif args.dsl_file is not None:
            if args.scene is None:
                raise UserError("--program needs --scene (the scene it was synthesized for)")
            samples = sample(read_program(args.dsl_file), read_scene(args.scene), config=load_config(args.config),
                             progress=progress, **keywords)
        else:
            if args.scene is not None or args.config is not None:
                raise UserError("--scene and --config belong to the --program route, not to a Scenic file")
            text = read_text_file(args.scenic_file, "program")
            samples = sample_scenic(text, options, filename=args.scenic_file, trusted=args.trusted, progress=progress)
    finally:
        progress.close()
    width = max(3, len(str(args.n - 1)))
    # Every sample is written beside the directory first and moved in only when all are: a full disk never
    # leaves some of them.
    with staged_files(out) as stage:
        for k, scene in enumerate(samples.scenes):
            (stage / f"sample_{k:0{width}d}.json").write_text(scene.to_json(), encoding="utf-8")
    # Samples of an earlier, larger run would read as part of this one: the directory holds this run's only.
    written = {f"sample_{k:0{width}d}.json" for k in range(len(samples.scenes))}
    for stale in sorted(out.glob("sample_*.json")):
        if stale.name not in written and re.fullmatch(r"sample_\d{3,}\.json", stale.name):  # names we write
            stale.unlink()
    print(f"wrote {len(samples.scenes)} scenes to {out} (seed {args.seed}, {samples.describe()})")
    return 0
