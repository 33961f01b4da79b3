"""Frames as rows, tables and Scenes: the one frames schema (frames.schema, docs/formats.md, "Frames
Parquet") that every extractor writes and the pipeline reads, a frame's rows to a Scene and back.

One row per entity per frame, ego included, in the ego-centric frame (+x right, +y forward, heading degrees
counter-clockwise from +y). Writing is atomic; reading validates, so a corrupt or foreign file is refused
with one clear line instead of failing deep inside a worker.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterator, Mapping
from typing import TYPE_CHECKING, Any

import pyarrow as pa
import pyarrow.parquet as pq

from frames.dataset import FramesDataset, check_table
from frames.naming import SceneNames
from frames.scene import arrow_rows, frame_to_scene
from frames.schema import (
    EXTRACTED_SCHEMA,
    FRAMES_COLUMNS,
    FRAMES_SCHEMA,
    LANE_FACT_COLUMNS,
    OPTIONAL_COLUMNS,
    ROAD_COLUMNS,
    FramesError,
)
from storage.atomic import atomic_path
from synth.scene import EGO_ID, Scene, make_scene

if TYPE_CHECKING:  # pandas is imported where rows are tabled: `r2s extract --help` and the sources need it not
    import pandas as pd


def frame_rows(
    source: str,
    scene_name: str,
    frame_index: int,
    timestamp_us: int | None,
    ego: Mapping[str, Any],
    others: list[Mapping[str, Any]],
    frame_id: str | None = None,
    names: SceneNames | None = None,
) -> list[dict[str, Any]]:
    """Rows of one frame. ego / others are dicts with track_id, type, category, x, y, heading, length, width
    already in the ego frame, and speed (m/s or None), and the road columns where known. Ids come from `names`,
    the scene's numbering so far (frames.naming: one id per track across a scene); without it, the frame is
    numbered on its own."""
    fid = frame_id or f"{scene_name}/{frame_index}"
    names = names if names is not None else SceneNames()
    tracks = [str(o.get("track_id", i)) for i, o in enumerate(others)]
    distances = [math.hypot(o["x"], o["y"]) for o in others]
    ids = names.name(scene_name, tracks, [o["type"] for o in others], distances)
    rows = []
    for eid, o, track, is_ego in [(EGO_ID, ego, str(ego.get("track_id", EGO_ID)), True)] + [
            (i, o, t, False) for i, o, t in zip(ids, others, tracks)]:
        rows.append(
            {
                "frame_id": fid, "source": source, "scene": scene_name, "frame_index": frame_index,
                "timestamp_us": timestamp_us, "entity_id": eid, "track_id": track,
                "type": o["type"], "category": str(o.get("category", o["type"])),
                "x": float(o["x"]), "y": float(o["y"]), "heading": float(o["heading"]) % 360.0,
                "length": o.get("length"), "width": o.get("width"), "is_ego": is_ego,
                "speed": known_speed(o.get("speed")),
                **{c: o[c] for c in ROAD_COLUMNS if c in o},
            }
        )
    # Ego first, then by distance to ego (ties by track id), the order ids are given in within a frame.
    order = sorted(range(len(others)), key=lambda i: (distances[i], tracks[i]))
    rows[1:] = [rows[1 + i] for i in order]
    return rows


def known_speed(v: Any) -> float | None:
    """A speed as frames store it: a finite, non-negative float, else None (unknown)."""
    if v is None:
        return None
    f = float(v)
    return f if math.isfinite(f) and f >= 0.0 else None


def to_table(rows: pd.DataFrame | list[dict[str, Any]]) -> pa.Table:
    """Rows as a table of exactly FRAMES_SCHEMA (plus optional columns present), validated."""
    import pandas as pd

    if not isinstance(rows, pd.DataFrame):
        optional = [c for c in {**OPTIONAL_COLUMNS, **ROAD_COLUMNS} if any(c in r for r in rows)]
        rows = pd.DataFrame(rows, columns=list(FRAMES_COLUMNS) + optional)
    df = rows
    validate_frames(df)
    types = {**OPTIONAL_COLUMNS, **ROAD_COLUMNS}
    extra = [c for c in types if c in df.columns]
    schema = pa.schema(list(FRAMES_SCHEMA) + [(c, types[c]) for c in extra])
    try:
        return pa.Table.from_pandas(df[list(FRAMES_COLUMNS) + extra], schema=schema, preserve_index=False)
    except (pa.ArrowException, TypeError, ValueError) as exc:  # a column the check does not read, of the wrong type
        raise FramesError(f"a column has values of the wrong type ({str(exc)[:120]})") from None


def write_frames(rows: pd.DataFrame | list[dict[str, Any]] | pa.Table, path: str | os.PathLike) -> int:
    """Write frames.parquet atomically (temp file, then rename). Returns the number of rows."""
    table = rows if isinstance(rows, pa.Table) else to_table(rows)
    with atomic_path(path) as tmp:
        pq.write_table(table, tmp, compression="zstd")
    return table.num_rows


def read_frames(path: str | os.PathLike) -> pd.DataFrame:
    """Read and validate a frames file or dataset directory, whole (small data: `r2s run` streams instead); any
    problem is a FramesError naming the file."""
    return FramesDataset.open(path).read_all().to_pandas()


def validate_frames(df: pd.DataFrame) -> None:
    """The rules every frames table obeys (finite positions, known types, one ego per frame, ids fit to print
    into programs, unique per frame, frames contiguous); the same check streams over datasets
    (frames.dataset.FramesCheck), so both refuse with the same words."""
    import pandas as pd

    missing = [c for c in FRAMES_COLUMNS if c not in df.columns]
    if missing:
        raise FramesError(f"lacks column(s) {', '.join(missing)}")
    if df.empty:
        return
    check = ["frame_id", "entity_id", "type", "x", "y", "heading", "is_ego"]
    df = df[check].copy()
    for c in ("x", "y", "heading"):
        df[c] = pd.to_numeric(df[c], errors="coerce")  # text where a number belongs is a missing value
    try:
        table = pa.Table.from_pandas(df, preserve_index=False)
    except (pa.ArrowException, TypeError, ValueError) as exc:
        raise FramesError(f"a column has values of the wrong type ({str(exc)[:120]})") from None
    for name in ("frame_id", "entity_id", "type"):
        if not pa.types.is_string(table.schema.field(name).type) and table.column(name).null_count < len(table):
            table = table.set_column(table.schema.get_field_index(name), name, table.column(name).cast(pa.string()))
    check_table(table)


def iter_scenes(df: pd.DataFrame) -> Iterator[Scene]:
    """Every frame of a frames table as a Scene, in order of first appearance (the table made Arrow once)."""
    table = arrow_rows(df)
    rows = df.groupby("frame_id", sort=False).indices
    for fid in df["frame_id"].unique():
        yield frame_to_scene(table.take(rows[fid]))


def scene_to_rows(scene: Scene, source: str = "scene", scene_name: str | None = None, frame_index: int = 0) -> list[dict[str, Any]]:
    """A Scene back as frames rows (ids kept as they are; speeds and measurement sigmas as their optional columns,
    if any entity has one; lane facts and the road's map id as the road columns; the scene's world pose as the ego
    row's map_x, map_y, map_heading; its time as every row's timestamp_us)."""
    optional = [c for c in OPTIONAL_COLUMNS if any(getattr(e, c) is not None for e in scene.entities)]
    world = scene.world
    map_id = scene.road.map_id if scene.road is not None else world.map_id if world is not None else None
    rows = []
    for e in scene.entities:
        rows.append(
            {
                "frame_id": scene.frame_id, "source": source, "scene": scene_name or scene.frame_id.split("/")[0],
                "frame_index": frame_index,
                "timestamp_us": world.timestamp_us if world is not None else None, "entity_id": e.id, "track_id": e.id,
                "type": e.type, "category": e.type, "x": e.x, "y": e.y, "heading": e.heading,
                "length": e.length, "width": e.width, "is_ego": e.is_ego,
                **{c: getattr(e, c) for c in optional},
                **({c: list(e.lanes) if c == "lanes" else getattr(e, c) for c in LANE_FACT_COLUMNS}
                   if e.lanes is not None else {}),
                **({"map_id": map_id} if map_id is not None else {}),
                **({"map_x": world.x, "map_y": world.y, "map_heading": world.heading}
                   if e.is_ego and world is not None else {}),
            }
        )
    return rows


__all__ = [
    "EXTRACTED_SCHEMA",
    "FRAMES_COLUMNS",
    "FRAMES_SCHEMA",
    "ROAD_COLUMNS",
    "FramesError",
    "frame_rows",
    "frame_to_scene",
    "iter_scenes",
    "make_scene",
    "read_frames",
    "scene_to_rows",
    "to_table",
    "validate_frames",
    "write_frames",
]
