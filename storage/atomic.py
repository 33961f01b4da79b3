"""Atomic writes for every output (frames, programs, reports): a temporary file beside the target, then
rename, so a crash or kill never leaves half a file where a reader looks (ScenarioNet's writer discipline).

An output given as a symbolic link is written through it (`place`): the file or folder it points to is replaced,
beside itself, and the link stays a link. Renaming over the link instead would turn it into a real file or
folder, leaving the file it points to stale and the link lost (and a folder's rename aside would hide the link
in a temporary).

Temporaries are named `.<target name>.<host>-<pid>.<random>.tmp` (hidden: dataset readers skip names starting
with "."), so that the next write of the same target can tell its own kind of leftovers from a live writer's:
one of this host whose process is gone was left by a crash or a kill -9, and is removed (`remove_stale`).
"""

from __future__ import annotations

import errno
import hashlib
import os
import re
import secrets
import shutil
import socket
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

HOST_TAG = hashlib.sha1(socket.gethostname().encode()).hexdigest()[:8]  # a pid means something on its host only


def place(target: str | os.PathLike) -> Path:
    """Where a write of `target` lands: its absolute path with every symbolic link followed (a link that points
    nowhere yet: where it points). A loop of links is an OSError (ELOOP), as opening it would be, and a path
    below a file a NotADirectoryError (a write would fail there after all the work)."""
    real = Path(os.path.realpath(target))
    if real.is_symlink():  # realpath leaves a link it cannot resolve: a loop
        raise OSError(errno.ELOOP, "is a loop of symbolic links", os.fspath(target))
    above = next(p for p in real.parents if p.exists())  # the folders below it are made by the write
    if not above.is_dir():
        raise NotADirectoryError(errno.ENOTDIR, f"is inside {above}, which is not a directory", os.fspath(target))
    return real


def temp_prefix(target: str | os.PathLike) -> str:
    """The start of the name of this process's temporaries for `target`."""
    return f".{Path(target).name}.{HOST_TAG}-{os.getpid()}."


def remove_stale(target: str | os.PathLike) -> list[Path]:
    """Remove the temporaries of `target` (files or directories, named by temp_prefix, ending in .tmp or
    .tmp.old) that a process of this host left when it died; a live writer's, or another host's, stay."""
    target = Path(target)
    try:
        siblings = list(target.parent.iterdir())
    except OSError:
        return []
    pattern = re.compile(re.escape(f".{target.name}.") + r"([0-9a-f]{8})-(\d+)\..*\.tmp(\.old)?")
    removed = []
    for p in siblings:
        m = pattern.fullmatch(p.name)
        if m is None or m.group(1) != HOST_TAG or _alive(int(m.group(2))):
            continue
        if p.is_dir() and not p.is_symlink():
            shutil.rmtree(p, ignore_errors=True)
        else:
            p.unlink(missing_ok=True)
        removed.append(p)
    return removed


def _alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # alive, someone else's
        return True
    return True


def temp_directory(target: str | os.PathLike) -> Path:
    """A new empty directory beside `target`, named as this process's temporaries of it (the stale ones of
    crashed processes removed first). mkdir, not mkdtemp (0700): an output gets the user's usual permissions."""
    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    remove_stale(target)
    stage = target.parent / f"{temp_prefix(target)}{secrets.token_hex(4)}.tmp"
    stage.mkdir()
    return stage


@contextmanager
def atomic_path(target: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path in the directory of the target's place (links followed); on success rename it
    over the target. A target that is a directory is an IsADirectoryError before anything is written."""
    given, target = target, place(target)
    if target.is_dir():
        raise IsADirectoryError(errno.EISDIR, "is a directory; this output is one file: name a file", os.fspath(given))
    target.parent.mkdir(parents=True, exist_ok=True)
    remove_stale(target)
    fd, tmp = tempfile.mkstemp(prefix=temp_prefix(target), suffix=".tmp", dir=target.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        # mkstemp creates 0600; an output is for the team, so give it what a plain open() would (umask).
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, target)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_text_atomic(target: str | os.PathLike, text: str) -> None:
    with atomic_path(target) as tmp:
        tmp.write_text(text, encoding="utf-8")


@contextmanager
def parquet_writer(target: str | os.PathLike, schema) -> Iterator:
    """A pyarrow ParquetWriter (zstd) into a temporary file that becomes `target` when the block succeeds."""
    import pyarrow.parquet as pq

    with atomic_path(target) as tmp, pq.ParquetWriter(tmp, schema, compression="zstd") as writer:
        yield writer
