"""`r2s run frames.parquet --out programs.parquet`: one program per frame, in parallel, each frame under its own
time and memory limit, written in atomic chunks so that a stopped run resumes where it stopped.

Everything that can be refused is checked before anything is written: bad input leaves no output file and no
parts directory behind. Heavy modules (pandas, pyarrow, joblib, dask) are imported inside run(), so that the
other verbs do not pay for them.
"""

from __future__ import annotations

import argparse
import itertools
import os
import signal
import sys
import time
from pathlib import Path

from pipeline.cmd_synth import uncertainty_arg
from synth.config import ORACLES, SOLVERS, STRATEGIES

DEFAULT_CHUNK_SIZE = 32
# A chunk is written at the latest this long after its first row, so slow frames are not held in memory.
CHUNK_MAX_AGE_S = 30.0


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("frames", help="frames Parquet file (r2s extract)")
    p.add_argument("--out", required=True, metavar="F", help="programs Parquet file to write (atomically); "
                   "an existing one is resumed: frames done with the same config are kept")
    p.add_argument("--jobs", type=int, metavar="N", help="parallel workers (default: all cores; "
                   "with --backend dask and --scheduler: all workers of the cluster)")
    p.add_argument("--time-limit", type=float, metavar="S", help="seconds of search per frame; the best program "
                   "found and a proven lower bound are recorded (status feasible or timeout)")
    p.add_argument("--memory-limit", type=float, metavar="MB", help="resident memory per frame: the search stops "
                   "past it (status memout, its best program kept); with loky a hard cap 50%% (at least 256 MB) "
                   "above it ends the frame")
    p.add_argument("--strategy", choices=STRATEGIES, help="search strategy (default: auto)")
    p.add_argument("--oracle", choices=ORACLES, help="relation oracle (default: hybrid)")
    p.add_argument("--solver", choices=SOLVERS, help="SMT solver (default: z3)")
    p.add_argument("--config", metavar="F", help="TOML config (configs/default.toml, configs/paper.toml)")
    p.add_argument("--motion", action="store_const", const=True, default=None,
                   help="statements also say how fast entities move, as in r2s synth (needs the frames' speed "
                        "column; a frame with an entity lacking speed is an error row naming it)")
    p.add_argument("--uncertainty", type=uncertainty_arg, metavar="POS_M,HEAD_DEG[,SPEED_MPS]",
                   help="robust synthesis, as in r2s synth (frames' pos_sigma / heading_sigma / speed_sigma columns "
                        "override)")
    p.add_argument("--backend", choices=("loky", "dask"), default="loky",
                   help="loky: local worker processes (default); dask: a dask.distributed cluster")
    p.add_argument("--scheduler", metavar="ADDR", help="dask scheduler address (tcp://host:8786); without it, "
                   "--backend dask starts a local cluster of --jobs single-threaded worker processes")
    p.add_argument("--chunk-size", type=int, default=DEFAULT_CHUNK_SIZE, metavar="K",
                   help=f"frames per part file written while running (default {DEFAULT_CHUNK_SIZE}); "
                        "a kill loses at most the frames in flight and the finished rows of the last "
                        f"{CHUNK_MAX_AGE_S:.0f} s")


def run(args: argparse.Namespace) -> int:
    from pipeline.errors import UserError
    from pipeline.inputs import load_config

    if args.jobs is not None and args.jobs < 1:
        raise UserError(f"--jobs must be at least 1, got {args.jobs}")
    if args.chunk_size < 1:
        raise UserError(f"--chunk-size must be at least 1, got {args.chunk_size}")
    if args.scheduler and args.backend != "dask":
        raise UserError("--scheduler needs --backend dask")
    if Path(args.frames).resolve() == Path(args.out).resolve():
        raise UserError("--out is the input frames file; choose another path")
    config = load_config(args.config).with_(
        strategy=args.strategy, oracle=args.oracle, solver=args.solver,
        time_limit=args.time_limit, memory_limit=args.memory_limit, motion=args.motion, **(args.uncertainty or {}),
    )
    return _Run(args, config).go()


