"""Workers of `r2s run`: a loky process pool or a dask.distributed cluster (through joblib's dask backend),
and the rule that keeps a run going when a worker dies.

When a worker dies (killed at its memory limit, by the OOM killer, a segfault in a native library), every
frame in flight fails with it and nobody says which frame was to blame. A lone suspect is the culprit; several
are retried one at a time, so a second death names its frame exactly and the innocent ones get their programs.
The culprit is recorded (memout when the worker was killed, else error, with the reason) and the run goes on
with a fresh pool.
"""

from __future__ import annotations

import re
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, wait
from dataclasses import dataclass
from typing import Any, Protocol

from pipeline.run import Row
from pipeline.run_task import FrameTask, one_line, run_frame


class WorkerLost(Exception):
    """Frames lost with their worker. `known`: these frames are to blame (not merely in flight)."""

    def __init__(self, frame_ids: Sequence[str], reason: str, status: str, known: bool = False) -> None:
        super().__init__(reason)
        self.frame_ids, self.reason, self.status, self.known = tuple(frame_ids), reason, status, known


class Pool(Protocol):
    def map_unordered(self, tasks: Sequence[FrameTask]) -> Iterator[Row]:
        """Rows as frames finish; raises WorkerLost naming the frames whose worker died."""


def death_status(reason: str) -> str:
    # SIGKILL is what the kernel's OOM killer sends; dask's nanny names memory when it restarts a worker.
    return "memout" if ("SIGKILL" in reason or "memory" in reason.lower()) else "error"


def wall_guard_s(time_limit: float | None) -> float | None:
    """Seconds after which a frame is taken for hung and its worker killed. The time limit bounds only the
    search; the oracle table and the certification around it grow with the frame, hence the generous slack."""
    return None if time_limit is None else 3.0 * time_limit + 60.0


@dataclass(frozen=True)
class LokyPool:
    """joblib's loky executor, used directly rather than through joblib.Parallel: Parallel runs n_jobs=1 in the
    calling process (no memory isolation: one bad frame would end the run) and does not say which frames were
    in flight when a worker died. At most `jobs` frames are submitted at once, so in flight means running."""

    jobs: int
    guard_s: float | None = None

    def map_unordered(self, tasks: Sequence[FrameTask]) -> Iterator[Row]:
        from joblib.externals.loky import get_reusable_executor
        from joblib.externals.loky.process_executor import BrokenProcessPool

        executor = get_reusable_executor(max_workers=self.jobs)  # a fresh one after a death or a kill
        pending = list(reversed(tasks))
        running: dict[Future, tuple[FrameTask, float]] = {}
        while pending or running:
            while pending and len(running) < self.jobs:
                task = pending.pop()
                running[executor.submit(run_frame, task)] = (task, time.monotonic())
            done, _ = wait(running, timeout=self._poll_s(), return_when=FIRST_COMPLETED)
            for future in done:
                task, _ = running.pop(future)
                try:
                    row = future.result()
                except BrokenProcessPool as exc:
                    lost = [task.frame_id] + [t.frame_id for t, _ in running.values()]
                    reason = _loky_reason(exc)  # not the whole message: it speculates about memory
                    raise WorkerLost(lost, reason, death_status(reason)) from None
                yield row
            overdue = self._overdue(running)
            if overdue:
                # wait=True: the next get_reusable_executor() shuts the old pool down again with
                # kill_workers=False, which would override ours and join a worker that never returns.
                executor.shutdown(wait=True, kill_workers=True)
                raise WorkerLost(overdue, f"no answer after {self.guard_s:.0f} s (wall-clock guard); worker killed",
                                 "timeout", known=True)

    def _poll_s(self) -> float | None:
        return None if self.guard_s is None else min(5.0, self.guard_s / 4)

    def _overdue(self, running: dict[Future, tuple[FrameTask, float]]) -> list[str]:
        if self.guard_s is None:
            return []
        now = time.monotonic()
        return [t.frame_id for t, started in running.values() if now - started > self.guard_s]


def _loky_reason(exc: BaseException) -> str:
    codes = re.search(r"exit codes of the workers are \{([^}]*)\}", str(exc))
    return f"worker died (exit code {codes.group(1)})" if codes else one_line(f"worker died: {exc}")


@dataclass(frozen=True)
class DaskPool:
    """The same stage on a dask.distributed cluster through joblib's dask backend. In flight = handed to
    joblib and not returned (joblib dispatches at most 2 * n_jobs ahead). Dask itself retries a task whose
    worker died on other workers; after `allowed_failures` deaths it raises KilledWorker, handled here."""

    client: Any
    jobs: int = -1

    def map_unordered(self, tasks: Sequence[FrameTask]) -> Iterator[Row]:
        from distributed import KilledWorker
        from joblib import Parallel, delayed, parallel_config

        dispatched: list[str] = []
        returned: set[str] = set()

        def calls() -> Iterable[Any]:
            for task in tasks:
                dispatched.append(task.frame_id)
                yield delayed(run_frame)(task)

        # The backend is bound when Parallel is made, so the config does not leak into the caller between rows.
        with parallel_config(backend="dask", client=self.client):
            parallel = Parallel(n_jobs=self.jobs, return_as="generator_unordered", batch_size=1,
                                pre_dispatch="2*n_jobs")
        try:
            for row in parallel(calls()):
                returned.add(row["frame_id"])
                yield row
        except KilledWorker as exc:
            reason = one_line(f"worker died: {exc}")
            raise WorkerLost([f for f in dispatched if f not in returned], reason, death_status(reason)) from None


def compute(pool: Pool, tasks: Sequence[FrameTask], log: Callable[[str], None]) -> Iterator[Row]:
    """One row per task, in completion order, whatever happens to the workers."""
    queue = {t.frame_id: t for t in tasks}
    while queue:
        try:
            for row in pool.map_unordered(list(queue.values())):
                queue.pop(row["frame_id"], None)
                yield row
        except WorkerLost as lost:
            suspects = [queue.pop(fid) for fid in lost.frame_ids if fid in queue]
            if lost.known or len(suspects) <= 1:
                for task in suspects:
                    log(f"frame {task.frame_id}: {lost.reason}; recorded as {lost.status}")
                    yield _lost_row(task, lost)
                continue
            log(f"{lost.reason} with {len(suspects)} frames in flight; retrying them one at a time")
            for task in suspects:
                yield from _alone(pool, task, log)


def _alone(pool: Pool, task: FrameTask, log: Callable[[str], None]) -> Iterator[Row]:
    try:
        yield from pool.map_unordered([task])
    except WorkerLost as lost:
        log(f"frame {task.frame_id}: {lost.reason}; recorded as {lost.status}")
        yield _lost_row(task, lost)


def _lost_row(task: FrameTask, lost: WorkerLost) -> Row:
    from pipeline.programs import failure_row

    return failure_row(task.frame_id, lost.status, lost.reason, len(task.scene.others), task.config,
                       task.config_hash)
