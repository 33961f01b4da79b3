"""Where `r2s report` writes: DIR is replaced wholesale, so it must be absent, empty or an earlier report, and the new
report is built in a directory beside it that takes its place only when complete."""

from __future__ import annotations

import os
import secrets
import shutil
from collections.abc import Iterator
from contextlib import contextmanager
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
    foreign = sorted(e.name for e in target.iterdir() if e.name not in report_files())
    if foreign:
        raise UserError(f"--out {target} holds files that are not part of a report ({', '.join(foreign[:3])}); "
                        "choose an empty or new directory")


@contextmanager
def staged_directory(target: Path) -> Iterator[Path]:
    """Yield an empty directory beside target; on success it takes target's place (an old target is removed)."""
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
