"""`r2s report` (report, its Python API: `from pipeline.report import report`) and where it writes: DIR is replaced wholesale, so it must be absent, empty or an earlier report (storage.folders, the rule of every
folder replaced whole), and the new report is built in a directory beside it that takes its place only when complete (pipeline.outputs.staged_directory,
as every output directory)."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from pipeline.errors import UserError
from pipeline.outputs import check_apart, staged_directory
from pipeline.report.document import HTML_NAME, MD_NAME, write_report
from pipeline.report.plots import PLOT_FILES
from pipeline.report.stats import ProgramsDB, by_config
from pipeline.report.window_section import window_section
from synth.dsl import DslError


def report_files() -> frozenset[str]:
    return frozenset((MD_NAME, HTML_NAME, *PLOT_FILES))


REPORT = "part of a report"


def _report_file(entry: os.DirEntry) -> bool:
    # A report's own files are regular files: a folder or a link named report.md is the user's, never ours.
    return entry.is_file(follow_symlinks=False) and entry.name in report_files()


@dataclass(frozen=True)
class ReportSummary:
    """What `r2s report` wrote: report.html (report.md beside it) and its summary line (`line`)."""

    html: Path
    line: str


def report(programs: str | os.PathLike, out: str | os.PathLike, *, frames: str | os.PathLike | None = None,
           query=None, query_name: str = "pattern", query_top: int = 10, max_table_rows: int = 40,
           frame_programs: str | os.PathLike | None = None) -> ReportSummary:
    """`r2s report PROGRAMS --out OUT` in-process (docs/api.md): report.md, report.html and their plots into the
    directory `out` (replaced whole, so absent, empty or an earlier report). `frames` fills in the commands that
    render the frames worth a look; `query` (pattern text or a parsed pattern, named `query_name`; needs `frames`)
    adds the section on the frames that match it; `frame_programs` (window programs only: the per-frame programs of
    the same frames; needs `frames`) compares each window's cost with its frames' own. Bad input raises an
    InputError before anything is written."""
    programs, frames = str(programs), None if frames is None else str(frames)
    frame_programs = None if frame_programs is None else str(frame_programs)
    target = Path(out)
    check_apart(target, [("programs", programs), ("frames", frames), ("frame programs", frame_programs)],
                directory=True)
    if frame_programs is not None and frames is None:
        raise UserError("--frame-programs needs --frames: the frames both programs came from (where each frame is)")
    if max_table_rows < 2:
        raise UserError(f"--max-table-rows must be at least 2, got {max_table_rows}")
    # A bad pattern or option: refused before anything is read. The windows' section is there for window
    # programs only (r2s run --window).
    extra = (*_query_sections(query, query_name, frames, query_top), window_section(frames, frame_programs))
    with ProgramsDB(programs) as db:  # ProgramsError (exit 2) before anything is written
        if db.rows == 0:
            raise UserError(f"{programs} has no rows: nothing to report (did `r2s run` process any frame?)")
        with staged_directory(target, _report_file, REPORT) as stage:
            write_report(programs, stage, frames=frames, max_table_rows=max_table_rows, db=db, extra=extra)
        overview = db.overview
        parts = [f"{overview.frames} frames", f"{len(overview.configs)} config{'s' * (len(overview.configs) != 1)}"]
        for g in by_config(db):
            median = "" if g.runtime_median is None else f", median {1000 * g.runtime_median:.1f} ms"
            parts.append(f"{g.config}: {g.optimal_pct:.1f}% optimal{median}")
    return ReportSummary(target / HTML_NAME, "; ".join(parts))


def _query_sections(query, name: str, frames: str | None, top: int) -> tuple:
    if query is None:
        return ()
    # only --query loads the miner and the frames reader (~0.1 s of a report's start-up)
    from frames.dataset import FramesDataset
    from pipeline.report.query_section import query_section
    from synth.patterns.temporal import parse_query_pattern

    if frames is None:
        raise UserError("--query needs --frames: the frames the programs came from, where the pattern is matched")
    if top < 1:
        raise UserError(f"--query-top must be at least 1, got {top}")
    if isinstance(query, str):
        try:
            query = parse_query_pattern(query)
        except DslError as exc:
            raise UserError(f"{name}: {exc}") from None
    FramesDataset.open(frames)  # a missing or foreign frames path is refused before the report is built
    return (query_section(query, name, frames, top),)
