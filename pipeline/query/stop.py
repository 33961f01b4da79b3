"""A query stopped by Ctrl-C or SIGTERM leaves nothing behind: not its spill folder, not its temporary output,
not the folders it created for --out; it prints one line and exits 130 (Ctrl-C) or 143 (SIGTERM).

Python runs a signal handler only when the main thread returns to the interpreter, and during a DuckDB query it
does not (DuckDB runs the join in C++ for as long as it takes). So the handlers do nothing themselves: the
signal's number reaches a watcher thread through signal.set_wakeup_fd, and the watcher removes what the query
registered (`leftovers`) and ends the process at once (os._exit), wherever the main thread is.
"""

from __future__ import annotations

import os
import shutil
import signal
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from pipeline.errors import ExitCode

# What the running query has made, in the order it made it (removed in reverse).
_MADE: list[tuple[Path, str]] = []
_LOCK = threading.Lock()


@contextmanager
def leftover(path: str | os.PathLike, kind: str) -> Iterator[Path]:
    """Register `path` (kind: "file", "tree" or "folder", a folder removed only when empty) for removal if a signal
    stops the process while the block runs."""
    entry = (Path(path), kind)
    with _LOCK:
        _MADE.append(entry)
    try:
        yield entry[0]
    finally:
        with _LOCK:
            _MADE.remove(entry)


def _remove_all() -> None:
    with _LOCK:
        made = list(reversed(_MADE))
    for path, kind in made:
        try:
            if kind == "tree":
                shutil.rmtree(path, ignore_errors=True)
            elif kind == "folder":
                path.rmdir()  # only if empty: never a user's file
            else:
                path.unlink(missing_ok=True)
        except OSError:
            pass


@contextmanager
def cleaned_up_on_signal(verb: str) -> Iterator[None]:
    """While the block runs (in the main thread), Ctrl-C and SIGTERM remove the registered leftovers and end the
    process with one line on stderr; afterwards the previous handlers are back."""
    read, write = os.pipe()
    os.set_blocking(write, False)
    previous_fd = signal.set_wakeup_fd(write, warn_on_full_buffer=False)
    previous = {s: signal.signal(s, lambda *_: None) for s in (signal.SIGINT, signal.SIGTERM)}
    done = threading.Event()

    def watch() -> None:
        try:
            got = os.read(read, 1)
        except OSError:
            return
        if done.is_set() or not got:
            return
        code = ExitCode.INTERRUPTED if got[0] == signal.SIGINT else ExitCode.TERMINATED
        _remove_all()
        sys.stderr.write(f"r2s {verb}: {'interrupted' if code == ExitCode.INTERRUPTED else 'terminated'}\n")
        sys.stderr.flush()
        os._exit(code)

    watcher = threading.Thread(target=watch, name="r2s-stop", daemon=True)
    watcher.start()
    try:
        yield
    finally:
        done.set()
        signal.set_wakeup_fd(previous_fd)
        for s, handler in previous.items():
            signal.signal(s, handler)
        os.close(write)  # the watcher's read returns b"" and it ends
        watcher.join()
        os.close(read)
