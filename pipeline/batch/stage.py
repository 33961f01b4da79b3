"""The batch stage: one program per frame of a frames dataset, in parallel, streaming, resumable.

`run_frames(frames, out, config, jobs=...)` is the Python API of `r2s run` (which only parses its options and
calls it). The coordinator never holds the dataset: it checks the input in one streaming pass (row groups,
dictionary-encoded), keeps 16 bytes per frame id for the exactly-once rules, and then walks the frame_id column
again, lazily, cutting chunks of frames (a file and a row range each) for the workers, which read their rows
themselves. At most `jobs` chunks are in flight and at most one part file's rows are buffered, whatever the
input size, so the first rows come back seconds after the check and memory stays flat.

Bad input (a missing or corrupt file, a wrong schema, a bad row anywhere, a corrupt value in any column the workers
will read, a frame split in two places, an output that is not ours) is refused before anything is written. A stop (SIGTERM, Ctrl-C) keeps every finished row and
says how to resume: the same call again.
"""

from __future__ import annotations

import os
import shutil
import signal
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager, nullcontext
from pathlib import Path
from typing import Any

import pyarrow as pa

from frames.dataset import FramesDataset
from frames.frame_hash import Coverage, FrameHasher, frame_keys, from_hex
from frames.maps import map_digests, maps_dir
from pipeline.batch import DEFAULT_CHUNK_SIZE, DEFAULT_PART_ROWS
from pipeline.batch.cluster import dask_pool
from pipeline.batch.options import RunOptions
from pipeline.batch.pool import LokyPool, compute, wall_guard_s
from pipeline.batch.progress import Progress
from pipeline.batch.rules import PartBuffer, Summary, chunk_size_for, chunk_sizes, chunks, status_counts, summarize
from pipeline.batch.store import RunStore, is_single_file
from pipeline.batch.task import ChunkTask, ChunkUnreadable
from pipeline.errors import UserError
from pipeline.outputs import check_apart
from pipeline.programs import CLIP_SCHEMA, PROGRAMS_SCHEMA, WINDOW_SCHEMA
from storage.atomic import temp_directory
from storage.frame_index import FrameIndex, frame_hashes
from synth.config import SynthConfig, as_config
from synth.version import ROWS_VERSION

PART_MAX_AGE_S = 30.0  # a part is written at the latest this long after its first row
MAX_SPAN_ROWS = 131_072  # rows a chunk may span in its file (two of our writers' row groups)


def run_frames(
    frames: str | os.PathLike,
    out: str | os.PathLike,
    config: SynthConfig | Mapping[str, Any] | None = None,
    *,
    jobs: int | None = None,
    backend: str = "loky",
    scheduler: str | None = None,
    chunk_size: int = DEFAULT_CHUNK_SIZE,
    part_rows: int = DEFAULT_PART_ROWS,
    log: Callable[[str], None] | None = None,
    log_every_s: float = 30.0,
    terminal: bool | None = None,
    synthesizer: Callable | None = None,
    window_s: float | None = None,
    stride_s: float | None = None,
    max_gap_s: float | None = None,
    clip_s: float | None = None,
) -> Summary:
    """Synthesize a program for every frame of `frames` (a frames Parquet file or a directory of them) into `out`
    (a dataset directory, or one file if the name ends in .parquet); frames already in `out` from the same rows
    with the same config are kept. `config`: a SynthConfig, a dict of its fields, or None for the defaults
    (docs/api.md). With `window_s`, one program per window of a scene's frames instead (docs/dsl.md, "Programs over
    a window"; rows: docs/formats.md, "Window programs"); with `clip_s`, one clip program per clip of a scene's
    frames (docs/dsl.md, "Behaviour programs"; rows: docs/formats.md, "Clip programs"). Returns the summary; raises UserError / FramesError /
    ProgramsError / ConfigError on bad input (nothing written then). `log` receives one line at a time (default: stderr); the other keywords are the
    fields of RunOptions (pipeline.batch.options), which says what each means."""
    options = RunOptions(jobs, backend, scheduler, chunk_size, part_rows, log_every_s, terminal, synthesizer, window_s,
                         stride_s, max_gap_s, clip_s)
    return run(frames, out, as_config(config), options, log or _stderr)


