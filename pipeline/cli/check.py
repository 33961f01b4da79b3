"""`r2s check SCENE PROGRAM`: is the scene in the program's semantics? Exit 0 yes, 3 no (violations listed)."""

from __future__ import annotations

import argparse

from pipeline.cli.options import add_config_option
from pipeline.errors import CheckFailed


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("scene", help="scene JSON file")
    p.add_argument("program", help="DSL program file")
    add_config_option(p, ": the tolerances delta1, delta2")


def run(args: argparse.Namespace) -> int:
    from pipeline.cli.inputs import load_config, read_program, read_scene
    from synth.semantics import check

    config = load_config(args.config)
    scene = read_scene(args.scene)
    program = read_program(args.program)
    result = check(program, scene, config)
    if result.ok:
        print(f"ok: the program contains scene {scene.frame_id} (cost {program.cost})")
        return 0
    for v in result.violations:
        print(f"violation: {v}")
    raise CheckFailed(f"the program does not contain the scene ({len(result.violations)} violations)")
