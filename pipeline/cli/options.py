"""Options more than one verb takes, each defined once, and the values they are read into: what a synthesis runs
with (`r2s synth`, `r2s run`), the config preset or file (every verb that reads one), how variants are drawn
(`r2s sample`, `r2s render`). Verbs import this module and pipeline.cli.inputs, never each other.

Kept light: `r2s synth --help` builds its parser from here, so the sampler and the batch stage are imported only
inside the functions that need them.
"""

from __future__ import annotations

import argparse
from collections.abc import Mapping

from pipeline.variants import DEFAULT_MAX_ITERATIONS, MAX_SEED, SAMPLERS
from synth.config import (
    DEFAULT_BURN_IN,
    DEFAULT_THIN,
    ORACLES,
    SOLVERS,
    STRATEGIES,
    UNCERTAINTY_FIELDS,
    ConfigError,
    parse_uncertainty,
)

# How `r2s synth` words the synthesis options; `r2s run` rewords some (its limits are per frame).
SYNTHESIS_HELP = {
    "time_limit": "seconds of search; the best program found is returned (default: no limit)",
    "memory_limit": "stop the search (status memout) past this RSS (default: no limit)",
    "motion": "every statement also says how fast its entity moves (stationary, moving like REF, moving Range m/s "
              "[relative to REF]); every entity needs a speed (config: motion = true)",
    "lanes": "every statement also says where its entity is on the recorded road (in lane of REF, in lane left / "
             "right of REF, in oncoming lane of REF, in intersection, on crosswalk, off road, off lane, in lane "
             "\"ID\"); the scene needs its road and lane facts (r2s scene writes them; config: lanes = true)",
    "uncertainty": "robust synthesis: the program contains every scene whose entities (not ego) are within POS_M "
                   "metres and HEAD_DEG degrees (and, with --motion, SPEED_MPS m/s) of the record (an entity's "
                   "pos_sigma / heading_sigma / speed_sigma overrides); default 0,0 = plain synthesis",
}


def add_config_option(p: argparse.ArgumentParser, uses: str) -> None:
    """--config: a preset name or a TOML file (pipeline.cli.inputs.load_config); `uses` says what the verb takes
    from it."""
    p.add_argument("--config", metavar="NAME|F", help=f"preset (default, paper) or TOML file{uses} (default: default)")


def add_synthesis_options(p: argparse.ArgumentParser, helps: Mapping[str, str] | None = None) -> None:
    """--strategy, --oracle, --solver, --time-limit, --memory-limit, --config, --motion, --lanes, --uncertainty: what a
    synthesis runs with, read back by synthesis_config. `helps` rewords options for the verb, by dest."""
    words = {**SYNTHESIS_HELP, **(helps or {})}
    p.add_argument("--strategy", choices=STRATEGIES, help="search strategy (default: auto)")
    p.add_argument("--oracle", choices=ORACLES, help="relation oracle (default: hybrid)")
    p.add_argument("--solver", choices=SOLVERS, help="SMT solver (default: z3)")
    p.add_argument("--time-limit", type=float, metavar="S", help=words["time_limit"])
    p.add_argument("--memory-limit", type=float, metavar="MB", help=words["memory_limit"])
    add_config_option(p, "; the options here override it")
    p.add_argument("--motion", action="store_const", const=True, default=None, help=words["motion"])
    p.add_argument("--lanes", action="store_const", const=True, default=None, help=words["lanes"])
    p.add_argument("--uncertainty", type=uncertainty_arg, metavar="POS_M,HEAD_DEG[,SPEED_MPS]",
                   help=words["uncertainty"])


def synthesis_config(args: argparse.Namespace):
    """The SynthConfig of add_synthesis_options' options: the --config preset or file, overridden by the others."""
    from pipeline.cli.inputs import load_config

    return load_config(args.config).with_(
        strategy=args.strategy, oracle=args.oracle, solver=args.solver,
        time_limit=args.time_limit, memory_limit=args.memory_limit, motion=args.motion, lanes=args.lanes, **(args.uncertainty or {}),
    )


def uncertainty_arg(text: str) -> dict[str, float]:
    """argparse type of --uncertainty: the SynthConfig fields it sets."""
    try:
        values = parse_uncertainty(text)
    except ConfigError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return dict(zip(UNCERTAINTY_FIELDS, values))


def bounded_int(lo: int, hi: int):
    """argparse type: an integer in [lo, hi]."""
    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if not lo <= v <= hi:
            raise argparse.ArgumentTypeError(f"must be in [{lo}, {hi}], got {v}")
        return v

    return parse


def add_sampling_options(p: argparse.ArgumentParser) -> None:
    """--seed, --sampler, --burn-in, --thin, --max-iterations, --allow-collisions: how variants are drawn, read
    back by sample_options."""
    p.add_argument("--seed", type=bounded_int(0, MAX_SEED), default=0, help="random seed (default 0)")
    p.add_argument("--sampler", choices=SAMPLERS, default=None,
                   help="gibbs: r2sgen's chain, any scene size (default); scenic: Scenic's rejection sampler, small "
                        "scenes only (the default for a --trusted edited file)")
    p.add_argument("--burn-in", type=bounded_int(0, 10**6), default=None, metavar="S",
                   help=f"gibbs: sweeps from the recorded scene to the first variant (default {DEFAULT_BURN_IN})")
    p.add_argument("--thin", type=bounded_int(1, 10**6), default=None, metavar="S",
                   help=f"gibbs: sweeps between variants (default {DEFAULT_THIN})")
    p.add_argument("--max-iterations", type=bounded_int(1, 10**7), default=DEFAULT_MAX_ITERATIONS, metavar="M",
                   help=f"scenic: rejection-sampling iterations per scene (default {DEFAULT_MAX_ITERATIONS})")
    p.add_argument("--allow-collisions", action="store_true",
                   help="drop the collision rule (by default two boxes may overlap only if they overlap in the "
                        "recorded scene)")


def sample_options(args: argparse.Namespace, n: int):
    """The SampleOptions of add_sampling_options' options, for n variants."""
    from pipeline.variants.sample import SampleOptions

    return SampleOptions(n=n, seed=args.seed, max_iterations=args.max_iterations,
                         allow_collisions=args.allow_collisions, sampler=args.sampler, burn_in=args.burn_in,
                         thin=args.thin)
