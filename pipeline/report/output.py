"""Where `r2s report` writes: DIR is replaced wholesale, so it must be absent, empty or an earlier report, and the new
report is built in a directory beside it that takes its place only when complete (pipeline.outputs.staged_directory,
as every output directory)."""

from __future__ import annotations

from pathlib import Path

from pipeline.errors import UserError
from pipeline.report.document import HTML_NAME, MD_NAME
from pipeline.report.plots import PLOT_FILES


def report_files() -> frozenset[str]:
    return frozenset((MD_NAME, HTML_NAME, *PLOT_FILES))


def check_replaceable(target: Path) -> None:
    """DIR is replaced wholesale, so it must be absent, empty or an earlier report: never a user's other files."""
    if not target.exists():
        return
    if not target.is_dir():
        raise UserError(f"--out {target} exists and is not a directory")
    # A report's own files are regular files: a folder or a link named report.md is the user's, never ours.
    foreign = sorted(e.name for e in target.iterdir()
                     if e.name not in report_files() or e.is_symlink() or not e.is_file())
    if foreign:
        raise UserError(f"--out {target} holds files that are not part of a report ({', '.join(foreign[:3])}); "
                        "choose an empty or new directory")
