"""`r2s render SCENE.json [--program P.dsl] [--samples K] --out bev.png`: a bird's-eye view of a scene.

Oriented boxes with heading arrows and ids in ego's frame, ego in red; with --program, an arrow from each
reference to the entity it places or orients, coloured by relation kind; with --samples K, K variants sampled
from the program as `r2s sample` draws them (same sampler and options), overlaid translucently under the
recorded one; with --matches M.parquet (r2s query's output), the entities a match binds in this frame outlined
and named by the pattern's names.
What it does is pipeline.variants.picture.render (`from pipeline import render`).
Exit codes: 0 written; 2 bad input (one line, nothing written); 4 no variant found (as `r2s sample`); 1 bug.
"""

from __future__ import annotations

import argparse

from pipeline.cli.options import add_config_option, add_sampling_options, bounded_int, sample_options
from pipeline.errors import UserError
from pipeline.outputs import check_apart


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("scene", help="scene JSON file, or - for standard input (r2s scene F ID | r2s render - ...)")
    p.add_argument("clip", nargs="*", metavar="SCENE", help="more scene JSON files: SCENE and these are a clip "
                   "(frames of one scene in time order): its recorded trajectories over the road")
    p.add_argument("--simulated", metavar="DIR", help="with a clip: a frames dataset of its simulated variants "
                   "(r2s simulate's output), each scene's trajectories overlaid dashed")
    p.add_argument("--program", metavar="P.dsl", help="DSL program of the scene: draw its references")
    p.add_argument("--programs", metavar="PATH", help="take the scene's program from a programs file or dataset "
                   "(r2s run's output) by its frame id, instead of --program")
    p.add_argument("--samples", type=bounded_int(0, 1000), default=0, metavar="K",
                   help="overlay K variants sampled from the program (needs --program)")
    p.add_argument("--matches", metavar="M.parquet",
                   help="a matches file of r2s query: outline the entities its bindings of this frame bind, named by "
                        "the pattern's names")
    add_config_option(p, ": the tolerances delta1, delta2")
    p.add_argument("--out", required=True, metavar="F", help="image file: .png, .svg or .pdf")
    add_sampling_options(p)


def run(args: argparse.Namespace) -> int:
    from pipeline.cli.inputs import load_config, read_program, read_scene
    from pipeline.variants.picture import render

    if args.clip or args.simulated is not None:
        return _clip(args)

    check_apart(args.out, [("scene", args.scene), ("program", args.program), ("programs", args.programs),
                           ("config", args.config), ("matches", args.matches)])
    render(read_scene(args.scene), args.out, program=read_program(args.program) if args.program else None,
           programs=args.programs, samples=args.samples, config=load_config(args.config),
           sampling=sample_options(args, max(1, args.samples)), matches=args.matches, where_scene=args.scene)
    print(f"wrote {args.out}")
    return 0


def _clip(args: argparse.Namespace) -> int:
    from pipeline.variants.clip_picture import render_clip

    if not args.clip:
        raise UserError("--simulated is drawn over the recorded clip: give its frames (two or more scene JSON files, "
                        "in time order)")
    given = [o for o, v in (("--program", args.program), ("--programs", args.programs), ("--samples", args.samples),
                            ("--matches", args.matches)) if v]
    if given:
        raise UserError(f"{given[0]} is for one frame: a clip is drawn with its trajectories (and --simulated)")
    if "-" in (args.scene, *args.clip):
        raise UserError("a clip's frames are files (standard input holds one frame)")
    render_clip([args.scene, *args.clip], args.out, simulated=args.simulated)
    print(f"wrote {args.out}")
    return 0
