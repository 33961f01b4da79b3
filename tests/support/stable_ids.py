"""The stable-id rule of docs/formats.md, computed independently of frames.naming: per scene, each track's
first frame (by frame index) and its distance to ego there; tracks ranked by (first frame, distance, track id);
the n-th track of a type (its type at first appearance) is `<type>n`."""

from __future__ import annotations

import pandas as pd


def expected_ids(frames: pd.DataFrame) -> pd.Series:
    """The entity id every non-ego row should have, indexed like those rows."""
    rows = frames[~frames.is_ego].copy()
    rows["distance"] = (rows.x ** 2 + rows.y ** 2) ** 0.5
    first = (rows.sort_values(["scene", "frame_index", "distance", "track_id"])
             .drop_duplicates(["scene", "track_id"]).copy())
    first["prefix"] = first.type.str.lower()
    first["n"] = first.groupby(["scene", "prefix"]).cumcount() + 1
    first["expected"] = first.prefix + first.n.astype(str)
    merged = rows.reset_index().merge(first[["scene", "track_id", "expected"]], on=["scene", "track_id"])
    return merged.set_index("index").expected.reindex(rows.index)
