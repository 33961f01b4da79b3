"""Output folders replaced whole (`r2s export`, `r2s report`, `r2s extract --out DIR`): the one rule by which
such a folder never loses or hides a user's files.

A folder is replaced only when it is absent, empty, or holds nothing but what the writer itself writes there
(`owns`: its own file names, regular files only, never a link): a folder of a user's files given as --out by
mistake is refused whole, not emptied. It is never the working directory or one holding it (replacing it would
leave the shell in a deleted folder). A symbolic link is followed (storage.atomic.place): the folder it points to
is replaced and the link stays. The new folder is built beside its place and renamed into it when whole, after
the rule is checked again (files put there meanwhile are kept), so a reader never sees half of it and a failure
leaves the old folder as it was.

Refusals are OSErrors (`NotReplaceable`, NotADirectoryError), strerror saying what to do, so that the verb's own
`except OSError` makes them its one line. Like all of storage, it imports nothing of r2sgen above it.
"""

from __future__ import annotations

import errno
import os
import secrets
import shutil
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from storage.atomic import place, temp_directory, temp_prefix

Owns = Callable[[os.DirEntry], bool]  # whether an entry (never a link: those are refused before) is the writer's


class NotReplaceable(OSError):
    """The folder holds what is not the writer's own, or is the working directory."""


def check_replaceable(target: str | os.PathLike, owns: Owns, what: str) -> Path:
    """The place of `target` (links followed) when a folder may be put there: absent, empty or holding only
    entries `owns` accepts (what: the writer's files in words, for the refusal)."""
    given, real = os.fspath(target), place(target)
    if not real.exists():
        return real
    if not real.is_dir():
        raise NotADirectoryError(errno.ENOTDIR, "exists and is not a directory", given)
    if real == Path.cwd() or real in Path.cwd().parents:
        raise NotReplaceable(errno.EBUSY, "is the working directory (or holds it), which the output would replace "
                             "whole; name a folder of its own", given)
    with os.scandir(real) as entries:
        foreign = sorted(e.name for e in entries if e.is_symlink() or not owns(e))
    if foreign:
        more = f", and {len(foreign) - 3} more" if len(foreign) > 3 else ""
        raise NotReplaceable(errno.ENOTEMPTY, f"holds files that are not {what} ({', '.join(foreign[:3])}{more}); "
                             "move them or choose another folder", given)
    return real


def only_files(names: Callable[[str], bool]) -> Owns:
    """An `owns` for a writer of regular files whose names `names` accepts."""
    return lambda e: e.is_file(follow_symlinks=False) and names(e.name)


@contextmanager
def replaced_directory(target: str | os.PathLike, owns: Owns, what: str) -> Iterator[Path]:
    """Yield an empty directory beside the place of `target`; when the block ends normally it takes that place
    (replace_with). Raises OSError (refusals included)."""
    stage = temp_directory(check_replaceable(target, owns, what))
    try:
        yield stage
        replace_with(stage, target, owns, what)
    finally:
        shutil.rmtree(stage, ignore_errors=True)


def replace_with(stage: Path | None, target: str | os.PathLike, owns: Owns, what: str) -> None:
    """Put the directory `stage` (beside it; None: nothing) in the place of `target`, which check_replaceable
    allows (checked now, so files put there since an earlier check are kept); the old folder is removed, or put
    back when the swap fails."""
    real = check_replaceable(target, owns, what)
    # named as a temporary of the target: one a crash leaves is removed by the next write (remove_stale)
    retired = real.with_name(f"{temp_prefix(real)}{secrets.token_hex(4)}.tmp.old")
    try:
        if real.exists():
            os.replace(real, retired)  # rename aside first: rename(2) will not replace a non-empty directory
        if stage is not None:
            try:
                os.replace(stage, real)
            except OSError:
                if retired.exists():
                    os.replace(retired, real)  # the old folder back: a failed swap loses nothing
                raise
    finally:
        shutil.rmtree(retired, ignore_errors=True)
