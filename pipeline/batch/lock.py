"""The lock of an output: one writer at a time for `r2s run --out PATH`, whatever machine or TMPDIR it runs from.

The lock is a file beside the output, `.<name>.lock` in the output's own directory (hidden from dataset readers,
which skip names starting with "."), held with a POSIX record lock (fcntl.lockf) for the life of the run. It
lives with the output, so two runs see the same lock whatever their TMPDIR; the kernel drops a record lock when
its process ends, however it ends (kill -9 included), so there is never a stale lock to clean up by hand.

On a shared filesystem (a dask run's coordinators on two hosts writing one output on NFS), it relies on the
filesystem's record locks: Linux NFS clients take POSIX locks on the server (NLM for NFSv3, in-protocol for
NFSv4), so a lock taken on one host is seen on the others; flock(2) is not used because a Linux NFS client
emulates it with these same locks, and other filesystems may keep it local. Where the filesystem refuses record
locks (ENOLCK, EOPNOTSUPP: some FUSE mounts), the lock falls back to the file's content: the holder's host and
pid, written with O_EXCL; a holder on this host that is no longer alive is stale and replaced, a holder on
another host is refused with its name (remove the file if that run is gone).

The file says who holds it (host, pid, start time), so a refused run can say whom it waits for. It is removed
when the run ends normally; after a kill it stays, empty of any lock, and the next run takes it.
"""

from __future__ import annotations

import errno
import fcntl
import json
import os
import socket
import time
from pathlib import Path

from pipeline.errors import UserError

_NO_LOCKS = {errno.ENOLCK, errno.EOPNOTSUPP, errno.ENOSYS, errno.EINVAL}


def lock_path(out: str | os.PathLike) -> Path:
    # beside the output's real place: runs naming it through a link and by its path take one lock
    out = Path(os.path.realpath(out))
    return out.parent / f".{out.name}.lock"


class OutputLock:
    """Held from `acquire()` until `release()` or the end of the process."""

    def __init__(self, out: str | os.PathLike) -> None:
        self.out = Path(out)
        self.path = lock_path(out)
        self._fd: int | None = None
        self._by_content = False

    def acquire(self) -> None:
        try:
            self._acquire()
        except OSError as exc:  # cannot create or write the lock file: a read-only or full output
            raise UserError(f"cannot write {self.path}: {exc.strerror or exc}") from None

    def _acquire(self) -> None:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        for _ in range(10):  # the file may be removed by its holder between our open and our lock: try again
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
            try:
                fcntl.lockf(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError as exc:
                os.close(fd)
                if exc.errno in (errno.EACCES, errno.EAGAIN):
                    raise UserError(self._busy_message()) from None
                if exc.errno in _NO_LOCKS:
                    self._acquire_by_content()
                    return
                raise
            if _same_file(fd, self.path):
                self._fd = fd
                self._write_holder(fd)
                return
            os.close(fd)  # we locked a file its holder had just removed: lock the new one
        raise UserError(f"cannot take the lock {self.path}: it keeps being replaced")

    def release(self) -> None:
        """Remove the file while still holding it, then let go (a run waiting to open it opens a new one)."""
        if self._fd is not None:
            try:
                if _same_file(self._fd, self.path):
                    self.path.unlink()
            except OSError:
                pass
            os.close(self._fd)
            self._fd = None
        elif self._by_content:
            try:
                if _holder(self.path).get("pid") == os.getpid():
                    self.path.unlink()
            except OSError:
                pass
            self._by_content = False

    def _write_holder(self, fd: int) -> None:
        os.ftruncate(fd, 0)
        os.pwrite(fd, _holder_text().encode(), 0)

    def _busy_message(self) -> str:
        who = _holder(self.path)
        by = f" (pid {who['pid']} on {who['host']}, since {who['since']})" if who else ""
        return (f"another r2s run{by} is writing {self.out} (lock {self.path}); wait for it or choose another "
                "--out")

    def _acquire_by_content(self) -> None:
        """For filesystems without record locks: the holder's host and pid, created exclusively."""
        for _ in range(3):
            try:
                fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
            except FileExistsError:
                who = _holder(self.path)
                here = who.get("host") == socket.gethostname()
                if who and here and not _alive(int(who.get("pid", 0))):
                    self.path.unlink(missing_ok=True)  # its run is gone: stale
                    continue
                if not who and time.time() - _mtime(self.path) > 60:
                    self.path.unlink(missing_ok=True)  # empty for a minute: a crash between create and write
                    continue
                gone = "" if here else "; the filesystem has no locks, so if that run is gone, remove the lock file"
                raise UserError(self._busy_message() + gone) from None
            try:
                os.write(fd, _holder_text().encode())
            finally:
                os.close(fd)
            self._by_content = True
            return
        raise UserError(f"cannot take the lock {self.path}")


def _holder_text() -> str:
    return json.dumps({"host": socket.gethostname(), "pid": os.getpid(),
                       "since": time.strftime("%Y-%m-%dT%H:%M:%S%z")}) + "\n"


def _holder(path: Path) -> dict:
    try:
        with open(path, "rb") as f:
            data = json.loads(f.read(4096) or b"{}")
        return data if isinstance(data, dict) and {"host", "pid", "since"} <= set(data) else {}
    except (OSError, ValueError):
        return {}


def _same_file(fd: int, path: Path) -> bool:
    try:
        a, b = os.fstat(fd), os.stat(path)
    except FileNotFoundError:
        return False
    return (a.st_dev, a.st_ino) == (b.st_dev, b.st_ino)


def _alive(pid: int) -> bool:
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _mtime(path: Path) -> float:
    try:
        return path.stat().st_mtime
    except OSError:
        return time.time()
