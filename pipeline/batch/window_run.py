"""The batch stage run with --window (pipeline.batch.stage's run, unit by unit): the rows are windows', planned by
pipeline.batch.windows and computed by pipeline.batch.window_task; parts, resume, the pool, progress and the
summary are the stage's own."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pyarrow as pa

from extractors.frame_hash import FrameHasher, frame_keys, from_hex
from pipeline.batch.rules import chunk_size_for, chunk_sizes
from pipeline.batch.stage import _Run
from pipeline.batch.window_task import WindowTask
from pipeline.batch.windows import plan_windows
from pipeline.programs import WINDOW_SCHEMA
from storage.frame_index import FrameIndex, frame_hashes


class WindowRun(_Run):
    unit = "windows"
    schema = WINDOW_SCHEMA

    def _units(self, dataset) -> tuple[int, Any, Any, str]:
        spec = self.options.window
        hasher = FrameHasher(keep_lanes=True)
        _, _ = dataset.check(hasher)
        self._windows, hashes = plan_windows(dataset, hasher, spec)
        firsts = [w.frames[0].frame_id for w in self._windows]
        hi, lo = frame_hashes(firsts)
        lane0, lane1, _ = from_hex(pa.array(hashes, pa.string()))
        return len(firsts), FrameIndex(hi, lo), FrameIndex(*frame_keys(hi, lo, lane0, lane1)), \
            spec.config_hash(self.config)

    def _tasks(self, dataset, done, todo: int, pool, progress_dir: str | None) -> Iterator[WindowTask]:
        spec = self.options.window
        parts = tuple((p.path, p.columns) for p in dataset.parts)
        windows = self._windows
        if len(done):
            windows = [w for w, kept in zip(windows, done.contains(*frame_hashes([w.frames[0].frame_id
                                                                                  for w in windows]))) if not kept]
        slots = pool.slots()
        sizes = chunk_sizes(slots, chunk_size_for(todo, slots, self.options.chunk_size))
        at, n = 0, 0
        while at < len(windows):
            size = next(sizes)
            yield WindowTask(f"w{n}", dataset.url, parts, tuple(windows[at:at + size]), self.config, spec,
                             spec.config_hash(self.config), hard_cap=pool.own_processes, progress_dir=progress_dir)
            at, n = at + size, n + 1
