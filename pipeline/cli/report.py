"""`r2s report programs.parquet --out DIR`: statistics tables and plots as DIR/report.md and DIR/report.html.

The report is built in a temporary directory beside DIR and renamed into place (pipeline.report.output), so a
failure or a kill leaves either the previous report or none, never half of one.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from pipeline.errors import UserError
from pipeline.outputs import check_apart, staged_directory


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("programs", help="programs file or dataset directory written by `r2s run`")
    p.add_argument("--frames", metavar="PATH", help="the frames the programs came from: fills in the commands "
                   "that render the frames worth a look")
    p.add_argument("--out", required=True, metavar="DIR", help="report directory (replaced if it holds a report)")
    p.add_argument("--max-table-rows", type=int, default=40, metavar="N",
                   help="frames shown in the side-by-side (Table 3) table; more are sampled evenly over N (default 40)")
    p.add_argument("--query", metavar="PATTERN", help="a section on the frames that match this pattern file (as "
                   "`r2s query` reads it; needs --frames): the match count, the frames with the most bindings and the longest events")
    p.add_argument("--query-top", type=int, default=10, metavar="N",
                   help="matching frames listed with their programs (default 10)")
    p.add_argument("--frame-programs", metavar="PATH",
                   help="for window programs (r2s run --window): the per-frame programs of the same frames (r2s run "
                        "without --window; needs --frames), to compare each window's cost with its frames' own")


def run(args: argparse.Namespace) -> int:
    from pipeline.report.output import check_replaceable
    from pipeline.report.stats import ProgramsDB

    check_apart(args.out, [("programs", args.programs), ("frames", args.frames), ("pattern", args.query),
                           ("frame programs", args.frame_programs)], directory=True)
    if args.frame_programs is not None and args.frames is None:
        raise UserError("--frame-programs needs --frames: the frames both programs came from (where each frame is)")
    if args.max_table_rows < 2:
        raise UserError(f"--max-table-rows must be at least 2, got {args.max_table_rows}")
    from pipeline.report.window_section import window_section

    # A bad pattern or option: exit 2 before anything is read or written. The windows' section is there for
    # window programs only (r2s run --window).
    extra = (*_query_sections(args), window_section(args.frames, args.frame_programs))
    target = Path(args.out)
    with ProgramsDB(args.programs) as db:  # ProgramsError (exit 2) before anything is written
        if db.rows == 0:
            raise UserError(f"{args.programs} has no rows: nothing to report (did `r2s run` process any frame?)")
        check_replaceable(target)
        from pipeline.report.document import HTML_NAME, write_report

        with staged_directory(target) as stage:
            write_report(args.programs, stage, frames=args.frames, max_table_rows=args.max_table_rows, db=db,
                         extra=extra)
        line = summary_line(db)
    print(f"r2s report: {line} -> {target / HTML_NAME}")
    return 0


def summary_line(db) -> str:
    """What the report is about, in one line, as every verb ends: frames, configs and how each fared."""
    from pipeline.report.stats import by_config

    overview = db.overview
    parts = [f"{overview.frames} frames", f"{len(overview.configs)} config{'s' * (len(overview.configs) != 1)}"]
    for g in by_config(db):
        median = "" if g.runtime_median is None else f", median {1000 * g.runtime_median:.1f} ms"
        parts.append(f"{g.config}: {g.optimal_pct:.1f}% optimal{median}")
    return "; ".join(parts)


def _query_sections(args: argparse.Namespace) -> tuple:
    if args.query is None:
        return ()
    from pipeline.cli.inputs import read_pattern
    from pipeline.report.query_section import query_section

    if args.frames is None:
        raise UserError("--query needs --frames: the frames the programs came from, where the pattern is matched")
    if args.query_top < 1:
        raise UserError(f"--query-top must be at least 1, got {args.query_top}")
    pattern = read_pattern(args.query)
    from extractors.frames_dataset import FramesDataset

    FramesDataset.open(args.frames)  # a missing or foreign frames path is refused before the report is built
    return (query_section(pattern, Path(args.query).name, args.frames, args.query_top),)
