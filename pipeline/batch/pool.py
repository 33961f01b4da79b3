"""Workers of `r2s run`: a loky process pool (joblib's) or a dask.distributed cluster, and the rule that keeps
a run going when a worker dies.

The unit of work is a chunk of frames (pipeline.batch.task.ChunkTask; with --window, a chunk of windows:
pipeline.batch.window_task.WindowTask, which answers the same members); the unit of blame is still one frame (one
window).
When a worker dies (killed at its memory limit, by the OOM killer, a segfault in a native library), the chunks
it ran fail with it and nobody says which frame was to blame. Each chunk's progress marker names the frame it
was running: the frames before it (finished, rows lost) and after it (not started) are innocent and go back
in the queue; the running frames are the suspects. A lone suspect is the culprit; several are retried one at
a time, so a second death names its frame exactly and the innocent ones get their programs. The culprit is
recorded (memout when the worker was killed, else error, with the reason) and the run goes on with a fresh
pool. On dask, where a death is pinned on a task (KilledWorker) but a remote worker's marker cannot be read,
the chunk is split into single frames, each of which dask pins on its own.
"""

from __future__ import annotations

import os
import re
import time
import uuid
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, wait
from dataclasses import dataclass, field
from typing import Any, Protocol

import pyarrow as pa

from pipeline.batch.parent import watch_parent
from pipeline.batch.task import ChunkTask, one_line, run_task
from pipeline.errors import UserError
from storage.parquet import filesystem
from synth.errors import InternalError


class WorkerLost(InternalError):
    """Every chunk in flight was lost with the pool. `in_flight`: (task, index of the frame it was running, -1
    when it had not started, None when unknown). `blamed`: keys of the tasks whose running frame is to blame
    (empty when nobody knows which worker died first)."""

    def __init__(self, in_flight, reason: str, status: str, blamed: frozenset[str] = frozenset()) -> None:
        super().__init__(reason)
        self.in_flight, self.reason, self.status, self.blamed = tuple(in_flight), reason, status, blamed


@dataclass(frozen=True)
class Lost:
    """One chunk whose death is pinned on it (dask's KilledWorker): the other chunks in flight go on."""

    task: ChunkTask
    reason: str
    status: str


class TaskQueue:
    """Chunks still to run: retries first, then the (lazy, possibly huge) stream of planned chunks."""

    def __init__(self, tasks: Iterable[ChunkTask]) -> None:
        self._retries: deque[ChunkTask] = deque()
        self._planned = iter(tasks)

    def retry(self, task: ChunkTask) -> None:
        self._retries.append(task)

    def next(self) -> ChunkTask | None:
        if self._retries:
            return self._retries.popleft()
        return next(self._planned, None)


class Pool(Protocol):
    """What the batch stage (pipeline.batch.stage) asks of the workers, whatever they are."""

    # Each worker is a process of this machine with nothing else in it: a per-process limit (the hard memory cap)
    # is the frame's own, and its progress markers can be read here (a lost chunk then blames one frame).
    own_processes: bool

    def slots(self) -> int:
        """How many chunks run at once."""

    def check_readable(self, url: str, path: str) -> None:
        """Refuse (UserError), before anything is written, workers that cannot read the frames themselves."""

    def map_unordered(self, queue: TaskQueue) -> Iterator[pa.Table | Lost | None]:
        """Tables as chunks finish, Lost for a chunk whose death is pinned on it, None as a heartbeat while
        nothing finishes; raises WorkerLost when the pool broke with chunks in flight."""


# How often a pool wakes up when no chunk finishes, so that a waiting part can be written on time.
HEARTBEAT_S = 5.0


def death_status(reason: str) -> str:
    # SIGKILL is what the kernel's OOM killer sends (or a user's kill -9); any other death is an error. Dask's
    # KilledWorker does not say how its workers died, so a death on dask is an error with that message.
    return "memout" if "SIGKILL" in reason else "error"


def wall_guard_s(time_limit: float | None) -> float | None:
    """Seconds after which a frame is taken for hung and its worker killed. The time limit bounds only the
    search; the oracle table and the certification around it grow with the frame, hence the generous slack."""
    return None if time_limit is None else 3.0 * time_limit + 60.0


@dataclass(frozen=True)
class _Hooks:
    """What differs between loky and dask in the bounded loop."""

    submit: Callable[[ChunkTask], Any]
    wait_first: Callable[[list, float | None], Iterable]
    death: Callable[[BaseException], tuple[str, bool] | None]  # (reason, pinned on this task) or None: a bug
    started: Callable[[ChunkTask], int | None] = lambda task: None  # index of the frame running, -1, None
    frame_since: Callable[[ChunkTask], float | None] = lambda task: None  # wall clock when it started
    guard_s: float | None = None
    kill: Callable[[], None] | None = None
    abandon: Callable[[list], None] | None = None


