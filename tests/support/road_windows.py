"""The windows of frames extracted with their maps, each frame with the road `r2s scene` gives it: what the tests of
programs over a window read real data through (tests/synth/window/test_window_lanes.py, test_window_road.py)."""

from __future__ import annotations

from pathlib import Path

from synth import tile
from synth.scene import Scene


def road_windows(frames: Path, window_s: float, limit: int | None = None) -> list[list[Scene]]:
    """The windows (tile over the timestamps) of every scene of frames extracted with their maps, each frame with
    the road `r2s scene` gives it (frames.maps.FrameRoads)."""
    import pandas as pd

    from frames.maps import FrameRoads, maps_dir
    from frames.rows import frame_to_scene

    roads = FrameRoads(maps_dir(frames))
    out = []
    for _, rows in pd.read_parquet(frames).groupby("scene", sort=True):
        rows = rows.sort_values("frame_index", kind="stable")
        frames_ = [(int(g.timestamp_us.iloc[0]), frame_to_scene(g, roads.road(g)[0]))
                   for _, g in rows.groupby("frame_id", sort=False)]
        for first, last in tile([t for t, _ in frames_], int(window_s * 1e6))[:limit]:
            out.append([s for _, s in frames_[first:last + 1]])
    return out
