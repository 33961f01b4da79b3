"""How every verb writes its output: never over one of its inputs, and never half of it.

`check_apart`: what every verb that writes checks of its output before any work: it must not be one of its inputs.

A verb writes its output by replacing it whole (a temporary file or directory beside it, then a rename), so an
output that is an input destroys the input, and an output inside an input directory (a frames or programs
dataset, an extractor's input folder) is read back as input by the next run. Paths are compared after
resolving symlinks (os.path.realpath) and, for files that exist, by identity (os.path.samefile: hard links):
`--out F` for the input F, a link to F, or `F/part.parquet` of a dataset F is refused with one line, exit 2.

`staged_directory`: an output directory is built beside its place and renamed into it when whole (files are
written by storage.atomic.atomic_path, the same discipline for one file).
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path

from pipeline.errors import UserError


def _real(path: str | os.PathLike) -> Path:
    return Path(os.path.realpath(os.fspath(path)))


def _is_path(value: object) -> bool:
    return value is not None and str(value) not in ("", "-") and "://" not in str(value)


def check_apart(out: str | os.PathLike, inputs: Iterable[tuple[str, str | os.PathLike | None]],
                flag: str = "--out", directory: bool = False) -> None:
    """Refuse (UserError) an output that is an input, is inside an input directory, or (`directory`: the verb
    writes a directory there, replacing it or adding to it) holds an input. `inputs`: (what it is, path) pairs;
    None, "-" (standard input) and URLs are skipped. A verb that writes one file refuses a directory itself."""
    if not _is_path(out):
        return
    dst = _real(out)
    for what, path in inputs:
        if not _is_path(path):
            continue
        src = _real(path)
        same = src == dst
        if not same and src.exists() and dst.exists():
            try:
                same = os.path.samefile(src, dst)
            except OSError:
                same = False
        if same:
            raise UserError(f"{flag} {out} is the {what} {path} (the same file or directory); choose another {flag}")
        if src in dst.parents:
            raise UserError(f"{flag} {out} is inside the {what} {path}; choose a {flag} outside it")
        if directory and dst in src.parents:
            raise UserError(f"the {what} {path} is inside {flag} {out}, which the output replaces; choose another "
                            f"{flag}")


def stage_beside(target: Path) -> Path:
    """A new empty directory beside `target` (storage.atomic.temp_directory), or a UserError (exit 2)."""
    from storage.atomic import temp_directory

    try:
        return temp_directory(target)
    except OSError as exc:
        raise UserError(f"cannot write beside --out {target}: {exc.strerror or exc}") from None


@contextmanager
def staged_directory(target: str | os.PathLike) -> Iterator[Path]:
    """Yield an empty directory beside `target`; when the block ends normally it takes target's place (an old
    target is removed), so a reader never sees half an output directory: a failure (a full disk, an error, a
    kill) leaves the old target as it was. A write that fails (OSError) is a UserError (exit 2)."""
    target = Path(target)
    stage = stage_beside(target)
    retired = stage.with_name(stage.name + ".old")
    try:
        try:
            yield stage
        except OSError as exc:
            raise UserError(f"cannot write {target}: {exc.strerror or exc}") from None
        if target.exists():
            os.replace(target, retired)  # rename aside first: rename(2) will not replace a non-empty directory
        os.replace(stage, target)
    finally:
        shutil.rmtree(stage, ignore_errors=True)
        shutil.rmtree(retired, ignore_errors=True)


@contextmanager
def staged_files(directory: str | os.PathLike) -> Iterator[Path]:
    """Yield an empty directory beside `directory`; when the block ends normally, every file in it is renamed
    into `directory` (created if need be), whose other files stay. The files are written, and may fail (a full
    disk: a UserError, exit 2), before any of them moves; renames need no space, so an output never has some of
    them only."""
    directory = Path(directory)
    stage = stage_beside(directory)
    try:
        try:
            yield stage
            directory.mkdir(parents=True, exist_ok=True)
            for f in sorted(stage.iterdir()):
                os.replace(f, directory / f.name)
        except OSError as exc:
            raise UserError(f"cannot write {directory}: {exc.strerror or exc}") from None
    finally:
        shutil.rmtree(stage, ignore_errors=True)
