"""`r2s check SCENE PROGRAM`: is the scene in the program's semantics? Exit 0 yes, 3 no (violations listed).
`r2s check A.json B.json ... PROGRAM` with a clip program (behaviours): does it contain the clip
(synth.behaviour.check)?"""

from __future__ import annotations

import argparse

from pipeline.cli.options import add_config_option
from pipeline.errors import CheckFailed, UserError


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("scene", nargs="+", help="scene JSON file; several: the frames of a clip, in time order, for a "
                                            "clip program (behaviours)")
    p.add_argument("program", help="DSL program file (a clip program: statements, then behaviours)")
    add_config_option(p, ": the tolerances delta1, delta2")


def run(args: argparse.Namespace) -> int:
    from pipeline.cli.inputs import load_config, read_scene, read_text_file
    from synth.behaviour.program import is_clip_program
    from synth.dsl import parse_program
    from synth.semantics import check
    from synth.syntax import DslError

    config = load_config(args.config)
    scene = read_scene(args.scene[0]) if len(args.scene) == 1 else None  # a scene's errors first, as ever
    text = read_text_file(args.program, "program")
    try:
        if scene is None or is_clip_program(text):
            return check_clip_files(args.scene, text, config)
        program = parse_program(text)
    except DslError as exc:
        raise UserError(f"{args.program}: {exc}") from None
    result = check(program, scene, config)
    if result.ok:
        print(f"ok: the program contains scene {scene.frame_id} (cost {program.cost})")
        return 0
    for v in result.violations:
        print(f"violation: {v}")
    raise CheckFailed(f"the program does not contain the scene ({len(result.violations)} violations)")


def check_clip_files(scene_paths: list[str], text: str, config) -> int:
    """A clip program on the clip's frames: exit 0 when it contains the clip, else the violations and exit 3.
    A program that is not DSL raises DslError (the caller names the file)."""
    from pipeline.cli.inputs import read_scene
    from synth.behaviour.check import check_clip
    from synth.behaviour.program import parse_clip_program

    if len(scene_paths) > 1 and "-" in scene_paths:
        raise UserError("a clip is read from files: standard input (-) holds one scene")
    program = parse_clip_program(text)
    scenes = [read_scene(p) for p in scene_paths]
    result = check_clip(program, scenes, config)
    if result.ok:
        print(f"ok: the program contains the clip {scenes[0].frame_id} to {scenes[-1].frame_id} "
              f"({len(scenes)} frames, cost {program.cost})")
        return 0
    for v in result.violations:
        print(f"violation: {v}")
    raise CheckFailed(f"the program does not contain the clip ({len(result.violations)} violations)")
