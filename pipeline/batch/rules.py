"""Pure logic of `r2s run`: how frames are grouped into chunks, when finished rows become a part file, what the
summary says. No files and no processes here (those are pipeline.batch.store and pipeline.batch.pool), so the rules
are tested on plain values.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass

import numpy as np
import pyarrow as pa

from pipeline.programs import STATUSES

Frame = tuple[str, int, int]  # (frame id, first row in its file, rows)


@dataclass(frozen=True)
class Summary:
    frames: int  # rows in the output: one per frame done, now or before
    computed: int  # frames computed by this run
    kept: int  # frames whose row an earlier run wrote with the same config
    statuses: tuple[tuple[str, int], ...]
    seconds: float
    first_result_s: float | None = None  # seconds from the start to the first finished frame
    changed: int = 0  # of the computed, frames recomputed because their rows changed since their stored program
    unit: str = "frames"  # what a row is of: frames, or windows (r2s run --window)

    def line(self) -> str:
        counts = dict(self.statuses)
        optimal = 100.0 * counts.get("optimal", 0) / self.frames if self.frames else 0.0
        others = ", ".join(f"{counts.get(s, 0)} {s}" for s in ("feasible", "timeout", "memout"))
        changed = f"; {self.changed} recomputed because their rows changed" if self.changed else ""
        return (f"{self.frames} {self.unit} ({self.computed} computed, {self.kept} kept), {optimal:.1f}% optimal, "
                f"{others}, {counts.get('error', 0)} errors, {self.seconds:.1f} s{changed}")


def summarize(counts: Mapping[str, int], computed: int, seconds: float, first_result_s: float | None = None,
              changed: int = 0, unit: str = "frames") -> Summary:
    frames = sum(counts.values())
    return Summary(frames, computed, frames - computed, tuple(sorted((s, int(n)) for s, n in counts.items())),
                   seconds, first_result_s, changed, unit)


def status_counts(table: pa.Table) -> dict[str, int]:
    values, counts = np.unique(table.column("status").to_numpy(zero_copy_only=False).astype(str), return_counts=True)
    return {str(v): int(c) for v, c in zip(values, counts)}


def chunk_size_for(todo: int, slots: int, largest: int) -> int:
    """Frames per task: `largest`, but small enough that every worker gets at least two tasks (a small run keeps
    its parallelism)."""
    return max(1, min(largest, -(-todo // (2 * max(slots, 1)))))


def chunk_sizes(slots: int, largest: int) -> Iterator[int]:
    """Frames per chunk, one chunk after another: 1 for the first chunk of each worker, then doubling up to
    `largest`, so the first rows come back after one frame, not after a whole chunk."""
    size = 1
    while True:
        for _ in range(max(slots, 1)):
            yield min(size, largest)
        size *= 2


def chunks(runs: Iterable[tuple[int, np.ndarray, np.ndarray, np.ndarray, np.ndarray]], sizes: int | Iterator[int],
           max_span_rows: int) -> Iterator[tuple[int, list[Frame]]]:
    """Group the frames to compute into chunks of one file, of the sizes `sizes` gives one after another (or all
    of one size), spanning at most `max_span_rows` rows (a worker reads the row groups under the span). `runs`
    yields (part, starts, lengths, ids, todo mask) in file order."""
    sizes = itertools.repeat(sizes) if isinstance(sizes, int) else iter(sizes)
    size = next(sizes)
    part, chunk = None, []
    for k, starts, lengths, ids, todo in runs:
        if k != part and chunk:
            yield part, chunk
            chunk, size = [], next(sizes)
        part = k
        for i in np.flatnonzero(todo):
            start, n = int(starts[i]), int(lengths[i])
            if chunk and start + n - chunk[0][1] > max_span_rows:
                yield part, chunk
                chunk, size = [], next(sizes)
            chunk.append((str(ids[i]), start, n))
            if len(chunk) >= size:
                yield part, chunk
                chunk, size = [], next(sizes)
    if chunk:
        yield part, chunk


class PartBuffer:
    """Finished rows waiting for their part file: a part is due at `rows` rows, or `max_age_s` seconds after its
    first row so that slow frames do not hold finished ones back (a kill loses what is buffered, besides the
    frames in flight)."""

    def __init__(self, rows: int, max_age_s: float) -> None:
        self.rows, self.max_age_s = rows, max_age_s
        self.tables: list[pa.Table] = []
        self.count = 0
        self._since: float | None = None

    def add(self, table: pa.Table, now: float) -> None:
        if not self.tables:
            self._since = now
        self.tables.append(table)
        self.count += table.num_rows

    def due(self, now: float) -> bool:
        if not self.tables:
            return False
        return self.count >= self.rows or (self._since is not None and now - self._since >= self.max_age_s)

    def take(self) -> pa.Table:
        table = pa.concat_tables(self.tables)
        self.tables, self.count, self._since = [], 0, None
        return table


def status_line(counts: Mapping[str, int]) -> str:
    return ", ".join(f"{counts[s]:,} {s}" for s in STATUSES if counts.get(s))
