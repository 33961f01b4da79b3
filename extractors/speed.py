"""Speeds from positions over time, for sources that record no velocity: differences along a track, unsmoothed.

A track's speed at a sample is |p_next - p_prev| / (t_next - t_prev) over its neighbouring samples when both are
at most MAX_GAP_S away (a centred difference), else the one-sided difference with the one neighbour that is, else
unknown (NaN). Positions must be in a ground-fixed frame (a city or map frame): differences of ego-frame
positions would be velocities relative to the moving ego.
"""

from __future__ import annotations

from collections.abc import Hashable, Sequence

import numpy as np

MAX_GAP_S = 0.5  # seconds: neighbours further apart than this say nothing about the speed at a sample


def track_speeds(t: np.ndarray, x: np.ndarray, y: np.ndarray, max_gap: float = MAX_GAP_S) -> np.ndarray:
    """Speeds of one track's samples (times in seconds, increasing), NaN where no neighbour is close. Times should
    count from a nearby origin (a log's start), not 1970: a float holds those to ~1e-7 s."""
    t, x, y = (np.asarray(a, dtype=float) for a in (t, x, y))
    n = len(t)
    out = np.full(n, np.nan)
    if n < 2:
        return out
    gap = np.diff(t)
    near = (gap > 0) & (gap <= max_gap)  # near[i]: samples i and i + 1 are neighbours
    has_prev = np.concatenate(([False], near))
    has_next = np.concatenate((near, [False]))
    idx = np.arange(n)
    first = np.where(has_prev, idx - 1, idx)
    last = np.where(has_next, idx + 1, idx)
    known = has_prev | has_next
    dt = t[last] - t[first]
    with np.errstate(divide="ignore", invalid="ignore"):
        v = np.hypot(x[last] - x[first], y[last] - y[first]) / dt
    out[known] = v[known]
    return out


def speeds_by_track(tracks: Sequence[Hashable], t: np.ndarray, x: np.ndarray, y: np.ndarray,
                    max_gap: float = MAX_GAP_S) -> np.ndarray:
    """track_speeds for every track of a table of samples (rows in any order); a track's duplicate times count
    once (the first row), the others get NaN."""
    t, x, y = (np.asarray(a, dtype=float) for a in (t, x, y))
    keys = np.asarray([str(k) for k in tracks])
    out = np.full(len(t), np.nan)
    order = np.lexsort((t, keys))  # by track, then time
    bounds = np.flatnonzero(np.concatenate(([True], keys[order][1:] != keys[order][:-1], [True])))
    for a, b in zip(bounds[:-1], bounds[1:]):
        rows = order[a:b]
        first = np.concatenate(([True], np.diff(t[rows]) > 0))
        rows = rows[first]
        out[rows] = track_speeds(t[rows], x[rows], y[rows], max_gap)
    return out
