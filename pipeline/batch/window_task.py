"""The worker side of `r2s run --window`: windows in (their frames' places), one programs row per window out.

A window task is to windows what a chunk task (pipeline.batch.task) is to frames, with the same members the pool
asks of a task (key, units in `frames`, singles, split_at, marker, run, lost_rows), so the pool's rules (at most
`jobs` in flight, a dead worker's suspects retried one at a time, the wall-clock guard) hold unit by unit. Each
window reads its frames' rows, hashes them as read (what its row records), and runs synth.window.program under the
frame's limits (the time limit bounds its search, the memory cap its worker).
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass

import numpy as np
import pyarrow as pa

from frames.dataset import read_frame_rows
from frames.maps import FrameRoads
from frames.rows import FramesError
from pipeline.batch.task import (
    ChunkInvalid,
    ChunkUnreadable,
    Units,
    _hard_memory_cap,
    _reset_peak_rss,
    frame_scene,
    hash_rows,
    one_line,
)
from pipeline.batch.windows import WindowSpec, WindowUnit
from pipeline.programs import WINDOW_SCHEMA, failure_row, programs_table, result_row
from synth.config import SynthConfig
from synth.search.budget import peak_rss_mb
from synth.window.program import synthesize_window


@dataclass(frozen=True)
class WindowTask(Units):
    """Windows to synthesize in one go: `frames[i]` is window i (a WindowUnit; the pool's unit of blame)."""

    key: str
    url: str
    parts: tuple[tuple[str, tuple[str, ...]], ...]  # (path, columns) of every part of the dataset
    frames: tuple[WindowUnit, ...]
    config: SynthConfig
    spec: WindowSpec
    config_hash: str  # the rows' (WindowSpec.config_hash)
    hard_cap: bool = False
    progress_dir: str | None = None
    maps: str | None = None  # with lanes: the maps beside the frames, each frame's road as r2s scene gives it

    def read(self, unit: WindowUnit, roads: FrameRoads | None) -> tuple[list, str]:
        """The window's frames' rows (one Arrow table each, in order) and the window's hash of them as read (with
        `roads`, --lanes: of the maps they name too)."""
        frames, lanes = [], []
        for k in sorted({p.part for p in unit.frames}):
            path, columns = self.parts[k]
            mine = [p for p in unit.frames if p.part == k]
            first, stop = min(p.start for p in mine), max(p.start + p.rows for p in mine)
            try:  # through the checks of every reader of frames, as a chunk task reads (pipeline.batch.task)
                rows = read_frame_rows(self.url, path, first, stop, columns)
            except FramesError as exc:
                raise ChunkInvalid(one_line(str(exc), 400)) from None
            except (OSError, pa.ArrowException) as exc:
                raise ChunkUnreadable(one_line(f"cannot read {self.url or ''}{path}: {exc}", 400)) from None
            for p in mine:
                piece = rows.slice(p.start - first, p.rows)
                lane0, lane1 = hash_rows(piece, np.zeros(1, dtype=np.int64), roads)
                frames.append((p.frame_id, piece))
                lanes.append((lane0[0], lane1[0]))
        order = {p.frame_id: i for i, p in enumerate(unit.frames)}
        ranked = sorted(zip(frames, lanes), key=lambda fl: order[fl[0][0]])
        ids = [f[0] for f, _ in ranked]
        # The timestamps as read (not as planned): a row records what it was computed from.
        read = unit._replace(timestamps_us=tuple(_first_timestamp(f[1]) for f, _ in ranked))
        digest = self.spec.unit_hash(read, ids, np.array([a for _, (a, _) in ranked], dtype=np.uint64),
                                     np.array([b for _, (_, b) in ranked], dtype=np.uint64))
        return [f[1] for f, _ in ranked], digest

    def run(self) -> pa.Table:
        """A row per window, in order. Never raises for a window, only when rows cannot be read at all."""
        marker = self.marker()
        roads = FrameRoads(self.maps) if self.maps is not None else None  # read once for the task's windows
        out = []
        for i, unit in enumerate(self.frames):
            if marker is not None:
                with open(marker, "w") as f:  # its mtime is when this window started (the wall-clock guard)
                    f.write(str(i))
            out.append(self._run_window(unit, roads))
        if marker is not None:
            try:
                os.unlink(marker)
            except FileNotFoundError:
                pass
        return programs_table(out, self.schema)

    schema = WINDOW_SCHEMA  # of the rows

    def synthesize(self, scenes: list, unit: WindowUnit, digest: str) -> dict:
        """The row of a window whose frames are `scenes` (synth.window.program)."""
        return {**result_row(synthesize_window(scenes, self.config), digest), **self._window_fields(unit),
                "config_hash": self.config_hash}

    def _run_window(self, unit: WindowUnit, roads: FrameRoads | None) -> dict:
        started = time.perf_counter()
        frames, digest = self.read(unit, roads)
        n_entities = max(len(f) for f in frames) - 1
        try:
            scenes = [frame_scene(f, roads) for f in frames]
        except FramesError as exc:  # one bad frame is an error row for its window; the run goes on
            return self._failure(unit, "error", str(exc), n_entities, digest)
        _reset_peak_rss()
        try:
            with _hard_memory_cap(self.config.memory_limit if self.hard_cap else None):
                return self.synthesize(scenes, unit, digest)
        except MemoryError:
            status, message = "memout", "out of memory outside the search (hard cap of the worker reached)"
        except Exception as exc:  # the run goes on: the window is recorded as an error, with the reason
            status, message = "error", one_line(f"{type(exc).__name__}: {exc}")
        return self._failure(unit, status, message, n_entities, digest, time.perf_counter() - started, peak_rss_mb())

    def _window_fields(self, unit: WindowUnit) -> dict:
        return {"frame_id": unit.frames[0].frame_id, "scene": unit.scene, "last_frame": unit.frames[-1].frame_id,
                "first_timestamp_us": unit.first_timestamp_us, "last_timestamp_us": unit.last_timestamp_us,
                "n_frames": len(unit.frames), "window_s": self.spec.window_s}

    def _failure(self, unit: WindowUnit, status: str, message: str, n_entities: int, digest: str | None,
                 runtime_s: float = 0.0, peak_mb: float = 0.0) -> dict:
        row = failure_row(unit.frames[0].frame_id, status, message, n_entities, self.config, runtime_s, peak_mb,
                          frame_hash=digest)
        return {**row, **self._window_fields(unit), "config_hash": self.config_hash}

    def lost_rows(self, status: str, reason: str) -> pa.Table:
        """The rows of windows whose worker died, with their hash (read here: a rare event) so that a resume keeps
        the verdict for the same rows; None if they cannot be read (recomputed)."""
        rows = []
        roads = FrameRoads(self.maps) if self.maps is not None else None
        for unit in self.frames:
            try:
                frames, digest = self.read(unit, roads)
                n_entities = max(len(f) for f in frames) - 1
            except ChunkUnreadable:
                digest, n_entities = None, 0
            rows.append(self._failure(unit, status, reason, n_entities, digest))
        return programs_table(rows, self.schema)


def _first_timestamp(rows: pa.Table) -> int | None:
    """A frame's timestamp_us (its rows all carry it)."""
    return rows.column("timestamp_us")[0].as_py() if "timestamp_us" in rows.column_names else None
