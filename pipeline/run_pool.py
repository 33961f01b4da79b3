"""Workers of `r2s run`: a loky process pool (joblib's) or a dask.distributed cluster, and the rule that keeps
a run going when a worker dies.

When a worker dies (killed at its memory limit, by the OOM killer, a segfault in a native library), every
frame in flight fails with it and nobody says which frame was to blame. A lone suspect is the culprit; several
are retried one at a time, so a second death names its frame exactly and the innocent ones get their programs.
The culprit is recorded (memout when the worker was killed, else error, with the reason) and the run goes on
with a fresh pool.
"""

from __future__ import annotations

import re
import time
import uuid
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, wait
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
    def map_unordered(self, tasks: Sequence[FrameTask]) -> Iterator[Row | None]:
        """Rows as frames finish, None as a heartbeat while none does; raises WorkerLost naming the frames
        whose worker died."""


# How often a pool wakes up when no frame finishes, so that a waiting chunk can be written on time.
HEARTBEAT_S = 5.0


def death_status(reason: str) -> str:
    # SIGKILL is what the kernel's OOM killer sends (or a user's kill -9); any other death is an error. Dask's
    # KilledWorker does not say how its workers died, so a death on dask is an error with that message.
    return "memout" if "SIGKILL" in reason else "error"


def wall_guard_s(time_limit: float | None) -> float | None:
    """Seconds after which a frame is taken for hung and its worker killed. The time limit bounds only the
    search; the oracle table and the certification around it grow with the frame, hence the generous slack."""
    return None if time_limit is None else 3.0 * time_limit + 60.0


def _bounded(
    tasks: Sequence[FrameTask],
    slots: int,
    submit: Callable[[FrameTask], Any],
    wait_first: Callable[[list, float | None], Iterable],
    death: Callable[[BaseException], tuple[str, bool] | None],
    guard_s: float | None = None,
    kill: Callable[[], None] | None = None,
    abandon: Callable[[list], None] | None = None,
) -> Iterator[Row | None]:
    """At most `slots` frames submitted at once, so that "in flight" means running and a death names few frames.

    `death(exc)` tells a worker death (reason, and whether the death is pinned on this frame) from a bug, which
    propagates. Frames running longer than `guard_s` are taken for hung: `kill()` ends the pool's workers.
    When the run itself stops (SIGTERM, Ctrl-C, a bug, the consumer closing us), `abandon(futures)` stops the
    frames in flight at once: a scheduler's grace period is seconds, and their rows are lost either way.
    """
    running: dict[Any, tuple[FrameTask, float]] = {}
    try:
        yield from _bounded_loop(tasks, slots, submit, wait_first, death, guard_s, kill, running)
    except WorkerLost:
        raise
    except BaseException:
        if abandon is not None and running:
            abandon(list(running))
        raise


def _bounded_loop(tasks, slots, submit, wait_first, death, guard_s, kill, running) -> Iterator[Row | None]:
    pending = list(reversed(tasks))
    poll_s = HEARTBEAT_S if guard_s is None else min(HEARTBEAT_S, guard_s / 4)
    while pending or running:
        while pending and len(running) < slots:
            task = pending.pop()
            running[submit(task)] = (task, time.monotonic())
        done = wait_first(list(running), poll_s)
        if not done:
            yield None  # the caller may write a chunk that has waited long enough
        for future in done:
            task, _ = running.pop(future)
            try:
                row = future.result()
            except Exception as exc:
                died = death(exc)
                if died is None:
                    raise
                reason, pinned = died
                lost = [task.frame_id] + ([] if pinned else [t.frame_id for t, _ in running.values()])
                raise WorkerLost(lost, reason, death_status(reason), known=pinned) from None
            yield row
        now = time.monotonic()
        overdue = [t.frame_id for t, started in running.values() if guard_s is not None and now - started > guard_s]
        if overdue:
            if kill is not None:
                kill()
            raise WorkerLost(overdue, f"no answer after {guard_s:.0f} s (wall-clock guard); worker killed",
                             "timeout", known=True)