def run(frames: str | os.PathLike, out: str | os.PathLike, config: SynthConfig, options: RunOptions,
        log: Callable[[str], None]) -> Summary:
    """run_frames with its options as one value."""
    options.check()
    if options.clip_s is not None and not config.lanes:
        # A clip's frames are placed in the world (their times, their moves) by the ego rows' world pose, which a
        # run reads, checks and hashes with each frame's road: without it every clip would be an error row.
        raise UserError("--clip needs --lanes: a clip's frames are placed by their world pose and road, which "
                        "--lanes reads")
    if options.window is not None and options.clip_s is None:
        from synth.window.program import check_window_config  # only --window loads the window synthesis

        check_window_config(config)
    check_apart(out, [("input frames", frames)], directory=not is_single_file(out))
    if is_single_file(out):  # its parts go beside it, in <out>.parts/
        check_apart(f"{out}.parts", [("input frames", frames)], directory=True)
    run = _Run if options.window is None else _ClipRun if options.clip_s is not None else _WindowRun
    return run(str(frames), Path(out), config, options, log).go()


def _stderr(line: str) -> None:
    sys.stderr.write(f"r2s run: {line}\n")
    sys.stderr.flush()


class _Run:
    """One invocation: check, plan, workers, parts, summary."""

    def __init__(self, frames: str, out: Path, config: SynthConfig, options: RunOptions,
                 log: Callable[[str], None]) -> None:
        self.frames, self.out, self.config, self.options, self._log = frames, out, config, options, log
        self.started = time.monotonic()
        self.first_result_s: float | None = None
        self._progress = None

    def log(self, message: str) -> None:
        if self._progress is not None:
            self._progress.write(message)
        else:
            self._log(message)

    unit = "frames"  # what a row is of (log lines, the summary)
    verb = "r2s run"  # the progress bar's label: the command the user typed

    def go(self) -> Summary:
        store = self._store()
        store.check_writable()
        dataset = FramesDataset.open(self.frames)  # bad input is refused before even the lock file is made
        n_units, index, contents, config_hash = self._units(dataset)
        store.lock()
        try:
            plan = store.plan(index, contents, config_hash, ROWS_VERSION)
            del index, contents  # 16 + 16 bytes a frame: not kept while the frames run
            return self._locked(store, dataset, n_units, plan)
        finally:
            store.unlock()

    @property
    def schema(self):
        return PROGRAMS_SCHEMA

    def _store(self) -> RunStore:
        """Where the rows go (a run of another kind keeps them beside its own files: pipeline.batch.simulations)."""
        return RunStore(self.out, self.schema)

    def _units(self, dataset) -> tuple[int, Any, Any, str]:
        """Check the input (streaming) and say what rows the run makes: how many, the index of their keys (frame
        ids), their keys with what each is computed from (the rows' hash: store.plan), and the config hash."""
        hasher = FrameHasher(coverage=self._coverage(dataset))  # every frame hashed in the checking pass
        checked = dataset.check(hasher, road=self._maps(dataset) is not None)
        n_frames, index = checked.frames, checked.index
        return n_frames, index, hasher.keys(), self.config.hash

    def _coverage(self, dataset):
        """What a stored row must have been computed from to be kept (frames.frame_hash.Coverage): the frame's
        rows, and with each frame's road (--lanes) its road columns and the content of every map, each map read
        and hashed once here."""
        maps = self._maps(dataset)
        return Coverage() if maps is None else Coverage.with_road(map_digests(maps))

    def _locked(self, store, dataset, n_frames: int, plan) -> Summary:
        todo = n_frames - len(plan.done)
        with self._pool(todo) as pool:  # connects to dask: may refuse, and nothing is written yet
            if pool is not None:
                pool.check_readable(dataset.url, dataset.parts[0].path)
            for w in plan.warnings:
                self.log(w)
            self._log_plan(plan, n_frames, dataset)
            store.apply(plan)
            store.remove_temporaries()
            computed = self._compute(store, pool, dataset, plan.done, n_frames, todo) if todo else 0
        store.finish()
        summary = summarize(store.status_counts(), computed, time.monotonic() - self.started, self.first_result_s,
                            plan.changed, self.unit)
        self.log(f"{summary.line()} -> {self.out}")
        return summary

    def _log_plan(self, plan, n_frames: int, dataset) -> None:
        files = f" in {len(dataset.parts)} files" if len(dataset.parts) > 1 else ""
        unit, one = self.unit, f"{self.unit[:-1]}(s)"
        self.log(f"{n_frames:,} {unit}{files} checked in {time.monotonic() - self.started:.1f} s")
        if len(plan.done):
            self.log(f"resuming: {len(plan.done)} of {n_frames} {unit} already done from the same rows with this "
                     "config")
        if plan.outdated:
            self.log(f"recomputing {plan.outdated} {one} whose rows another r2s version or synthesis revision wrote "
                     f"(e.g. {plan.outdated_example}: {plan.outdated_version}; this is {ROWS_VERSION})")
        if plan.changed:
            road = " (their road columns or the maps they name included)" if self._maps(dataset) else ""
            self.log(f"recomputing {plan.changed} {one} whose rows changed since their program was made{road} "
                     f"(e.g. {plan.changed_example}); their rows are replaced")
        if plan.unhashed:
            self.log(f"recomputing {plan.unhashed} {one} whose rows were written without a frame_hash "
                     "(by an older r2s): what they were computed from is unknown")
        if plan.stale:
            self.log(f"recomputing {plan.stale} {one} whose rows have another config hash "
                     f"(e.g. {plan.stale_example}); their rows are replaced")
        if plan.foreign:
            self.log(f"dropping {plan.foreign} row(s) of {unit} that are not in {self.frames}")

    def _pool(self, todo: int):
        """A context that yields the pool (None when there is nothing to compute)."""
        if todo == 0:
            return nullcontext(None)
        if self.options.backend == "dask":
            return dask_pool(self.options.scheduler, self.options.jobs)
        jobs = min(self.options.jobs or os.cpu_count() or 1, todo)
        return nullcontext(LokyPool(jobs, self._wall_guard_s()))

    def _wall_guard_s(self) -> float | None:
        """Seconds after which a unit is taken for hung and its worker killed (pool.wall_guard_s)."""
        return wall_guard_s(self.config.time_limit)

    def _maps(self, dataset) -> str | None:
        """With lanes each frame gets its road from the maps beside the frames, as r2s scene gives it (local only):
        the workers then read the road columns too (FramesPart.read_columns), and the check decodes them."""
        return str(maps_dir(self.frames)) if self.config.lanes and not dataset.url else None

    def _tasks(self, dataset, done, todo: int, pool, progress_dir: str | None) -> Iterator:
        def runs():
            for r in dataset.runs():
                mask = ~done.contains(*frame_hashes(r.ids)) if len(done) else r.lengths > 0
                yield r.part, r.starts, r.lengths, r.ids, mask

        maps = self._maps(dataset)
        slots = pool.slots()
        sizes = chunk_sizes(slots, chunk_size_for(todo, slots, self.options.chunk_size))
        for n, (k, frames) in enumerate(chunks(runs(), sizes, MAX_SPAN_ROWS)):
            part = dataset.parts[k]
            yield ChunkTask(f"c{n}", dataset.url, part.path, tuple(frames), part.read_columns(maps is not None),
                            self.config, hard_cap=pool.own_processes, synthesizer=self.options.synthesizer,
                            progress_dir=progress_dir, maps=maps)

    def _compute(self, store, pool, dataset, done, n_frames: int, todo: int) -> int:
        # Workers' progress markers, where the workers are processes of this machine's: in the temp directory (not
        # beside the output: a full output disk must not stop the markers), named by host and pid, so a killed
        # run's folder is removed by the next run.
        progress_dir = (str(temp_directory(Path(tempfile.gettempdir()) / "r2s-run-progress"))
                        if pool.own_processes else None)
        buffer = PartBuffer(self.options.part_rows, PART_MAX_AGE_S)
        self._progress = Progress(todo, self._log, self.options.log_every_s, self.options.terminal, self.started,
                                  self.unit, self.verb)
        computed = 0
        stopped, refused = True, False
        try:
            tasks = self._tasks(dataset, done, todo, pool, progress_dir)
            for table in compute(pool, tasks, self.log):
                now = time.monotonic()
                if table is not None:
                    if self.first_result_s is None:
                        self.first_result_s = now - self.started
                        if not self._progress.has_bar:
                            self.log(f"first {self.unit[:-1]} done after {self.first_result_s:.1f} s")
                    counts = status_counts(table)
                    computed += table.num_rows
                    buffer.add(table, now)
                    self._progress.update(counts)
                else:
                    self._progress.tick()
                if buffer.due(now):
                    _write_part(store, buffer.take())
            stopped = False
            return computed
        except ChunkUnreadable as exc:
            # Bad input, not a stop: the same command would meet it again. The rows still in the buffer are not
            # written, so a refusal found before any part was due leaves no output behind (as the check's refusals
            # do); whether other chunks finished before the bad one is a race of the workers, and must not decide it.
            stopped, refused = False, True
            raise UserError(f"{exc}{exc.hint}") from None
        finally:
            if buffer.count and not refused:
                _write_part(store, buffer.take())
            if stopped:
                # The store's own count: a stop held back during a write is delivered as the write returns, before
                # any count kept here could be updated, and the line would say one part less than is saved.
                saved = n_frames - todo + store.rows_written
                where = self.out if not store.single_file else store.parts
                self.log(f"stopped: {saved:,} of {n_frames:,} {self.unit} are saved in {where}; "
                         "run the same command again to resume")
            self._progress.close()
            self._progress = None
            if progress_dir is not None:
                shutil.rmtree(progress_dir, ignore_errors=True)


