"""`r2s report programs.parquet --out DIR`: statistics tables and plots as DIR/report.md and DIR/report.html.

The report is built in a temporary directory beside DIR and renamed into place, so a failure or a kill leaves
either the previous report or none, never half of one.
"""

from __future__ import annotations

import argparse
import os
import secrets
import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("programs", help="programs file or dataset directory written by `r2s run`")
    p.add_argument("--frames", metavar="PATH", help="the frames the programs came from: fills in the commands "
                   "that render the frames worth a look")
    p.add_argument("--out", required=True, metavar="DIR", help="report directory (replaced if it holds a report)")
    p.add_argument("--max-table-rows", type=int, default=40, metavar="N",
                   help="frames shown in the side-by-side (Table 3) table; more are sampled evenly over N (default 40)")
    p.add_argument("--query", metavar="PATTERN", help="a section on the frames that match this pattern file (as "
                   "`r2s query` reads it; needs --frames): the match count and the frames with the most bindings")
    p.add_argument("--query-top", type=int, default=10, metavar="N",
                   help="matching frames listed with their programs (default 10)")


def _report_files() -> frozenset[str]:
    from pipeline.report.document import HTML_NAME, MD_NAME
    from pipeline.report.plots import PLOT_FILES

    return frozenset((MD_NAME, HTML_NAME, *PLOT_FILES))


def _check_replaceable(target: Path) -> None:
    """DIR is replaced wholesale, so it must be absent, empty or an earlier report: never a user's other files."""
    from pipeline.errors import UserError

    if not target.exists():
        return
    if not target.is_dir():
        raise UserError(f"--out {target} exists and is not a directory")
    foreign = sorted(e.name for e in target.iterdir() if e.name not in _report_files())
    if foreign:
        raise UserError(f"--out {target} holds files that are not part of a report ({', '.join(foreign[:3])}); "
                        "choose an empty or new directory")


@contextmanager
def staged_directory(target: Path) -> Iterator[Path]:
    """Yield an empty directory beside target; on success it takes target's place (an old target is removed)."""
    from pipeline.errors import UserError

    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        # mkdir (not mkdtemp, which makes it 0700) so the report gets the user's usual permissions.
        stage = target.parent / f".{target.name}.{os.getpid()}.{secrets.token_hex(4)}.tmp"
        stage.mkdir()
    except OSError as exc:
        raise UserError(f"cannot write beside --out {target}: {exc.strerror or exc}") from None
    retired = stage.with_name(stage.name + ".old")
    try:
        yield stage
        if target.exists():
            os.replace(target, retired)  # rename aside first: rename(2) will not replace a non-empty directory
        os.replace(stage, target)
    finally:
        shutil.rmtree(stage, ignore_errors=True)
        shutil.rmtree(retired, ignore_errors=True)


def run(args: argparse.Namespace) -> int:
    from pipeline.errors import UserError
    from pipeline.report.stats import ProgramsDB

    if args.max_table_rows < 2:
        raise UserError(f"--max-table-rows must be at least 2, got {args.max_table_rows}")
    extra = _query_sections(args)  # a bad pattern or option: exit 2 before anything is read or written
    target = Path(args.out)
    with ProgramsDB(args.programs) as db:  # ProgramsError (exit 2) before anything is written
        if db.rows == 0:
            raise UserError(f"{args.programs} has no rows: nothing to report (did `r2s run` process any frame?)")
        _check_replaceable(target)
        from pipeline.report.document import HTML_NAME, write_report

        with staged_directory(target) as stage:
            write_report(args.programs, stage, frames=args.frames, max_table_rows=args.max_table_rows, db=db,
                         extra=extra)
    print(target / HTML_NAME)
    return 0


def _query_sections(args: argparse.Namespace) -> tuple:
    from pipeline.errors import UserError

    if args.query is None:
        return ()
    from pipeline.cli.inputs import read_text_file
    from pipeline.report.query_section import query_section
    from synth.dsl import DslError
    from synth.pattern import parse_pattern

    if args.frames is None:
        raise UserError("--query needs --frames: the frames the programs came from, where the pattern is matched")
    if args.query_top < 1:
        raise UserError(f"--query-top must be at least 1, got {args.query_top}")
    try:
        pattern = parse_pattern(read_text_file(args.query, "pattern"))
    except DslError as exc:
        raise UserError(f"{args.query}: {exc}") from None
    from extractors.frames_dataset import FramesDataset

    FramesDataset.open(args.frames)  # a missing or foreign frames path is refused before the report is built
    return (query_section(pattern, Path(args.query).name, args.frames, args.query_top),)
