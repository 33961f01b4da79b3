"""`r2s` as a real process under a watchdog, for inputs that could hang it or blow up its memory.

The child runs as `run_r2s` runs it; a thread samples its resident size (/proc/PID/status VmRSS) every few
milliseconds and kills it (SIGKILL) when it passes `max_rss_mb` or outlives `timeout`, so a reader of /dev/zero
or of a FIFO fails the test instead of the machine. VmHWM is not enough: it dies with the process, and
ru_maxrss carries the forking parent's peak over to the child.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from tests.support import ROOT


@dataclass(frozen=True)
class Bounded:
    returncode: int
    stdout: str
    stderr: str
    peak_rss_mb: float
    seconds: float
    killed: str | None  # "timeout" or "memory" when the watchdog killed it


def _rss_mb(pid: int) -> float:
    try:
        with open(f"/proc/{pid}/status", "rb") as f:
            for line in f:
                if line.startswith(b"VmRSS:"):
                    return int(line.split()[1]) / 1024
    except (OSError, ValueError):
        pass
    return 0.0


def run_bounded(*args: str, timeout: float = 60, max_rss_mb: float = 1500, cwd: Path | None = None,
                env: dict | None = None, stdin=subprocess.DEVNULL, command: list[str] | None = None) -> Bounded:
    """Run `r2s ARGS` (or `command`) under the watchdog; returns what it printed, its peak RSS and why it was
    killed, if it was."""
    cmd = command or [sys.executable, "-m", "pipeline.cli", *args]
    start = time.monotonic()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, stdin=stdin, text=True,
                            cwd=cwd or ROOT, env=env, start_new_session=True)
    state = {"peak": 0.0, "killed": None}

    def watch() -> None:
        while proc.poll() is None:
            state["peak"] = max(state["peak"], _rss_mb(proc.pid))
            why = ("memory" if state["peak"] > max_rss_mb else
                   "timeout" if time.monotonic() - start > timeout else None)
            if why:
                state["killed"] = why
                try:
                    os.killpg(proc.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
                return
            time.sleep(0.005)

    watcher = threading.Thread(target=watch, daemon=True)
    watcher.start()
    out, err = proc.communicate()
    watcher.join()
    return Bounded(proc.returncode, out, err, state["peak"], time.monotonic() - start, state["killed"])


def assert_refused(result: Bounded, contains: str | None = None, code: int = 2) -> None:
    """Refused promptly: not killed by the watchdog, the exit code, one line on stderr, no traceback."""
    assert result.killed is None, (result.killed, result.peak_rss_mb, result.stderr[-500:])
    assert result.returncode == code, (result.returncode, result.stderr)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
    if contains:
        assert contains.lower() in lines[0].lower(), lines[0]
