"""`r2s VERB ...`: every operation is a verb of one command (ScenarioNet's style).

Each verb lives in its own module with `add_arguments(parser)` and `run(args) -> int`, imported only when
that verb runs, so `r2s synth` never pays for pandas, Scenic or the dataset readers. `r2s VERB --help` shows the
options with their defaults, an example that runs on the data shipped in the repository (EXAMPLES; the tests run
every one) and the exit codes (docs/cli.md). An error reaches main() as an R2sError (synth.errors) whose kind
names the exit code: InputError 2 (bad input or usage: one line on stderr, nothing written), CheckFailed 3 (r2s
check: the program does not contain the scene), SamplingError 4 (r2s sample and render: no variant found); any
other exception is a bug: 1.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
import threading
import warnings
from collections.abc import Callable

from synth.errors import ExitCode, exit_code
from synth.version import __version__

# verb -> (module, one-line help)
VERBS: dict[str, tuple[str, str]] = {
    "synth": ("pipeline.cli.synth", "synthesize a minimum-cost program for one scene JSON (or a clip of frames)"),
    "check": ("pipeline.cli.check", "does a DSL program contain a scene? (the semantics checker)"),
    "extract": ("pipeline.cli.extract", "recorded data (nuScenes, ScenarioNet, AV2, MCAP, ROS bags) to frames.parquet"),
    "scene": ("pipeline.cli.scene", "print one frame of a frames.parquet as scene JSON"),
    "run": ("pipeline.cli.run", "one program per frame of a frames.parquet, in parallel, with limits and resume"),
    "query": ("pipeline.cli.query", "every frame of a frames dataset that matches a DSL pattern (scenario mining)"),
    "report": ("pipeline.cli.report", "report.md / report.html with plots from r2s run's programs"),
    "render": ("pipeline.cli.render", "bird's-eye view of a scene, its program's references and sampled variants"),
    "sample": ("pipeline.cli.sample", "variants of a recorded scene, sampled from its program, as scene JSON"),
    "eval-frontend": ("pipeline.cli.eval_frontend", "detection metrics of predicted frames against ground truth"),
    "export": ("pipeline.cli.export", "a frame and its variants as ScenarioNet scenarios or OpenSCENARIO + OpenDRIVE"),
    "simulate": ("pipeline.cli.simulate", "simulated variants of a clip's behaviour program, as frames, each re-checked"),
}

# verb -> an example, one command a line, run from the repository's root on the data shipped there (after
# `make setup`, with .venv/bin on PATH). Lines that make an input are repeated where a verb needs one, so that
# each example runs alone; tests/pipeline/cli/test_cli_help.py runs them all.
_SCENE = "r2s scene data/nuscenes-mini-keyframes/frames.parquet scene-0103/0 --out scene.json"
_EXCERPT = "r2s extract scenarionet data/nuscenes-mini-excerpt/scenarionet --out frames.parquet"
EXAMPLES: dict[str, tuple[str, ...]] = {
    "synth": (_SCENE, "r2s synth scene.json --format json --out result.json",
              "r2s scene data/nuscenes-mini-keyframes/frames.parquet scene-0103/1 --out next.json",
              "r2s synth scene.json next.json --out clip.dsl"),
    "check": (_SCENE, "r2s synth scene.json --out scene.dsl", "r2s check scene.json scene.dsl"),
    "extract": ("r2s extract scenarionet data/nuscenes-mini-excerpt/scenarionet --categories all --out frames",),
    "scene": (_SCENE,),
    "run": (_EXCERPT, "r2s run frames.parquet --out programs --jobs 2 --time-limit 30"),
    "query": ("r2s query data/nuscenes-mini-keyframes/frames.parquet data/patterns/queue-of-three.dsl "
              "--out matches.parquet",),
    "report": (_EXCERPT, "r2s run frames.parquet --out programs --jobs 2 --time-limit 30",
               "r2s report programs --frames frames.parquet --out report"),
    "render": (_SCENE, "r2s synth scene.json --out scene.dsl",
               "r2s render scene.json --program scene.dsl --samples 5 --out scene.png"),
    "sample": (_SCENE, "r2s synth scene.json --format scenic --out scene.scenic",
               "r2s sample scene.scenic --n 5 --seed 0 --out variants"),
    "eval-frontend": ("r2s extract scenarionet data/nuscenes-mini-excerpt/scenarionet --categories all --out gt.parquet",
                      "r2s extract scenarionet data/nuscenes-mini-excerpt/scenarionet --categories vehicles "
                      "--out vehicles.parquet",
                      "r2s eval-frontend vehicles.parquet gt.parquet --out eval --name vehicles-only"),
    "export": (_EXCERPT, "r2s scene frames.parquet scene-0103/0 --out scene.json",
               "r2s synth scene.json --format scenic --out scene.scenic",
               "r2s sample scene.scenic --n 5 --seed 0 --out variants",
               "r2s export scene.json variants --to scenarionet --out scenarios"),
    "simulate": tuple(f"r2s scene data/argoverse2-log-excerpt/frames.parquet adcf7d18-0510-35b0-a2fa-b4cea13a6d76/{k} "
                      f"--out f{k}.json" for k in range(100, 106))
                + ("r2s synth f100.json f101.json f102.json f103.json f104.json f105.json --behaviours --motion --lanes "
                   "--format json --out clip.json",
                   "r2s simulate clip.json f100.json f101.json f102.json f103.json f104.json f105.json --motion --lanes "
                   "--n 2 --seed 0 --out simulated",
                   # every clip program of a run (about 20 s on 2 cores: four 4 s clips)
                   "r2s run data/argoverse2-log-excerpt/frames.parquet --clip 4 --lanes --jobs 2 --out clips",
                   "r2s simulate clips --frames data/argoverse2-log-excerpt/frames.parquet --lanes --jobs 2 "
                   "--out simulated-clips"),
}

EXIT_CODES = (f"{ExitCode.OK} done; {ExitCode.BAD_INPUT} bad input or usage (one line on stderr, nothing written); "
              f"{ExitCode.INTERNAL_ERROR} internal error (R2S_DEBUG=1: traceback)")
# Exit codes beyond EXIT_CODES, by verb.
MORE_EXIT_CODES: dict[str, str] = {
    "check": f"{ExitCode.CHECK_FAILED} the program does not contain the scene (the violations on stdout)",
    "sample": f"{ExitCode.SAMPLING_FAILED} sampling failed: no variant satisfies the program and the collision rule "
              "within the budget (one line naming the colliding entities; nothing written)",
    "render": f"{ExitCode.SAMPLING_FAILED} with --samples: no variant found (as r2s sample)",
    "simulate": f"{ExitCode.SAMPLING_FAILED} no variant written: each rejected by Scenic, past --time-limit or refused "
                f"by the checker (nothing written); {ExitCode.INTERRUPTED} / {ExitCode.TERMINATED} RUN_OUTPUT: stopped "
                "by Ctrl-C / SIGTERM (finished clips kept: the same command resumes)",
    "run": f"{ExitCode.INTERRUPTED} / {ExitCode.TERMINATED} stopped by Ctrl-C / SIGTERM (finished frames kept: the "
           "same command resumes)",
}


class _HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """Every option with its default (unless its help already says it); description and epilog as written."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        if ("default" in text or not action.option_strings or action.default is None or action.default is False
                or action.default is argparse.SUPPRESS):
            return text
        return f"{text} (default: %(default)s)"


