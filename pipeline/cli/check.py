"""`r2s check SCENE PROGRAM`: is the scene in the program's semantics? Exit 0 yes, 3 no (violations listed)."""

from __future__ import annotations

import argparse
import sys


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("scene", help="scene JSON file")
    p.add_argument("program", help="DSL program file")
    p.add_argument("--config", metavar="NAME|F",
                   help="preset (default, paper) or TOML file: the tolerances delta1, delta2 (default: default)")


def run(args: argparse.Namespace) -> int:
    from pipeline.cli.inputs import load_config, read_scene, read_text_file
    from pipeline.errors import UserError
    from synth.dsl import DslError, parse_program
    from synth.semantics import check

    config = load_config(args.config)
    scene = read_scene(args.scene)
    try:
        program = parse_program(read_text_file(args.program, "program"))
    except DslError as exc:
        raise UserError(f"{args.program}: {exc}") from None
    result = check(program, scene, config)
    if result.ok:
        print(f"ok: the program contains scene {scene.frame_id} (cost {program.cost})")
        return 0
    for v in result.violations:
        print(f"violation: {v}")
    sys.stderr.write(f"r2s check: the program does not contain the scene ({len(result.violations)} violations)\n")
    return 3