class _Run:
    """One invocation: checks, plan, workers, chunks, consolidation, summary."""

    def __init__(self, args: argparse.Namespace, config) -> None:
        self.args, self.config = args, config
        self.config_hash = config.semantic_hash()
        self.started = time.perf_counter()
        self._bar = None

    def go(self) -> int:
        from extractors.frames import read_frames
        from pipeline.errors import UserError
        from pipeline.run import plan_run
        from pipeline.run_store import RunStore

        store = RunStore(self.args.out)
        store.check_writable()
        df = read_frames(self.args.frames)  # bad input is refused before even the lock file is made
        store.lock()
        if df.empty:
            raise UserError(f"{self.args.frames} has no frames")
        groups = {str(fid): rows for fid, rows in df.groupby("frame_id", sort=False)}
        order = list(groups)
        existing, warnings = store.existing_rows()
        plan = plan_run(order, existing, self.config_hash)
        del existing
        with self._pool(len(plan.todo)) as pool:  # connects to dask: may refuse, and nothing is written yet
            for w in warnings:
                self.log(w)
            self._log_plan(plan)
            computed = self._compute(store, pool, plan.todo, groups) if plan.todo else 0
        return self._finish(store, order, computed)

    def _log_plan(self, plan) -> None:
        if plan.kept:
            self.log(f"resuming: {len(plan.kept)} of {len(plan.order)} frames already done with this config")
        if plan.stale:
            self.log(f"recomputing {len(plan.stale)} frame(s) whose rows have another config hash "
                     f"(e.g. {plan.stale[0]}); their rows are replaced")
        if plan.foreign:
            self.log(f"dropping {plan.foreign} row(s) of frames that are not in {self.args.frames}")

    def _pool(self, n_todo: int):
        """A context that yields the pool (None when there is nothing to compute)."""
        from contextlib import nullcontext

        from pipeline.run_pool import LokyPool, wall_guard_s

        if n_todo == 0:
            return nullcontext(None)
        if self.args.backend == "dask":
            from pipeline.run_dask import dask_pool

            return dask_pool(self.args.scheduler, self.args.jobs)
        jobs = min(self.args.jobs or os.cpu_count() or 1, n_todo)
        return nullcontext(LokyPool(jobs, wall_guard_s(self.config.time_limit)))

    def _compute(self, store, pool, todo, groups) -> int:
        from tqdm import tqdm

        from pipeline.run import ChunkBuffer
        from pipeline.run_pool import compute

        store.remove_temporaries()
        tasks, failed = self._tasks(todo, groups)
        buffer = ChunkBuffer(self.args.chunk_size, CHUNK_MAX_AGE_S)
        # SIGTERM (a scheduler's stop) ends the run like Ctrl-C: the finished rows of the chunk are kept.
        signal.signal(signal.SIGTERM, lambda *_: sys.exit(128 + signal.SIGTERM))
        self._bar = tqdm(total=len(todo), desc="r2s run", unit=" frames", file=sys.stderr, disable=None,
                         dynamic_ncols=True)
        try:
            for row in itertools.chain(failed, compute(pool, tasks, self.log)):
                if row is not None:  # None: a heartbeat, no frame finished
                    buffer.add(row, time.monotonic())
                    self._bar.update(1)
                if buffer.due(time.monotonic()):
                    _write_part(store, buffer.take())
        finally:
            if buffer.rows:
                _write_part(store, buffer.take())
            self._bar.close()
            self._bar = None
        return len(todo)

    def _tasks(self, todo, groups):
        """Scenes for the workers; a frame that is not a valid scene is an error row here (the run goes on)."""
        from extractors.frames import FramesError, frame_to_scene
        from pipeline.programs import failure_row
        from pipeline.run_task import TEST_HOOK_ENV, FrameTask

        hook = os.environ.get(TEST_HOOK_ENV) or None
        tasks, failed = [], []
        for fid in todo:
            try:
                scene = frame_to_scene(groups[fid])
            except FramesError as exc:
                failed.append(failure_row(fid, "error", str(exc), len(groups[fid]) - 1, self.config,
                                          self.config_hash))
                continue
            tasks.append(FrameTask(fid, scene, self.config, self.config_hash, hard_cap=self.args.backend == "loky",
                                   test_hook=hook))
        return tasks, failed

    def _finish(self, store, order, computed: int) -> int:
        from pipeline.run import merge_rows, summarize

        rows, _ = store.existing_rows()
        final = merge_rows(order, rows)
        store.consolidate(final)
        summary = summarize(final, computed, time.perf_counter() - self.started)
        sys.stderr.write(f"r2s run: {summary.line()} -> {self.args.out}\n")
        return 0

    def log(self, message: str) -> None:
        line = f"r2s run: {message}"
        if self._bar is not None:
            self._bar.write(line, file=sys.stderr)
        else:
            sys.stderr.write(line + "\n")


def _write_part(store, rows) -> None:
    """Write a chunk with SIGTERM held back: the rows have left the buffer, so an exit in the middle of the write
    would lose them; the signal is delivered (and the run ends) right after."""
    held = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGTERM})
    try:
        store.write_part(rows)
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, held)
