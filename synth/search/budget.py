"""Time and memory budgets of an anytime search: polled, never signalled, so the search stops cleanly."""

from __future__ import annotations

import resource
import time
from dataclasses import dataclass, field

from synth.errors import InternalError

_PAGE_MB = resource.getpagesize() / (1024 * 1024)


def current_rss_mb() -> float:
    """Resident set size now (Linux /proc; elsewhere the peak so far)."""
    try:
        with open("/proc/self/statm", "rb") as f:
            return int(f.read().split()[1]) * _PAGE_MB
    except OSError:  # pragma: no cover - non-Linux
        return peak_rss_mb()


def peak_rss_mb() -> float:
    """This process's peak resident memory: VmHWM, not ru_maxrss.

    Linux carries ru_maxrss over exec, so a process started by a large parent (a pool worker, a benchmark's
    child) would report the parent's size; VmHWM belongs to this process's own memory, and a pool worker can
    reset it between frames (/proc/self/clear_refs), which ru_maxrss ignores.
    """
    try:
        with open("/proc/self/status", "rb") as f:
            for line in f:
                if line.startswith(b"VmHWM:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:  # pragma: no cover - non-Linux
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


class BudgetExhausted(InternalError):
    """Raised inside a search when its budget runs out; the search catches it and answers anytime."""

    def __init__(self, reason: str):
        super().__init__(reason)
        self.reason = reason  # timeout | memout


@dataclass
class Budget:
    time_limit: float | None = None
    memory_limit_mb: float | None = None
    started: float = field(default_factory=time.perf_counter)
    nodes: int = 0
    exhausted: str | None = None

    def tick(self, n: int = 1) -> None:
        """Count n expanded nodes; raise BudgetExhausted when the time or memory is up."""
        self.nodes += n
        if self.exhausted:
            raise BudgetExhausted(self.exhausted)
        if self.time_limit is not None and self.nodes & 63 == 0:
            if time.perf_counter() - self.started > self.time_limit:
                self.exhausted = "timeout"
                raise BudgetExhausted("timeout")
        if self.memory_limit_mb is not None and self.nodes & 4095 == 0:
            if current_rss_mb() > self.memory_limit_mb:
                self.exhausted = "memout"
                raise BudgetExhausted("memout")

    def remaining(self) -> float | None:
        if self.time_limit is None:
            return None
        return max(0.0, self.time_limit - (time.perf_counter() - self.started))
