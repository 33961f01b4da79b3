"""`r2s synth SCENE.json`: one scene in, its minimum-cost program out (DSL, Scenic or JSON)."""

from __future__ import annotations

import argparse
import json
import sys

from synth.config import ORACLES, SOLVERS, STRATEGIES


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("scene", help="scene JSON file, or - for standard input (format: docs/formats.md)")
    p.add_argument("--strategy", choices=STRATEGIES, help="search strategy (default: auto)")
    p.add_argument("--oracle", choices=ORACLES, help="relation oracle (default: hybrid)")
    p.add_argument("--solver", choices=SOLVERS, help="SMT solver (default: z3)")
    p.add_argument("--time-limit", type=float, metavar="S",
                   help="seconds of search; the best program found is returned (default: no limit)")
    p.add_argument("--memory-limit", type=float, metavar="MB",
                   help="stop the search (status memout) past this RSS (default: no limit)")
    p.add_argument("--config", metavar="NAME|F",
                   help="preset (default, paper) or TOML file; the options here override it (default: default)")
    p.add_argument("--format", choices=("dsl", "scenic", "json"), default="dsl", help="output (default: dsl)")
    p.add_argument("--out", metavar="F", help="write to this file (atomically) instead of stdout")
    p.add_argument("--max-entities", type=int, default=1000, metavar="N",
                   help="refuse scenes with more entities than this (default 1000)")
    p.add_argument("--motion", action="store_const", const=True, default=None,
                   help="every statement also says how fast its entity moves (stationary, moving like REF, "
                        "moving Range m/s [relative to REF]); every entity needs a speed (config: motion = true)")
    p.add_argument("--uncertainty", type=uncertainty_arg, metavar="POS_M,HEAD_DEG[,SPEED_MPS]",
                   help="robust synthesis: the program contains every scene whose entities (not ego) are within "
                        "POS_M metres and HEAD_DEG degrees (and, with --motion, SPEED_MPS m/s) of the record (an "
                        "entity's pos_sigma / heading_sigma / speed_sigma overrides); default 0,0 = plain synthesis")


def uncertainty_arg(text: str) -> dict[str, float]:
    """argparse type of --uncertainty: the SynthConfig fields it sets (also for `r2s run --uncertainty`)."""
    from synth.config import UNCERTAINTY_FIELDS, ConfigError, parse_uncertainty

    try:
        values = parse_uncertainty(text)
    except ConfigError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return dict(zip(UNCERTAINTY_FIELDS, values))


def run(args: argparse.Namespace) -> int:
    from extractors.atomic import write_text_atomic
    from pipeline.cli.inputs import load_config, read_scene
    from synth.synthesize import synthesize

    config = load_config(args.config).with_(
        strategy=args.strategy, oracle=args.oracle, solver=args.solver,
        time_limit=args.time_limit, memory_limit=args.memory_limit, motion=args.motion, **(args.uncertainty or {}),
    )
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
