"""`r2s synth SCENE.json`: one scene in, its minimum-cost program out (DSL, Scenic or JSON)."""

from __future__ import annotations

import argparse
import json
import sys

from pipeline.cli.options import add_synthesis_options, synthesis_config
from pipeline.outputs import check_apart
from synth.synthesize import synthesize


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("scene", help="scene JSON file, or - for standard input (format: docs/formats.md)")
    p.add_argument("--format", choices=("dsl", "scenic", "json"), default="dsl", help="output (default: dsl)")
    p.add_argument("--out", metavar="F", help="write to this file (atomically) instead of stdout")
    p.add_argument("--max-entities", type=int, default=1000, metavar="N",
                   help="refuse scenes with more entities than this (default 1000)")
    add_synthesis_options(p)


def run(args: argparse.Namespace) -> int:
    from pipeline.cli.inputs import read_scene
    from storage.atomic import write_text_atomic

    check_apart(args.out, [("input scene", args.scene), ("config", args.config)])
    config = synthesis_config(args)
    scene = read_scene(args.scene, max_entities=args.max_entities)
    result = synthesize(scene, config)
    if args.format == "json":
        text = json.dumps(result.to_json_dict(), indent=1) + "\n"
    elif args.format == "scenic":
        text = result.scenic
    else:
        text = str(result.program)
    if args.out:
        write_text_atomic(args.out, text)
    else:
        sys.stdout.write(text)
    if result.status != "optimal":
        sys.stderr.write(
            f"r2s synth: {result.status}: cost {result.cost}, proven lower bound {result.lower_bound}\n"
        )
    return 0
