"""The worker side of `r2s run`: a chunk of frames in (a file and a row range), one programs row per frame out.

A chunk task reads its own rows (frames.dataset.read_frame_rows: a file and a row range, through the
checks of every reader of frames), so frame data never passes through the process that plans the run, on one machine or on a cluster. Each frame runs under its own time and memory
limits (run_frame), and becomes a row whatever happens to it; only a dead worker loses rows. Before each frame
the task writes the frame's index to its progress marker, so that when a worker dies the run knows which frame
it was running: that frame is the suspect, the others of the chunk are innocent.

Everything a worker needs is imported at module level on purpose: unpickling the task imports this module
before the task runs, so the imports are paid once per worker and are not counted against a frame's hard
memory cap.
"""

from __future__ import annotations

import os
import resource
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, replace

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from frames.dataset import read_frame_rows
from frames.frame_hash import Coverage, frame_hashes_of, to_hex
from frames.maps import FrameRoads
from frames.rows import FramesError, frame_to_scene
from frames.scene import EgoPlace, FrameColumns
from pipeline.programs import failure_row, programs_table, result_row
from synth.config import SynthConfig
from synth.errors import InternalError
from synth.result import SynthResult
from synth.scene import Scene
from synth.search.budget import current_rss_mb, peak_rss_mb
from synth.synthesize import synthesize

# What a frame runs when not synth.synthesize: a function of the same signature given to run_frames (a
# module-level function or a functools.partial of one: the task carries it to the worker by reference).
Synthesizer = Callable[[Scene, SynthConfig], SynthResult]

# Room left above the soft limit before the hard cap: the Budget's RSS poll (every 4096 nodes) should stop the
# search first and return its best program; the hard cap catches what the poll cannot see (allocation outside
# the search, inside z3, or between two polls). A worker's VmSize jumps by ~130 MB when z3 opens a new arena.
HARD_CAP_MARGIN_MB = 256.0


@dataclass(frozen=True)
class FrameTask:
    frame_id: str
    scene: Scene
    config: SynthConfig
    # Set only where the worker is a process of its own (loky): an address-space limit is per process, and a
    # threaded dask worker shares its process with other frames (or with the run itself).
    hard_cap: bool = False
    synthesizer: Synthesizer | None = None  # None: synth.synthesize
    frame_hash: str | None = None  # the hash of the rows the scene came from (frames.frame_hash)


class Units:
    """What the pool asks of a task besides running it (pipeline.batch.pool): its units in `frames` (frames, or
    windows: pipeline.batch.window_task), taken apart to retry or blame one, and its progress marker. A frozen
    dataclass with `key`, `frames` and `progress_dir` fields."""

    def only(self, indices, tag: str):
        return replace(self, key=f"{self.key}.{tag}", frames=tuple(self.frames[i] for i in indices))

    def split_at(self, i: int):
        """(unit i alone, the other units or None)."""
        rest = [k for k in range(len(self.frames)) if k != i]
        return self.only([i], f"s{i}"), (self.only(rest, f"r{i}") if rest else None)

    def singles(self) -> list:
        return [self.only([i], f"s{i}") for i in range(len(self.frames))]

    def marker(self) -> str | None:
        return None if self.progress_dir is None else os.path.join(self.progress_dir, self.key)


