"""`r2s report programs.parquet --out DIR`: statistics tables and plots as DIR/report.md and DIR/report.html.

The report is built in a temporary directory beside DIR and renamed into place (pipeline.report.output), so a
failure or a kill leaves either the previous report or none, never half of one. What it does is pipeline.report.output.report (`from pipeline.report import report`).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from pipeline.errors import UserError
from pipeline.outputs import check_apart


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
    from pipeline.cli.inputs import read_pattern
    from pipeline.report.output import report

    check_apart(args.out, [("programs", args.programs), ("frames", args.frames), ("pattern", args.query),
                           ("frame programs", args.frame_programs)], directory=True)
    if args.frame_programs is not None and args.frames is None:
        raise UserError("--frame-programs needs --frames: the frames both programs came from (where each frame is)")
    if args.query is not None and args.frames is None:
        raise UserError("--query needs --frames: the frames the programs came from, where the pattern is matched")
    pattern = None if args.query is None else read_pattern(args.query)
    summary = report(args.programs, args.out, frames=args.frames, query=pattern,
                     query_name=Path(args.query).name if args.query else "pattern", query_top=args.query_top,
                     max_table_rows=args.max_table_rows, frame_programs=args.frame_programs)
    print(f"r2s report: {summary.line} -> {summary.html}")
    return 0
