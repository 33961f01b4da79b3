"""How every verb writes its output: never over one of its inputs, and never half of it.

`check_apart`: what every verb that writes checks of its output before any work: it must not be one of its inputs,
a loop of symbolic links or below a file.

A verb writes its output by replacing it whole (a temporary file or directory beside it, then a rename), so an
output that is an input destroys the input, and an output inside an input directory (a frames or programs
dataset, an extractor's input folder) is read back as input by the next run. Paths are compared after
resolving symlinks (os.path.realpath) and, for files that exist, by identity (os.path.samefile: hard links):
`--out F` for the input F, a link to F, or `F/part.parquet` of a dataset F is refused with one line, exit 2.

`staged_directory`: an output directory is built beside its place and renamed into it when whole, and replaces
only a folder of the writer's own files (storage.folders; files are written by storage.atomic.atomic_path, the
same discipline for one file).
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path

from pipeline.errors import UserError
from storage.atomic import place, temp_directory
from storage.folders import NotReplaceable, Owns, check_replaceable, replaced_directory


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
    output_place(out, flag)  # a loop of links, a file where a folder must be: refused before any work
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


def output_place(out: str | os.PathLike, flag: str = "--out") -> Path:
    """Where an output lands: symbolic links followed (storage.atomic.place: a link given as --out is written
    through and stays a link), or a UserError (a loop of links)."""
    try:
        return place(out)
    except OSError as exc:
        raise UserError(f"{flag} {out} {exc.strerror}") from None


@contextmanager
def writing(out: str | os.PathLike, flag: str = "--out") -> Iterator[None]:
    """A block that writes the output `out` (storage.atomic): an OSError in it (a directory where one file goes,
    a read-only folder, a full disk) is one line, exit 2; the atomic write has left nothing."""
    try:
        yield
    except OSError as exc:
        raise UserError(f"cannot write {flag} {out}: {exc.strerror or exc}") from None


def check_folder(target: str | os.PathLike, owns: Owns, what: str, flag: str = "--out") -> None:
    """Refuse (UserError), before any work, a folder output that may not be replaced (storage.folders: absent,
    empty or the writer's own files only; never the working directory)."""
    try:
        check_replaceable(target, owns, what)
    except OSError as exc:
        raise UserError(f"{flag} {target} {exc.strerror or exc}") from None


@contextmanager
def staged_directory(target: str | os.PathLike, owns: Owns, what: str) -> Iterator[Path]:
    """Yield an empty directory beside `target`; when the block ends normally it takes target's place
    (storage.folders.replaced_directory: only a folder of the writer's own files is replaced, a link is followed),
    so a reader never sees half an output directory: a failure (a full disk, an error, a kill) leaves the old
    target as it was. A refusal or a write that fails (OSError) is a UserError (exit 2)."""
    check_folder(target, owns, what)
    try:
        with replaced_directory(target, owns, what) as stage:
            yield stage
    except NotReplaceable as exc:  # a user's file put there while the output was built
        raise UserError(f"--out {target} {exc.strerror}") from None
    except OSError as exc:
        raise UserError(f"cannot write {target}: {exc.strerror or exc}") from None


@contextmanager
def staged_files(directory: str | os.PathLike) -> Iterator[Path]:
    """Yield an empty directory beside `directory`; when the block ends normally, every file in it is renamed
    into `directory` (created if need be), whose other files stay. The files are written, and may fail (a full
    disk: a UserError, exit 2), before any of them moves; renames need no space, so an output never has some of
    them only."""
    real = output_place(directory)
    with scratch_beside(real) as stage:
        try:
            yield stage
            real.mkdir(parents=True, exist_ok=True)
            for f in sorted(stage.iterdir()):
                os.replace(f, real / f.name)
        except OSError as exc:
            raise UserError(f"cannot write {directory}: {exc.strerror or exc}") from None


@contextmanager
def scratch_beside(target: str | os.PathLike) -> Iterator[Path]:
    """A new empty directory beside the place of `target` (storage.atomic.temp_directory: a crashed writer's
    removed first), removed when the block ends; one that cannot be made is a UserError (exit 2)."""
    try:
        stage = temp_directory(output_place(target))
    except OSError as exc:
        raise UserError(f"cannot write beside {target}: {exc.strerror or exc}") from None
    try:
        yield stage
    finally:
        shutil.rmtree(stage, ignore_errors=True)
