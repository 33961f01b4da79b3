"""Input files are regular files: every path a verb or an extractor reads goes through here.

A path given to r2s may be a symbolic link to /dev/zero (endless data: a reader runs until memory runs out), a
FIFO (opening it blocks until a writer comes, reading it until the writer leaves), a socket or a device. Only
regular files are read, after symbolic links are followed; a file is opened with O_NONBLOCK and checked with
fstat on the open descriptor before a byte is read (so a FIFO never blocks and a file swapped after a check is
still caught), and at most a limit + 1 bytes are read. Readers of libraries that open paths themselves (the
nuScenes devkit, rosbags, pyarrow's memory maps) get `check_regular` on each path first: stat never blocks.

Refusals are OSErrors (strerror says what the path is), so a caller's existing `except OSError` turns them into
its own one-line error. Like all of storage, it imports nothing of r2sgen.
"""

from __future__ import annotations

import errno
import fcntl
import os
import stat
from typing import BinaryIO


class NotRegularFile(OSError):
    """The path is a directory, FIFO, socket or device (possibly through a symbolic link)."""


class FileTooLarge(OSError):
    """The file holds more bytes than its reader's limit."""


def kind(mode: int) -> str:
    """What a file of this st_mode is, in words."""
    for test, name in ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
                       (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
                       (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return name
    return "a regular file" if stat.S_ISREG(mode) else "not a regular file"


def _refuse(path: str | os.PathLike, mode: int) -> NotRegularFile:
    link = " (through a symbolic link)" if os.path.islink(path) else ""
    code = errno.EISDIR if stat.S_ISDIR(mode) else errno.EINVAL
    return NotRegularFile(code, f"is {kind(mode)}{link}, not a regular file", str(path))


def check_regular(path: str | os.PathLike, limit: int | None = None) -> os.stat_result:
    """stat(path) (symbolic links followed; never blocks) when it is a regular file of at most `limit` bytes."""
    st = os.stat(path)
    if not stat.S_ISREG(st.st_mode):
        raise _refuse(path, st.st_mode)
    if limit is not None and st.st_size > limit:
        raise _too_large(path, limit)
    return st


def is_regular(path: str | os.PathLike) -> bool:
    """Whether path (symbolic links followed) is a regular file; False for anything that does not exist."""
    try:
        return stat.S_ISREG(os.stat(path).st_mode)
    except (OSError, ValueError):
        return False


def _too_large(path: str | os.PathLike, limit: int) -> FileTooLarge:
    return FileTooLarge(errno.EFBIG, f"is larger than the limit of {_size(limit)}", str(path))


def _size(n: int) -> str:
    return f"{n / 2**20:g} MB" if n >= 2**20 else f"{n} bytes"


def open_regular(path: str | os.PathLike, limit: int | None = None) -> BinaryIO:
    """A regular file opened for binary reading (see the module's docstring); the caller closes it."""
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC | getattr(os, "O_NOCTTY", 0))
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise _refuse(path, st.st_mode)
        if limit is not None and st.st_size > limit:
            raise _too_large(path, limit)
        fcntl.fcntl(fd, fcntl.F_SETFL, fcntl.fcntl(fd, fcntl.F_GETFL) & ~os.O_NONBLOCK)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def read_regular(path: str | os.PathLike, limit: int) -> bytes:
    """The bytes of a regular file of at most `limit` bytes; never reads more than limit + 1 (a file that grows
    while it is read is still refused). Reads its size + 1 first, not limit + 1: read(n) reserves n bytes up front,
    and a limit of gigabytes would reserve that much address space for a small file."""
    with open_regular(path, limit) as fh:
        chunks = [fh.read(min(os.fstat(fh.fileno()).st_size, limit) + 1)]
        total = len(chunks[0])
        while chunks[-1] and total <= limit:  # it grew since fstat: read on, never past limit + 1
            chunks.append(fh.read(min(limit + 1 - total, 2**20)))
            total += len(chunks[-1])
    if total > limit:
        raise _too_large(path, limit)
    return b"".join(chunks)
