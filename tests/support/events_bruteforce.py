"""An independent reference for events (`r2s query --events`): a plain loop over each scene's frames in frame-index
order, the bindings of each frame from tests.support.query_bruteforce (the checker's own verdicts), keyed by the
tracks they bind; a run is extended while the next frame of the scene binds the same tracks."""

from __future__ import annotations

import pandas as pd

from frames.rows import frame_to_scene
from synth.patterns.one_frame import Pattern
from tests.support.query_bruteforce import brute_matches


def brute_events(frames: pd.DataFrame, pattern: Pattern, min_duration_s: float | None = None) -> list[dict]:
    """Events as dicts of the Events Parquet columns (binding and tracks as tuples in name order), in order of the
    first frame's position in `frames`, then of the first binding's entities' rows."""
    order = {fid: k for k, fid in enumerate(dict.fromkeys(frames.frame_id))}
    events = []
    for scene, rows in frames.groupby("scene", sort=False):
        frame_ids = sorted(dict.fromkeys(rows.frame_id), key=lambda f: (int(rows[rows.frame_id == f].frame_index.iloc[0]), order[f]))
        open_runs: dict[tuple, dict] = {}
        for fid in frame_ids:
            f = rows[rows.frame_id == fid]
            track_of = dict(zip(f.entity_id, f.track_id))
            row_of = {e: k for k, e in enumerate(f.entity_id)}
            ts = f.timestamp_us.iloc[0]
            ts = None if pd.isna(ts) else int(ts)
            now: dict[tuple, dict] = {}
            for ids in brute_matches(pattern, frame_to_scene(f)):  # lexicographic: the first of a tracks wins
                tracks = tuple(track_of[i] for i in ids)
                if tracks in now:
                    continue
                run = open_runs.get(tracks)
                if run is None:
                    run = {"scene": scene, "binding": ids, "tracks": tracks, "first_frame": fid,
                           "first_timestamp_us": ts, "n_frames": 0, "_order": (order[fid], [row_of[i] for i in ids])}
                    events.append(run)
                run.update(last_frame=fid, last_timestamp_us=ts, n_frames=run["n_frames"] + 1)
                now[tracks] = run
            open_runs = now  # a binding absent from this frame ends its run
    for e in events:
        known = e["first_timestamp_us"] is not None and e["last_timestamp_us"] is not None
        e["duration_s"] = (e["last_timestamp_us"] - e["first_timestamp_us"]) / 1e6 if known else None
    events.sort(key=lambda e: e.pop("_order"))
    if min_duration_s is not None:
        events = [e for e in events if e["duration_s"] is not None and e["duration_s"] >= min_duration_s]
    return events