def _bounded(queue: TaskQueue, slots: int, hooks: _Hooks) -> Iterator[pa.Table | Lost | None]:
    """At most `slots` chunks submitted at once, so that "in flight" means running and a death names few frames.

    When the run itself stops (SIGTERM, Ctrl-C, a bug, the consumer closing us), `abandon(futures)` stops the
    chunks in flight at once: a scheduler's grace period is seconds, and their rows are lost either way.
    """
    running: dict[Any, ChunkTask] = {}
    try:
        yield from _bounded_loop(queue, slots, hooks, running)
    except WorkerLost:
        raise
    except BaseException:
        if hooks.abandon is not None and running:
            hooks.abandon(list(running))
        raise


def _bounded_loop(queue: TaskQueue, slots: int, hooks: _Hooks, running: dict) -> Iterator[pa.Table | Lost | None]:
    poll_s = HEARTBEAT_S if hooks.guard_s is None else min(HEARTBEAT_S, hooks.guard_s / 4)
    while True:
        while len(running) < slots and (task := queue.next()) is not None:
            running[hooks.submit(task)] = task
        if not running:
            return
        done = hooks.wait_first(list(running), poll_s)
        if not done:
            yield None  # the caller may write a part that has waited long enough
        for future in done:
            task = running.pop(future)
            try:
                table = future.result()
            except Exception as exc:
                died = hooks.death(exc)
                if died is None:
                    raise
                reason, pinned = died
                if pinned:
                    yield Lost(task, reason, death_status(reason))
                    continue
                lost = [(task, hooks.started(task))] + [(t, hooks.started(t)) for t in running.values()]
                running.clear()
                raise WorkerLost(lost, reason, death_status(reason)) from None
            yield table
        if hooks.guard_s is not None:
            now = time.time()
            overdue = [t for t in running.values()
                       if (since := hooks.frame_since(t)) is not None and now - since > hooks.guard_s]
            if overdue:
                lost = [(t, hooks.started(t)) for t in running.values()]
                running.clear()
                if hooks.kill is not None:
                    hooks.kill()
                raise WorkerLost(lost, f"no answer after {hooks.guard_s:.0f} s (wall-clock guard); worker killed",
                                 "timeout", blamed=frozenset(t.key for t in overdue))


def _read_marker(task: ChunkTask) -> tuple[int, float] | None:
    path = task.marker()
    if path is None:
        return None
    try:
        with open(path) as f:
            return int(f.read() or -1), os.fstat(f.fileno()).st_mtime
    except (FileNotFoundError, ValueError):
        return None


def _started(task: ChunkTask) -> int | None:
    if task.progress_dir is None:
        return None
    mark = _read_marker(task)
    if mark is None:
        return -1  # no marker: the chunk never started, or finished (a finished chunk's rows came back)
    marker = task.marker()
    try:
        os.unlink(marker)  # the chunk is over: a retry of its frames writes markers of its own
    except FileNotFoundError:
        pass
    return mark[0]


def _frame_since(task: ChunkTask) -> float | None:
    mark = _read_marker(task)
    return None if mark is None else mark[1]


@dataclass(frozen=True)
class LokyPool:
    """joblib's loky executor, used directly rather than through joblib.Parallel: Parallel runs n_jobs=1 in the
    calling process (no memory isolation: one bad frame would end the run) and does not say which tasks were
    in flight when a worker died."""

    jobs: int
    guard_s: float | None = None
    own_processes = True

    def slots(self) -> int:
        return self.jobs

    def check_readable(self, url: str, path: str) -> None:
        """The workers are processes of this machine: they read what the run read."""

    def map_unordered(self, queue: TaskQueue) -> Iterator[pa.Table | Lost | None]:
        from joblib.externals.loky import get_reusable_executor

        # A fresh one after a death or a kill; its workers end when this process does, however it ends.
        executor = get_reusable_executor(max_workers=self.jobs, initializer=watch_parent, initargs=(os.getpid(),))

        def wait_first(futures: list, timeout: float | None) -> Iterable:
            return wait(futures, timeout=timeout, return_when=FIRST_COMPLETED).done

        def kill() -> None:
            # wait=True: the next get_reusable_executor() shuts the old pool down again with
            # kill_workers=False, which would override ours and join a worker that never returns.
            executor.shutdown(wait=True, kill_workers=True)

        def abandon(_futures: list) -> None:
            # The process is on its way out: no pool follows, so nothing can override kill_workers.
            executor.shutdown(wait=False, kill_workers=True)

        yield from _bounded(queue, self.jobs, _Hooks(
            submit=lambda t: executor.submit(run_task, t), wait_first=wait_first, death=_loky_death,
            started=_started, frame_since=_frame_since, guard_s=self.guard_s, kill=kill, abandon=abandon))


def _loky_death(exc: BaseException) -> tuple[str, bool] | None:
    from joblib.externals.loky.process_executor import BrokenProcessPool

    if not isinstance(exc, BrokenProcessPool):
        return None
    # The whole pool breaks with one worker, and the message does not say which task it ran: not pinned.
    # Only the exit code is kept: the rest of the message speculates about memory.
    codes = re.search(r"exit codes of the workers are \{([^}]*)\}", str(exc))
    return (f"worker died (exit code {codes.group(1)})" if codes else one_line(f"worker died: {exc}")), False