@dataclass(frozen=True)
class ChunkTask(Units):
    """Frames of one file to synthesize in one go: frame i is `frames[i] = (frame_id, first row, rows)`."""

    key: str  # unique within the run: names the progress marker and the dask task
    url: str  # the filesystem of a dataset given as a URL ("" for local paths)
    path: str
    frames: tuple[tuple[str, int, int], ...]
    columns: tuple[str, ...]
    config: SynthConfig
    hard_cap: bool = False
    synthesizer: Synthesizer | None = None  # None: synth.synthesize
    progress_dir: str | None = None  # where the marker goes; None: progress is not tracked (remote workers)
    maps: str | None = None  # with lanes: the maps beside the frames (frames.maps), whence each frame's road

    @property
    def frame_ids(self) -> list[str]:
        return [f[0] for f in self.frames]

    def read(self, roads: FrameRoads | None = None) -> tuple[pa.Table, int, list[str]]:
        """The rows of the chunk's span (whole frames, from its first frame's first row to its last frame's last
        row), the span's first row, and the hash of each of the chunk's frames' rows in its order
        (frames.frame_hash): a row records what it was computed from, as the worker read it; with `roads` (the
        maps the frames' roads come from: --lanes), the maps they name too."""
        first = min(f[1] for f in self.frames)
        stop = max(f[1] + f[2] for f in self.frames)
        try:  # through the checks of every reader of frames: the footer as the file is now, every value decoded
            rows = read_frame_rows(self.url, self.path, first, stop, self.columns)
        except FramesError as exc:
            raise ChunkInvalid(one_line(str(exc), 400)) from None
        except (OSError, pa.ArrowException) as exc:
            raise ChunkUnreadable(one_line(f"cannot read {self.url or ''}{self.path}: {exc}", 400)) from None
        # The span cut at every start and end of the chunk's frames (rows between them are other frames': one
        # vectorized pass over the span, the pieces between are hashed and not used).
        cuts = sorted({f[1] - first for f in self.frames} | {f[1] + f[2] - first for f in self.frames} - {stop - first})
        lanes = hash_rows(rows, np.array(cuts, dtype=np.int64), roads)
        hashes = dict(zip(cuts, to_hex(*lanes)))
        return rows, first, [hashes[f[1] - first] for f in self.frames]

    def roads(self) -> FrameRoads | None:
        return FrameRoads(self.maps) if self.maps is not None else None


    def run(self) -> pa.Table:
        """What a worker runs (run_task): a row per frame, in order."""
        return run_chunk(self)

    def lost_rows(self, status: str, reason: str) -> pa.Table:
        """The rows of frames whose worker died, with the hash of their rows (read here: a rare event, one frame
        usually) so that a resume keeps the verdict for the same rows; None if they cannot be read (recomputed)."""
        try:
            hashes = self.read(self.roads())[2]
        except ChunkUnreadable:
            hashes = [None] * len(self.frames)
        return programs_table([failure_row(fid, status, reason, n - 1, self.config, frame_hash=h)
                               for (fid, _, n), h in zip(self.frames, hashes)])


def run_task(task) -> pa.Table:
    """What the pool submits: the task's own run (a ChunkTask, or a window task: pipeline.batch.window_task)."""
    return task.run()


class ChunkUnreadable(InternalError):
    """A worker could not read its chunk (the file moved, or a cluster worker does not see the path)."""

    hint = " (on a cluster, the frames must be at a path every worker sees)"


class ChunkInvalid(ChunkUnreadable):
    """A chunk's rows fail the frames checks as a worker reads them: the file changed since the run checked it,
    or a column the check does not read holds a corrupt value."""

    hint = ""


def run_chunk(task: ChunkTask) -> pa.Table:
    """Programs rows of every frame of the chunk, in its order. Never raises for a frame, only when the rows
    cannot be read at all (ChunkUnreadable)."""
    roads = task.roads()
    table, first, hashes = task.read(roads)
    marker = task.marker()
    out = []
    for i, ((frame_id, start, n), frame_hash) in enumerate(zip(task.frames, hashes)):
        if marker is not None:
            with open(marker, "w") as f:  # its mtime is when this frame started (the wall-clock guard reads it)
                f.write(str(i))
        try:
            scene = frame_scene(table.slice(start - first, n), roads)
        except FramesError as exc:  # one bad frame is an error row; the rest of the chunk goes on
            out.append(failure_row(frame_id, "error", str(exc), n - 1, task.config, frame_hash=frame_hash))
            continue
        out.append(run_frame(FrameTask(frame_id, scene, task.config, task.hard_cap, task.synthesizer, frame_hash)))
    if marker is not None:
        try:
            os.unlink(marker)
        except FileNotFoundError:
            pass
    return programs_table(out)


