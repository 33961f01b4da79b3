"""Events: the per-frame bindings of a pattern grouped into maximal runs of consecutive frames (docs/formats.md,
"Events Parquet").

A binding is the same from frame to frame when it binds the same tracks (track ids, which extractors keep one to
one with entity ids within a scene). Consecutive frames are consecutive positions in a scene (frame_pos: the
frames of the scene in frame-index order). A run is found with the gaps-and-islands rule: within one (scene,
tracks), frame_pos minus the dense rank of frame_pos is constant exactly along a run of consecutive positions (one
window, one aggregate). All of it is one DuckDB query over the bindings relation m (pipeline.query.sql.bindings_query), which sorts and spills as it needs:
nothing is held in Python.
"""

from __future__ import annotations

import math

from pipeline.errors import UserError

EVENT_COLUMNS = ("scene", "binding", "tracks", "first_frame", "last_frame", "first_timestamp_us",
                 "last_timestamp_us", "duration_s", "n_frames")


def events_select(min_duration_s: float | None = None) -> str:
    """The SELECT that follows `WITH ..., m AS (...)`: one row per event, in order of the event's first frame in
    the input, then of its first binding's rows. With min_duration_s, only events at least that long."""
    if min_duration_s is not None and not (math.isfinite(min_duration_s) and min_duration_s >= 0):
        raise UserError(f"--min-duration must be a finite number of seconds >= 0, got {min_duration_s}")
    having = f" HAVING duration_s >= '{float(min_duration_s)!r}'::DOUBLE" if min_duration_s is not None else ""
    # A frame may bind the same tracks twice (a track id given to two boxes by another tool's frames): one binding
    # of those tracks, its first in key order. dense_rank numbers a (scene, tracks)'s frames, so the rows of one
    # frame share an island, and an island is a run of consecutive positions: its frames are last - first + 1.
    # One sort (the window) and one aggregate: no per-frame grouping of the bindings first.
    return (
        ", islands AS (SELECT *, frame_pos - dense_rank() OVER (PARTITION BY scene, tracks ORDER BY frame_pos) "
        "AS island FROM m)"
        ", events AS (SELECT scene, tracks, first(binding ORDER BY frame_pos, key) AS binding, "
        "first(frame_id ORDER BY frame_pos) AS first_frame, last(frame_id ORDER BY frame_pos) AS last_frame, "
        "first(timestamp_us ORDER BY frame_pos) AS first_timestamp_us, "
        "last(timestamp_us ORDER BY frame_pos) AS last_timestamp_us, "
        "(last(timestamp_us ORDER BY frame_pos) - first(timestamp_us ORDER BY frame_pos)) / 1e6 AS duration_s, "
        "max(frame_pos) - min(frame_pos) + 1 AS n_frames, first(frame_ord ORDER BY frame_pos) AS first_ord, "
        f"first(key ORDER BY frame_pos, key) AS first_key FROM islands GROUP BY scene, tracks, island{having})\n"
        f"SELECT {', '.join(EVENT_COLUMNS)} FROM events ORDER BY first_ord, first_key"
    )
