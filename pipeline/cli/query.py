"""`r2s query FRAMES PATTERN.dsl --out matches.parquet`: every frame that matches a pattern (scenario mining).

PATTERN is a DSL program whose names are variables (types may be `Vehicle` or `Object`; Ranges of any width);
a match is an injective binding of its names to a frame's non-ego entities under which every statement holds by
the semantics `r2s check` uses. One row per matching frame (or per binding with --all, or per event with --events:
a maximal run of consecutive frames of a scene binding the same tracks); a summary line on stdout.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from pipeline.cli.options import add_config_option
from pipeline.errors import UserError
from pipeline.outputs import check_apart


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("frames", help="frames Parquet file or dataset directory (from r2s extract)")
    p.add_argument("pattern", help="pattern file: DSL statements whose names are variables, or steps over time "
                                   "(then [within T s], for at least T s, braking, ...: docs/dsl.md)")
    p.add_argument("--out", required=True, metavar="F", help="matches Parquet file (written atomically)")
    p.add_argument("--all", action="store_true", dest="all_bindings",
                   help="one row per binding instead of one per frame (with the first binding)")
    p.add_argument("--events", action="store_true",
                   help="one row per event instead: a maximal run of consecutive frames of a scene in which the same "
                        "binding (the same tracks) matches, with its first and last frame and its duration")
    p.add_argument("--min-duration", type=float, metavar="S",
                   help="with --events: only events at least S seconds long (last timestamp minus first)")
    add_config_option(p, ": the tolerances delta1, delta2; motion v_stop, dv")
    p.add_argument("--threads", type=int, metavar="N", help="DuckDB threads (default: every core)")
    p.add_argument("--memory-limit", type=int, metavar="MB",
                   help="DuckDB memory limit; beyond it the join spills beside --out (default: DuckDB's, 80%% of RAM)")


def run(args: argparse.Namespace) -> int:
    from pipeline.cli.inputs import load_config, read_pattern
    from pipeline.query.mining import query_frames
    from pipeline.query.stop import cleaned_up_on_signal

    for flag, value in (("--threads", args.threads), ("--memory-limit", args.memory_limit)):
        if value is not None and value < 1:
            raise UserError(f"{flag} must be at least 1, got {value}")
    check_apart(args.out, [("input frames", args.frames), ("pattern", args.pattern), ("config", args.config)])
    if Path(args.out).is_dir():
        raise UserError(f"--out {args.out} is a directory; matches are one Parquet file")
    config = load_config(args.config)
    pattern = read_pattern(args.pattern)
    with cleaned_up_on_signal("query"):  # Ctrl-C / SIGTERM: nothing left behind, one line, exit 130 / 143
        summary = query_frames(args.frames, pattern, args.out, all_bindings=args.all_bindings, config=config,
                               threads=args.threads, memory_limit_mb=args.memory_limit, events=args.events,
                               min_duration_s=args.min_duration)
    print(f"r2s query: {summary.line()} -> {args.out}")
    return 0
