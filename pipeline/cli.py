"""`r2s VERB ...`: every operation is a verb of one command (ScenarioNet's style).

Each verb lives in its own module with `add_arguments(parser)` and `run(args) -> int`, imported only when
that verb runs, so `r2s synth` never pays for pandas, Scenic or the dataset readers.
Exit codes: 0 done; 2 bad input or usage (one line on stderr, nothing written); 1 internal error; 3 from r2s check
(the program does not contain the scene); 4 from r2s sample and render (no variant found: the one-line error's
class carries `exit_code`).
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys

# verb -> (module, one-line help)
VERBS: dict[str, tuple[str, str]] = {
    "synth": ("pipeline.cmd_synth", "synthesize a minimum-cost program for one scene JSON"),
    "check": ("pipeline.cmd_check", "does a DSL program contain a scene? (the semantics checker)"),
    "extract": ("pipeline.cmd_extract", "recorded data (nuScenes, ScenarioNet, AV2, MCAP, ROS bags) to frames.parquet"),
    "scene": ("pipeline.cmd_scene", "print one frame of a frames.parquet as scene JSON"),
    "run": ("pipeline.cmd_run", "one program per frame of a frames.parquet, in parallel, with limits and resume"),
    "query": ("pipeline.cmd_query", "every frame of a frames dataset that matches a DSL pattern (scenario mining)"),
    "report": ("pipeline.cmd_report", "report.md / report.html with plots from a programs.parquet"),
    "render": ("pipeline.cmd_render", "bird's-eye view of a scene, its program's references and sampled variants"),
    "sample": ("pipeline.cmd_sample", "sample scenes from a generated Scenic program with the Scenic compiler"),
    "eval-frontend": ("pipeline.cmd_eval_frontend", "detection metrics of predicted frames against ground truth"),
}


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # one line and exit 2, as for any bad input
        sys.stderr.write(f"{self.prog}: {message}\n")
        sys.exit(2)


def _top_help() -> str:
    width = max(map(len, VERBS))
    rows = "\n".join(f"  {v.ljust(width)}  {h}" for v, (_, h) in VERBS.items())
    return f"usage: r2s VERB [options]\n\nverbs:\n{rows}\n\n`r2s VERB --help` for a verb's options.\n"


def build_parser(verb: str) -> argparse.ArgumentParser:
    """The argument parser of one verb (its module's add_arguments)."""
    module = importlib.import_module(VERBS[verb][0])
    parser = _Parser(prog=f"r2s {verb}", description=VERBS[verb][1])
    module.add_arguments(parser)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help"):
        sys.stdout.write(_top_help())
        return 0 if argv else 2
    if argv[0] == "--version":
        from synth import __version__

        print(f"r2sgen {__version__}")
        return 0
    verb = argv[0]
    if verb not in VERBS:
        sys.stderr.write(f"r2s: unknown verb {verb!r} (verbs: {', '.join(VERBS)})\n")
        return 2
    module = importlib.import_module(VERBS[verb][0])
    args = build_parser(verb).parse_args(argv[1:])
    from pipeline.errors import user_error_types

    try:
        return int(module.run(args) or 0)
    except user_error_types() as exc:
        sys.stderr.write(f"r2s {verb}: {exc}\n")
        return getattr(exc, "exit_code", 2)
    except KeyboardInterrupt:
        sys.stderr.write(f"r2s {verb}: interrupted\n")
        return 130
    except BrokenPipeError:
        return 0
    except Exception as exc:  # a bug: one line by default, the traceback on request
        if os.environ.get("R2S_DEBUG"):
            raise
        sys.stderr.write(f"r2s {verb}: internal error: {type(exc).__name__}: {exc} (R2S_DEBUG=1 shows the traceback)\n")
        return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