def _epilog(verb: str) -> str:
    import textwrap  # not at the top: `r2s --help` does not need it

    codes = f"exit codes: {EXIT_CODES}" + (f"; {MORE_EXIT_CODES[verb]}" if verb in MORE_EXIT_CODES else "")
    lines = ["example (from the repository's root):", *(f"  {line}" for line in EXAMPLES[verb]), "",
             textwrap.fill(codes, width=100, subsequent_indent="  "), "",
             "the specification: docs/cli.md, docs/formats.md, docs/dsl.md"]
    return "\n".join(lines)


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # one line and exit 2, as for any bad input
        sys.stderr.write(f"{self.prog}: {message}\n")
        sys.exit(ExitCode.BAD_INPUT)


def _top_help() -> str:
    width = max(map(len, VERBS))
    rows = "\n".join(f"  {v.ljust(width)}  {h}" for v, (_, h) in VERBS.items())
    return (f"usage: r2s VERB [options]\n\nverbs:\n{rows}\n\n`r2s VERB --help` for a verb's options, defaults and an "
            f"example.\nexit codes: {EXIT_CODES}; {ExitCode.CHECK_FAILED} r2s check: the program does not contain the "
            f"scene; {ExitCode.SAMPLING_FAILED} r2s sample, r2s render --samples, r2s simulate: no variant found\n"
            "the specification: docs/spec.md\n")