@dataclass(frozen=True)
class LokyPool:
    """joblib's loky executor, used directly rather than through joblib.Parallel: Parallel runs n_jobs=1 in the
    calling process (no memory isolation: one bad frame would end the run) and does not say which frames were
    in flight when a worker died."""

    jobs: int
    guard_s: float | None = None

    def map_unordered(self, tasks: Sequence[FrameTask]) -> Iterator[Row]:
        from joblib.externals.loky import get_reusable_executor

        executor = get_reusable_executor(max_workers=self.jobs)  # a fresh one after a death or a kill

        def wait_first(futures: list, timeout: float | None) -> Iterable:
            return wait(futures, timeout=timeout, return_when=FIRST_COMPLETED).done

        def kill() -> None:
            # wait=True: the next get_reusable_executor() shuts the old pool down again with
            # kill_workers=False, which would override ours and join a worker that never returns.
            executor.shutdown(wait=True, kill_workers=True)

        def abandon(_futures: list) -> None:
            # The process is on its way out: no pool follows, so nothing can override kill_workers.
            executor.shutdown(wait=False, kill_workers=True)

        yield from _bounded(tasks, self.jobs, lambda t: executor.submit(run_frame, t), wait_first, _loky_death,
                            self.guard_s, kill, abandon)


def _loky_death(exc: BaseException) -> tuple[str, bool] | None:
    from joblib.externals.loky.process_executor import BrokenProcessPool

    if not isinstance(exc, BrokenProcessPool):
        return None
    # The whole pool breaks with one worker, and the message does not say which frame it ran: not pinned.
    # Only the exit code is kept: the rest of the message speculates about memory.
    codes = re.search(r"exit codes of the workers are \{([^}]*)\}", str(exc))
    return (f"worker died (exit code {codes.group(1)})" if codes else one_line(f"worker died: {exc}")), False


@dataclass(frozen=True)
class DaskPool:
    """The same stage on a dask.distributed cluster, with dask futures.

    Not through joblib's dask backend, deliberately: joblib 1.6's backend never calls the completion callback
    of a task whose future errs (KilledWorker after a worker death), so Parallel waits for it forever, in every
    return_as mode. Dask itself retries a task whose worker died on other workers; after `allowed-failures`
    deaths it raises KilledWorker for that task alone, so the death is pinned on its frame.
    """

    client: Any
    jobs: int | None = None

    def map_unordered(self, tasks: Sequence[FrameTask]) -> Iterator[Row]:
        from distributed import KilledWorker
        from distributed import wait as dask_wait

        slots = self.jobs or max(1, sum(self.client.nthreads().values()))

        def submit(task: FrameTask) -> Any:
            return self.client.submit(run_frame, task, key=f"r2s-run-{uuid.uuid4().hex}", pure=False)

        def wait_first(futures: list, timeout: float | None) -> Iterable:
            try:
                return dask_wait(futures, timeout=timeout, return_when="FIRST_COMPLETED").done
            except TimeoutError:
                return ()

        def death(exc: BaseException) -> tuple[str, bool] | None:
            if not isinstance(exc, KilledWorker):
                return None
            tries = re.search(r"on (\d+) different workers", str(exc))
            return (f"worker died (dask: each of the {tries.group(1)} workers that ran it died)" if tries
                    else one_line(f"worker died: {exc}")), True

        yield from _bounded(tasks, slots, submit, wait_first, death, abandon=self.client.cancel)


def compute(pool: Pool, tasks: Sequence[FrameTask], log: Callable[[str], None]) -> Iterator[Row | None]:
    """One row per task, in completion order, whatever happens to the workers (None: a heartbeat)."""
    queue = {t.frame_id: t for t in tasks}
    while queue:
        try:
            for row in pool.map_unordered(list(queue.values())):
                if row is not None:
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


def _alone(pool: Pool, task: FrameTask, log: Callable[[str], None]) -> Iterator[Row | None]:
    try:
        yield from pool.map_unordered([task])
    except WorkerLost as lost:
        log(f"frame {task.frame_id}: {lost.reason}; recorded as {lost.status}")
        yield _lost_row(task, lost)


def _lost_row(task: FrameTask, lost: WorkerLost) -> Row:
    from pipeline.programs import failure_row

    return failure_row(task.frame_id, lost.status, lost.reason, len(task.scene.others), task.config,
                       task.config_hash)
