"""`r2s synth SCENE.json`: one scene in, its minimum-cost program out (DSL, Scenic or JSON). Several scene JSON
files (frames of one scene, in time order): one program over the clip, which holds in each of them
(synth.window.program). With --behaviours, the clip's program: its first frame's program and a behaviour per entity
(synth.behaviour)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from pipeline.cli.options import add_synthesis_options, synthesis_config
from pipeline.errors import UserError
from pipeline.export.opendrive import check_road_frame, header_frame, map_path
from pipeline.outputs import check_apart, writing
from storage.atomic import write_text_atomic
from synth.scenic.emit import on_map
from synth.synthesize import synthesize


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("scene", nargs="+",
                   help="scene JSON file, or - for standard input (format: docs/formats.md); several files: frames "
                        "of one scene in time order (r2s scene writes them), one program for the clip")
    p.add_argument("--format", choices=("dsl", "scenic", "json"), default="dsl", help="output (default: dsl)")
    p.add_argument("--out", metavar="F", help="write to this file (atomically) instead of stdout")
    p.add_argument("--max-entities", type=int, default=1000, metavar="N",
                   help="refuse scenes with more entities than this (default 1000)")
    p.add_argument("--behaviours", action="store_true",
                   help="the clip's program: its first frame's program plus a minimum-cost behaviour per entity, "
                        "ego included (docs/dsl.md, Behaviour programs; frames need times and speeds)")
    p.add_argument("--road", metavar="XODR",
                   help="with --format scenic: the road as OpenDRIVE that the Scenic text names (param map) and "
                        "Scenic's driving domain loads: the scene's road in its ego frame (r2s export SCENE.json --to "
                        "opendrive --frame ego --out F.xodr); with --behaviours the clip's road in the world frame "
                        "(r2s export FIRST.json --to openscenario --out DIR writes it)")
    add_synthesis_options(p)


def run(args: argparse.Namespace) -> int:
    from pipeline.cli.inputs import read_scene

    check_apart(args.out, [*(("input scene", s) for s in args.scene), ("config", args.config)])
    if len(args.scene) > 1 and "-" in args.scene:
        raise UserError("a clip is read from files: standard input (-) holds one scene")
    if args.road is not None and args.format != "scenic":
        raise UserError("--road is the OpenDRIVE road a program's Scenic text names: give it with --format scenic")
    if args.behaviours and args.format == "scenic" and args.road is None:
        raise UserError("--behaviours --format scenic needs --road FILE.xodr, the road the scenario is simulated on "
                        "(r2s export FIRST.json --to openscenario --out DIR writes it)")
    if args.road is not None and not Path(args.road).is_file():
        raise UserError(f"--road {args.road} is not a file (r2s export FIRST.json --to openscenario --out DIR "
                        "writes the .xodr)")
    config = synthesis_config(args)
    scenes = [read_scene(path, max_entities=args.max_entities) for path in args.scene]
    if args.road is not None and not args.behaviours:
        check_road_frame(args.road, scenes[0])
    if args.behaviours:
        from synth.behaviour.synthesize import synthesize_behaviours

        result = synthesize_behaviours(scenes, config)
    elif len(scenes) == 1:
        result = synthesize(scenes[0], config)
    else:
        from synth.window.program import synthesize_window

        result = synthesize_window(scenes, config)
    if args.format == "json":
        text = json.dumps(result.to_json_dict(), indent=1) + "\n"
    elif args.format == "scenic" and args.behaviours:
        from synth.behaviour.scenic import clip_scenic

        road = str(Path(args.road).resolve())
        ox, oy, _ = header_frame(road) or (0.0, 0.0, 0.0)
        text = clip_scenic(result, road, config.v_stop, (ox, oy))
    elif args.format == "scenic" and args.road is not None:
        text = on_map(result.scenic, map_path(args.road, args.out))
    elif args.format == "scenic":
        text = result.scenic
    else:
        text = str(result.program)
    if args.out:
        with writing(args.out):
            write_text_atomic(args.out, text)
    else:
        sys.stdout.write(text)
    if result.status != "optimal":
        sys.stderr.write(
            f"r2s synth: {result.status}: cost {result.cost}, proven lower bound {result.lower_bound}\n"
        )
    return 0