def _write_part(store, table) -> None:
    """Write a part with Ctrl-C and SIGTERM held back: the rows have left the buffer, so a stop in the middle of the
    write would lose them; a stop that arrives is delivered (and the run ends) right after."""
    with _stops_held():
        store.write_part(table)


@contextmanager
def _stops_held() -> Iterator[None]:
    """Hold Ctrl-C and SIGTERM at the Python level, then deliver the first that arrived to the handler it was meant
    for. Not by blocking the signal (pthread_sigmask): that blocks it in this thread only, and the kernel hands it
    to another thread (pyarrow's, loky's), whose flag the interpreter then serves in this thread mid-write."""
    if threading.current_thread() is not threading.main_thread():  # handlers can be changed in the main thread only
        yield
        return
    arrived: list[tuple[int, Any]] = []
    stops = (signal.SIGINT, signal.SIGTERM)
    previous = {s: signal.signal(s, lambda signum, frame: arrived.append((signum, frame))) for s in stops}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
        if arrived:
            signum, frame = arrived[0]
            handler = previous[signum]
            if callable(handler):
                handler(signum, frame)
            elif handler == signal.SIG_DFL:
                signal.raise_signal(signum)  # the default action: the process ends as it would have


class _WindowRun(_Run):
    """The run with --window: the rows are windows', planned by pipeline.batch.windows and computed by
    pipeline.batch.window_task; parts, resume, the pool, progress and the summary are _Run's own."""

    unit = "windows"

    @property
    def schema(self):
        return WINDOW_SCHEMA

    @property
    def spec(self):
        """How the units tile the scenes and what their config hash covers (a WindowSpec)."""
        return self.options.window

    def _task_type(self):
        from pipeline.batch.window_task import WindowTask

        return WindowTask

    def _units(self, dataset) -> tuple[int, Any, Any, str]:
        from pipeline.batch.windows import plan_windows

        spec = self.spec
        hasher = FrameHasher(keep_lanes=True, coverage=self._coverage(dataset))
        # Refuses bad input (every value the workers will read); the hasher keeps each frame's hash
        dataset.check(hasher, road=self._maps(dataset) is not None)
        self._windows, hashes = plan_windows(dataset, hasher, spec)
        firsts = [w.frames[0].frame_id for w in self._windows]
        hi, lo = frame_hashes(firsts)
        lane0, lane1, _ = from_hex(pa.array(hashes, pa.string()))
        return len(firsts), FrameIndex(hi, lo), FrameIndex(*frame_keys(hi, lo, lane0, lane1)), \
            spec.config_hash(self.config)

    def _tasks(self, dataset, done, todo: int, pool, progress_dir: str | None) -> Iterator:
        task = self._task_type()
        spec = self.spec
        maps = self._maps(dataset)
        parts = tuple((p.path, p.read_columns(maps is not None)) for p in dataset.parts)
        windows = self._windows
        if len(done):
            windows = [w for w, kept in zip(windows, done.contains(*frame_hashes([w.frames[0].frame_id
                                                                                  for w in windows]))) if not kept]
        slots = pool.slots()
        sizes = chunk_sizes(slots, chunk_size_for(todo, slots, self.options.chunk_size))
        at, n = 0, 0
        while at < len(windows):
            size = next(sizes)
            yield task(f"w{n}", dataset.url, parts, tuple(windows[at:at + size]), self.config, spec,
                             spec.config_hash(self.config), hard_cap=pool.own_processes, progress_dir=progress_dir,
                             maps=maps)
            at, n = at + size, n + 1


class _ClipRun(_WindowRun):
    """The run with --clip: a window run whose units are clips (pipeline.batch.clips), each synthesized into a clip
    program; the frames need timestamps (the plan refuses frames without) and speeds."""

    unit = "clips"

    @property
    def schema(self):
        return CLIP_SCHEMA

    def _task_type(self):
        from pipeline.batch.clips import ClipTask

        return ClipTask

    def _units(self, dataset) -> tuple[int, Any, Any, str]:
        lacking = [p.path for p in dataset.parts if "speed" not in p.columns]
        if lacking:
            raise UserError(f"{dataset.source}: {lacking[0]} has no speed column; --clip needs every entity's speed "
                            "(extract the frames with speeds, as r2s extract writes them)")
        return super()._units(dataset)
