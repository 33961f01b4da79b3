"""Pure logic of `r2s run`: what is already done, what to compute, how rows merge, what the summary says.

No files and no processes here (those are pipeline.run_store and pipeline.run_pool), so resume and merge
rules are tested on plain lists.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

Row = dict[str, Any]


@dataclass(frozen=True)
class RunPlan:
    order: tuple[str, ...]  # every frame id of the input, in input order
    kept: tuple[Row, ...]  # rows already computed with this config hash (not recomputed)
    todo: tuple[str, ...]  # frames to compute, in input order
    stale: tuple[str, ...]  # frames whose existing row has another config hash (recomputed, row replaced)
    foreign: int  # existing rows of frames that are not in the input (dropped from the output)


def plan_run(order: Sequence[str], existing: Iterable[Row], config_hash: str) -> RunPlan:
    """Skip a frame only when a row exists for the same frame id AND the same config hash: the hash covers
    everything that decides the program (SynthConfig.semantic_hash), so a kept row is the row a rerun makes."""
    latest = latest_rows(existing)
    wanted = set(order)
    kept, todo, stale = [], [], []
    for fid in order:
        row = latest.get(fid)
        if row is not None and row.get("config_hash") == config_hash:
            kept.append(row)
        else:
            todo.append(fid)
            if row is not None:
                stale.append(fid)
    foreign = sum(1 for fid in latest if fid not in wanted)
    return RunPlan(tuple(order), tuple(kept), tuple(todo), tuple(stale), foreign)


def latest_rows(rows: Iterable[Row]) -> dict[str, Row]:
    """One row per frame id: the last one wins (sources are read oldest first: output, then parts in order)."""
    out: dict[str, Row] = {}
    for row in rows:
        out[row["frame_id"]] = row
    return out


def merge_rows(order: Sequence[str], rows: Iterable[Row]) -> list[Row]:
    """The final table: one row per input frame that has one, in input order; never a duplicate."""
    latest = latest_rows(rows)
    return [latest[fid] for fid in order if fid in latest]


@dataclass(frozen=True)
class Summary:
    frames: int
    computed: int
    kept: int
    statuses: tuple[tuple[str, int], ...]
    seconds: float

    def line(self) -> str:
        counts = dict(self.statuses)
        optimal = 100.0 * counts.get("optimal", 0) / self.frames if self.frames else 0.0
        others = ", ".join(f"{counts.get(s, 0)} {s}" for s in ("feasible", "timeout", "memout"))
        return (f"{self.frames} frames ({self.computed} computed, {self.kept} kept), {optimal:.1f}% optimal, "
                f"{others}, {counts.get('error', 0)} errors, {self.seconds:.1f} s")


def summarize(rows: Sequence[Row], computed: int, seconds: float) -> Summary:
    statuses = Counter(str(r["status"]) for r in rows)
    return Summary(len(rows), computed, len(rows) - computed, tuple(sorted(statuses.items())), seconds)


class ChunkBuffer:
    """Finished rows waiting for their part file: a chunk is due at `size` rows, or after `max_age_s` seconds
    so that slow frames are not held back (a kill loses what is buffered, besides the frames in flight)."""

    def __init__(self, size: int, max_age_s: float) -> None:
        self.size, self.max_age_s = size, max_age_s
        self.rows: list[Row] = []
        self._since: float | None = None

    def add(self, row: Row, now: float) -> None:
        if not self.rows:
            self._since = now
        self.rows.append(row)

    def due(self, now: float) -> bool:
        if not self.rows:
            return False
        return len(self.rows) >= self.size or (self._since is not None and now - self._since >= self.max_age_s)

    def take(self) -> list[Row]:
        rows, self.rows, self._since = self.rows, [], None
        return rows
