"""Progress of a long run: a tqdm bar on a terminal; without one (nohup, CI, a cluster job) a log line every
`every_s` seconds with frames done, rate, ETA and counts by status, so a run is never silent for hours."""

from __future__ import annotations

import sys
import time
from collections import Counter
from collections.abc import Callable

from tqdm import tqdm

from pipeline.batch.rules import status_line


def duration(seconds: float) -> str:
    seconds = max(0, int(round(seconds)))
    if seconds < 60:
        return f"{seconds} s"
    if seconds < 3600:
        return f"{seconds // 60} min {seconds % 60:02d} s"
    if seconds < 86400:
        return f"{seconds // 3600} h {seconds % 3600 // 60:02d} min"
    return f"{seconds // 86400} d {seconds % 86400 // 3600:02d} h"


class Progress:
    def __init__(self, total: int, emit: Callable[[str], None], every_s: float = 30.0,
                 terminal: bool | None = None, started: float | None = None, unit: str = "frames",
                 label: str = "r2s run") -> None:
        self.total, self.every_s, self._emit, self.unit = total, every_s, emit, unit  # unit: what is counted
        self.done = 0
        self.counts: Counter = Counter()
        self.started = time.monotonic() if started is None else started
        self._last_line = time.monotonic()
        terminal = sys.stderr.isatty() if terminal is None else terminal
        self._bar = tqdm(total=total, desc=label, unit=f" {unit}", file=sys.stderr, dynamic_ncols=True,
                         disable=not terminal) if terminal else None

    @property
    def has_bar(self) -> bool:
        return self._bar is not None

    def update(self, counts: dict[str, int]) -> None:
        n = sum(counts.values())
        self.done += n
        self.counts.update(counts)
        if self._bar is not None:
            self._bar.update(n)
        self.tick()

    def tick(self) -> None:
        now = time.monotonic()
        if self._bar is None and now - self._last_line >= self.every_s:
            self._last_line = now
            self._emit(self.line(now))

    def line(self, now: float | None = None) -> str:
        elapsed = (time.monotonic() if now is None else now) - self.started
        rate = self.done / elapsed if elapsed > 0 else 0.0
        left = self.total - self.done
        eta = duration(left / rate) if rate > 0 else "unknown"
        pct = 100.0 * self.done / self.total if self.total else 100.0
        return (f"{self.done:,} of {self.total:,} {self.unit} ({pct:.1f}%), {rate:.1f} {self.unit}/s, ETA {eta}"
                + (f"; {status_line(self.counts)}" if self.counts else ""))

    def write(self, message: str) -> None:
        """A log line that does not break the bar."""
        if self._bar is not None:
            self._bar.write(message, file=sys.stderr)
        else:
            self._emit(message)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()
            self._bar = None