@dataclass(frozen=True)
class DaskPool:
    """The same stage on a dask.distributed cluster, with dask futures.

    Not through joblib's dask backend, deliberately: joblib 1.6's backend never calls the completion callback
    of a task whose future errs (KilledWorker after a worker death), so Parallel waits for it forever, in every
    return_as mode. Dask itself retries a task whose worker died on other workers; after `allowed-failures`
    deaths it raises KilledWorker for that task alone, so the death is pinned on its chunk.
    """

    client: Any
    jobs: int | None = None
    # Task keys are the run's own: two runs on one cluster (or a rerun while the scheduler still remembers the
    # last one) must never share a result.
    run_id: str = field(default_factory=lambda: uuid.uuid4().hex[:12])
    own_processes = False  # threaded workers, maybe on other machines

    def slots(self) -> int:
        return self.jobs or max(1, sum(self.client.nthreads().values()))

    def check_readable(self, url: str, path: str) -> None:
        """Every worker must read the frames itself (nothing passes through the coordinator): ask each one
        before anything is written."""
        answers = self.client.run(_can_read, url, path)
        blind = sorted(worker for worker, error in answers.items() if error)
        if blind:
            raise UserError(f"dask worker {blind[0]} cannot read the frames ({answers[blind[0]]}); on a cluster the "
                            "frames must be at a path every worker sees (a shared filesystem or an fsspec URL)")

    def map_unordered(self, queue: TaskQueue) -> Iterator[pa.Table | Lost | None]:
        from distributed import KilledWorker
        from distributed import wait as dask_wait

        def submit(task: ChunkTask) -> Any:
            return self.client.submit(run_task, task, key=f"r2s-run-{self.run_id}-{task.key}", pure=False)

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

        yield from _bounded(queue, self.slots(), _Hooks(submit=submit, wait_first=wait_first, death=death,
                                                        abandon=self.client.cancel))


def _can_read(url: str, path: str) -> str:
    try:
        pafs, _ = filesystem(url) if url else filesystem(path)
        with pafs.open_input_file(path) as f:
            f.read(4)
        return ""
    except Exception as exc:  # the worker's own words, whatever its filesystem raised
        return one_line(f"{type(exc).__name__}: {exc}", 200)


def compute(pool: Pool, tasks: Iterable[ChunkTask], log: Callable[[str], None]) -> Iterator[pa.Table | None]:
    """One row per planned frame, in tables as chunks finish, whatever happens to the workers (None: a heartbeat)."""
    queue = TaskQueue(tasks)
    while True:
        try:
            for item in pool.map_unordered(queue):
                if isinstance(item, Lost):
                    yield from _pinned(item, queue, log)
                else:
                    yield item
            return
        except WorkerLost as lost:
            suspects = []
            for task, started in lost.in_flight:
                if started is None:  # progress unknown: every frame of the chunk is a suspect
                    suspects.extend(task.singles())
                elif started < 0 or (lost.blamed and task.key not in lost.blamed):
                    queue.retry(task)  # never started, or killed by us together with a hung frame: innocent
                else:
                    culprit, rest = task.split_at(started)
                    if rest is not None:  # finished before the death (rows lost with it) or not yet started
                        queue.retry(rest)
                    if task.key in lost.blamed:
                        log(f"frame {culprit.frames[0][0]}: {lost.reason}; recorded as {lost.status}")
                        yield culprit.lost_rows(lost.status, lost.reason)
                    else:
                        suspects.append(culprit)
            if len(suspects) == 1:
                log(f"frame {suspects[0].frames[0][0]}: {lost.reason}; recorded as {lost.status}")
                yield suspects[0].lost_rows(lost.status, lost.reason)
            elif suspects:
                log(f"{lost.reason} with {len(suspects)} frames in flight; retrying them one at a time")
                for task in suspects:
                    yield from _alone(pool, task, log)


def _pinned(lost: Lost, queue: TaskQueue, log: Callable[[str], None]) -> Iterator[pa.Table]:
    if len(lost.task.frames) == 1:
        log(f"frame {lost.task.frames[0][0]}: {lost.reason}; recorded as {lost.status}")
        yield lost.task.lost_rows(lost.status, lost.reason)
        return
    log(f"a chunk of {len(lost.task.frames)} frames: {lost.reason}; retrying its frames one by one")
    for single in lost.task.singles():
        queue.retry(single)


def _alone(pool: Pool, task: ChunkTask, log: Callable[[str], None]) -> Iterator[pa.Table | None]:
    try:
        for item in pool.map_unordered(TaskQueue([task])):
            yield item.task.lost_rows(item.status, item.reason) if isinstance(item, Lost) else item
    except WorkerLost as lost:
        log(f"frame {task.frames[0][0]}: {lost.reason}; recorded as {lost.status}")
        yield task.lost_rows(lost.status, lost.reason)