def hash_rows(rows: pa.Table, starts: np.ndarray, roads: FrameRoads | None) -> tuple[np.ndarray, np.ndarray]:
    """frames.frame_hash.frame_hashes_of of rows a worker read, covering what the run's check hashed: with roads
    (--lanes), the content of every map the rows name as this worker reads it (FrameRoads.digest). Rows or maps that
    the check passed and that cannot be hashed now changed since: a ChunkInvalid."""
    try:
        if roads is None:
            return frame_hashes_of(rows, starts)
        named = pc.unique(rows.column("map_id")).drop_null().to_pylist() if "map_id" in rows.column_names else []
        return frame_hashes_of(rows, starts, Coverage.with_road({m: roads.digest(m) for m in named}))
    except FramesError as exc:
        raise ChunkInvalid(one_line(str(exc), 400)) from None


def frame_scene(rows: pa.Table, roads: FrameRoads | None) -> Scene:
    """A frame's rows as its Scene, with (given `roads`: --lanes) the road r2s scene gives it; the rows and the ego
    row are read once for both (frames.scene). A map the frame names but the maps lack is a
    FramesError."""
    rows = FrameColumns.of(rows)  # read once, column by column
    place = EgoPlace.of(rows)
    road = None
    if roads is not None:
        road, missing = roads.road(rows, place)
        if missing is not None:
            raise FramesError(f"the frame names map {missing!r}, which is not in {roads.where}")
    return frame_to_scene(rows, road, place)


def run_frame(task: FrameTask) -> dict:
    """Synthesize one frame; a frame that raises becomes an `error` row with a one-line message."""
    started = time.perf_counter()
    config = task.config
    _reset_peak_rss()
    try:
        with _hard_memory_cap(config.memory_limit if task.hard_cap else None):
            return result_row((task.synthesizer or synthesize)(task.scene, config), task.frame_hash)
    except MemoryError:
        status, message = "memout", "out of memory outside the search (hard cap of the worker reached)"
    except Exception as exc:  # the run goes on: the frame is recorded as an error, with the reason
        status, message = "error", one_line(f"{type(exc).__name__}: {exc}")
    return failure_row(task.frame_id, status, message, len(task.scene.others), config, runtime_s=time.perf_counter() - started, peak_rss_mb=peak_rss_mb(), frame_hash=task.frame_hash)


def one_line(text: str, limit: int = 300) -> str:
    text = " ".join(str(text).split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _reset_peak_rss() -> None:
    # A worker takes many frames and VmHWM is a lifetime peak: without a reset, peak_rss_mb of a frame would
    # be the worst of every frame before it in that worker. Linux resets the high-water mark on "5".
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
    except OSError:  # pragma: no cover - non-Linux or not permitted: the lifetime peak stays an upper bound
        pass


def _vm_size_mb() -> float | None:
    try:
        with open("/proc/self/statm", "rb") as f:
            return int(f.read().split()[0]) * resource.getpagesize() / 2**20
    except OSError:  # pragma: no cover - non-Linux: no hard cap, the Budget's poll still applies
        return None


@contextmanager
def _hard_memory_cap(limit_mb: float | None) -> Iterator[None]:
    """RLIMIT_AS for the duration of one frame, so an allocation past the cap raises MemoryError in this frame
    instead of letting the kernel's OOM killer pick a victim (maybe another worker, or the run).

    Why RLIMIT_AS and not a watchdog thread on RSS: the kernel enforces it at the allocation itself, with no
    polling window, and Python turns it into a MemoryError the task can record while the worker lives on.
    Its flaw is that it counts address space, not resident memory (a worker reserves ~300 MB it never
    touches), so the cap is the current address space plus the allowed growth, not the limit itself. Only the
    soft limit is lowered and restored afterwards, so the same worker can take the next frame unchanged.
    """
    vm = _vm_size_mb() if limit_mb is not None else None
    if vm is None:
        yield
        return
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    growth = max(limit_mb - current_rss_mb(), 0.0) + max(0.5 * limit_mb, HARD_CAP_MARGIN_MB)
    cap = int((vm + growth) * 2**20)
    if hard != resource.RLIM_INFINITY:
        cap = min(cap, hard)
    if soft != resource.RLIM_INFINITY:
        cap = min(cap, soft)
    resource.setrlimit(resource.RLIMIT_AS, (cap, hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_AS, (soft, hard))