def build_parser(verb: str) -> argparse.ArgumentParser:
    """The argument parser of one verb (its module's add_arguments)."""
    module = importlib.import_module(VERBS[verb][0])
    parser = _Parser(prog=f"r2s {verb}", description=VERBS[verb][1], formatter_class=_HelpFormatter)
    module.add_arguments(parser)
    parser.epilog = _epilog(verb)
    return parser


def thread_failed_hook(verb: str) -> Callable[[threading.ExceptHookArgs], None]:
    """threading.excepthook for a verb: a library's background thread that fails (loky's executor manager, seen
    once with a KeyError while a stopped run shut its pool down) is one line, never a traceback; nothing while the
    interpreter is finalizing (the process is already on its way out with its own last line); R2S_DEBUG=1: the
    traceback."""
    def hook(args: threading.ExceptHookArgs) -> None:
        if os.environ.get("R2S_DEBUG"):
            threading.__excepthook__(args)
        elif args.exc_type is not SystemExit and not sys.is_finalizing():
            name = args.thread.name if args.thread is not None else "a thread"
            message = " ".join(str(args.exc_value).splitlines())
            sys.stderr.write(f"r2s {verb}: internal error in background thread {name}: {args.exc_type.__name__}: "
                             f"{message} (R2S_DEBUG=1 shows the traceback)\n")
    return hook


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help"):
        sys.stdout.write(_top_help())
        return ExitCode.OK if argv else ExitCode.BAD_INPUT
    if argv[0] == "--version":
        print(f"r2sgen {__version__}")
        return ExitCode.OK
    verb = argv[0]
    if verb not in VERBS:
        sys.stderr.write(f"r2s: unknown verb {verb!r} (verbs: {', '.join(VERBS)})\n")
        return ExitCode.BAD_INPUT
    module = importlib.import_module(VERBS[verb][0])
    args = build_parser(verb).parse_args(argv[1:])
    # A verb's messages are its own lines: numpy's floating-point warnings (overflow in an extreme input, ...)
    # would print before them, and the input is checked and refused on its own terms.
    warnings.filterwarnings("ignore", category=RuntimeWarning)
    threading.excepthook = thread_failed_hook(verb)
    try:
        return int(module.run(args) or ExitCode.OK)
    except KeyboardInterrupt:
        sys.stderr.write(f"r2s {verb}: interrupted\n")
        return ExitCode.INTERRUPTED
    except BrokenPipeError:
        return ExitCode.OK
    except Exception as exc:  # the one place where an error becomes an exit code (its kind's, synth.errors)
        code = exit_code(exc)
        message = " ".join(str(exc).splitlines())  # one line, whatever the message (a library's may hold several)
        if code != ExitCode.INTERNAL_ERROR:  # bad input, a failed check, no variant: its one line says it all
            sys.stderr.write(f"r2s {verb}: {message}\n")
            return code
        if os.environ.get("R2S_DEBUG"):  # a bug: one line by default, the traceback on request
            raise
        sys.stderr.write(f"r2s {verb}: internal error: {type(exc).__name__}: {message} (R2S_DEBUG=1 shows the "
                         "traceback)\n")
        return code
