"""`r2s render SCENE.json [--program P.dsl] [--samples K] --out bev.png`: a bird's-eye view of a scene.

Oriented boxes with heading arrows and ids in ego's frame, ego in red; with --program, an arrow from each
reference to the entity it places or orients, coloured by relation kind; with --samples K, K variants sampled
from the program as `r2s sample` draws them (same sampler and options), overlaid translucently under the
recorded one.
Exit codes: 0 written; 2 bad input (one line, nothing written); 4 no variant found (as `r2s sample`); 1 bug.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from pipeline.cli.options import add_config_option, add_sampling_options, bounded_int, sample_options
from pipeline.errors import UserError
from pipeline.outputs import check_apart


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("scene", help="scene JSON file, or - for standard input (r2s scene F ID | r2s render - ...)")
    p.add_argument("--program", metavar="P.dsl", help="DSL program of the scene: draw its references")
    p.add_argument("--programs", metavar="PATH", help="take the scene's program from a programs file or dataset "
                   "(r2s run's output) by its frame id, instead of --program")
    p.add_argument("--samples", type=bounded_int(0, 1000), default=0, metavar="K",
                   help="overlay K variants sampled from the program (needs --program)")
    add_config_option(p, ": the tolerances delta1, delta2")
    p.add_argument("--out", required=True, metavar="F", help="image file: .png, .svg or .pdf")
    add_sampling_options(p)


def run(args: argparse.Namespace) -> int:
    from pipeline.cli.inputs import load_config, read_program, read_scene
    from pipeline.variants.render import FORMATS, View, draw, save
    from synth.semantics import check

    check_apart(args.out, [("scene", args.scene), ("program", args.program), ("programs", args.programs),
                           ("config", args.config)])
    if Path(args.out).suffix.lstrip(".").lower() not in FORMATS:
        raise UserError(f"--out {args.out}: the file name must end in {', '.join('.' + f for f in FORMATS)}")
    if Path(args.out).is_dir():
        raise UserError(f"--out {args.out} is a directory")
    if args.program and args.programs:
        raise UserError("give --program or --programs, not both")
    if args.samples and args.program is None and args.programs is None:
        raise UserError("--samples needs --program (variants are sampled from the program)")
    config = load_config(args.config)
    scene = read_scene(args.scene)
    program, samples, subtitle = None, (), ""
    if args.programs is not None:
        from pipeline.programs import program_of_frame
        from synth.dsl import DslError, parse_program

        text = program_of_frame(args.programs, scene.frame_id)
        if text is None:
            raise UserError(f"{args.programs} has no program for frame {scene.frame_id!r}")
        try:
            program = parse_program(text)
        except DslError as exc:
            raise UserError(f"{args.programs}, frame {scene.frame_id}: {exc}") from None
        where = f"the program of {scene.frame_id} in {args.programs}"
    elif args.program is not None:
        program, where = read_program(args.program), args.program
    if program is not None:
        ids = {e.id for e in scene.entities}
        missing = next((s.id for s in program.statements if s.id not in ids), None)
        if missing is not None:
            raise UserError(f"{where} declares {missing!r}, which is not an entity of {args.scene}")
        result = check(program, scene, config)
        subtitle = f"program cost {program.cost}, " + (
            "contains the scene" if result.ok else f"does NOT contain the scene ({len(result.violations)} violations)")
        if args.samples:
            from pipeline.variants.sample import ProgressReport, sample_program

            progress = ProgressReport("r2s render")
            try:
                drawn = sample_program(program, scene, config, sample_options(args, args.samples), progress)
            finally:
                progress.close()
            samples = drawn.scenes
            subtitle += f"; {len(samples)} variants ({drawn.sampler}, seed {args.seed})"
    save(draw(View(scene, program, samples, subtitle)), args.out)
    print(f"wrote {args.out}")
    return 0
