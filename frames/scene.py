"""One frame's rows as a Scene: the one conversion every reader of frames uses (r2s run's frames and windows,
r2s scene, the Python API, r2s query's scenes), from an Arrow table or a DataFrame alike.

The rows are read column by column into Python values once (`FrameColumns`: Arrow's nulls, and the NaN or pd.NA
that pandas holds a null as, all None), then each entity goes through scene JSON's validators
(synth.scene.scene_from_dict): a frame is refused with the words scene JSON's are. The ego row's place is read
once (`EgoPlace`: the map it names and scene JSON's `world`) and given to both the Scene and its road
(frames.maps.FrameRoads.road). The box rule of frames (docs/formats.md, Frames Parquet) is `box`: a length or
width that is not a positive finite number is no box, where scene JSON refuses one.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

import pyarrow as pa

from frames.schema import LANE_FACT_COLUMNS, OPTIONAL_COLUMNS, FramesError
from synth.scene import Scene, SceneError, scene_from_dict

if TYPE_CHECKING:  # pandas is imported by whoever has rows as a DataFrame: r2s run reads Arrow
    import pandas as pd

    from synth.road.roadmap import RoadMap

POSE_COLUMNS = ("map_x", "map_y", "map_heading")
NAME_COLUMNS = ("source", "scene", "map_id")


def given(v: Any) -> float | None:
    """A number of a frames row, or None where it is missing (None, or NaN); anything else (negative, infinite)
    is for the scene's validators to refuse."""
    if v is None:
        return None
    f = float(v)
    return None if math.isnan(f) else f


def box(v: Any) -> float | None:
    """A length or width of a frames row: a positive finite number, else None (no box: the type's typical size)."""
    if v is None:
        return None
    f = float(v)
    return f if math.isfinite(f) and f > 0 else None


def arrow_rows(rows: pa.Table | pd.DataFrame) -> pa.Table:
    """Rows as an Arrow table: NaN and pd.NA become nulls, as Arrow holds them; a column pandas holds in a way no
    Arrow column can (mixed types) is a FramesError."""
    if isinstance(rows, pa.Table):
        return rows
    try:
        return pa.Table.from_pandas(rows, preserve_index=False)
    except (pa.ArrowException, TypeError, ValueError) as exc:
        raise FramesError(f"a column has values of the wrong type ({str(exc)[:120]})") from None


@dataclass(frozen=True)
class FrameColumns:
    """One frame's rows, a list of Python values per column (a null is None), read once."""

    columns: dict[str, list]

    @classmethod
    def of(cls, rows: FrameColumns | pa.Table | pd.DataFrame) -> FrameColumns:
        if isinstance(rows, FrameColumns):
            return rows
        table = arrow_rows(rows)
        return cls({c: table.column(c).to_pylist() for c in table.column_names})

    def __len__(self) -> int:
        return len(self.columns["frame_id"])

    def get(self, name: str) -> list | None:
        return self.columns.get(name)

    def ego_index(self) -> int | None:
        return next((i for i, e in enumerate(self.columns["is_ego"]) if e), None)


@dataclass(frozen=True)
class EgoPlace:
    """Where a frame is, from its ego row: the map it names (None: none, or no map_id column) and its world
    (scene JSON's `world`: x, y, heading from map_x, map_y, map_heading, with the row's source, scene, frame index,
    timestamp and map; None where the ego row has no world pose). Not validated here: scene JSON's validators are the one
    gate (synth.world.world_from_dict, through scene_from_dict), and a pose they refuse refuses the frame."""

    map_id: str | None
    world: dict[str, Any] | None

    @classmethod
    def of(cls, rows: FrameColumns) -> EgoPlace:
        i = rows.ego_index()
        if i is None:
            return cls(None, None)

        def at(column: str) -> Any:
            values = rows.get(column)
            return None if values is None else values[i]

        map_id = at("map_id") if isinstance(at("map_id"), str) else None
        pose = [given(at(c)) for c in POSE_COLUMNS]
        if None in pose:
            return cls(map_id, None)
        index, stamp = given(at("frame_index")), given(at("timestamp_us"))
        names = {c: v for c in NAME_COLUMNS if isinstance(v := at(c), str) and v}
        return cls(map_id, {"x": pose[0], "y": pose[1], "heading": pose[2], **names,
                            **({"frame_index": int(index)} if index is not None else {}),
                            **({"timestamp_us": int(stamp)} if stamp is not None else {})})

    @property
    def road_pose(self) -> tuple[float, float, float] | None:
        """(x, y, heading degrees CCW from +x) in the map's frame, where the frame names a map and has a pose:
        what its road is placed by (synth.road.roadmap.in_ego_frame); else None."""
        if self.map_id is None or self.world is None:
            return None
        return self.world["x"], self.world["y"], self.world["heading"]


def _entities(rows: FrameColumns) -> Iterator[dict[str, Any]]:
    """Each row as a scene JSON entity: a missing value (None) means "not given"."""
    cols = rows.columns
    optional = [(k, cols[k]) for k in OPTIONAL_COLUMNS if k in cols]
    lanes = cols.get("lanes")
    facts = [(k, cols[k]) for k in LANE_FACT_COLUMNS[1:] if k in cols]
    for i, (eid, etype, x, y, heading) in enumerate(zip(cols["entity_id"], cols["type"], cols["x"], cols["y"],
                                                        cols["heading"])):
        d = {"id": eid, "type": etype, **{k: v if v is None else float(v) for k, v in (("x", x), ("y", y),
                                                                                      ("heading", heading))}}
        for key in ("length", "width"):
            if (v := box(cols[key][i])) is not None:
                d[key] = v
        for key, values in optional:  # speed and measurement bounds
            if (v := given(values[i])) is not None:
                d[key] = v
        if lanes is not None and lanes[i] is not None:
            d["lanes"] = [str(x) for x in lanes[i]]
            for key, values in facts:
                if (v := values[i]) is not None:
                    d[key] = v if key == "lane" else bool(v)
        yield d


def frame_to_scene(rows: FrameColumns | pa.Table | pd.DataFrame, road: RoadMap | None = None,
                   place: EgoPlace | None = None) -> Scene:
    """One frame's rows as a validated Scene (ids and types are re-checked: frames may come from anyone), with
    each entity's lane facts where the rows have them, `road` (in the frame's ego frame) as its road, and the
    world of `place` (the ego row's, read once by whoever placed the road; EgoPlace.of the rows if not given)."""
    rows = FrameColumns.of(rows)
    fid = str(rows.columns["frame_id"][0])
    try:
        doc: dict[str, Any] = {"frame_id": fid, "entities": list(_entities(rows))}
        world = (place if place is not None else EgoPlace.of(rows)).world
    except (TypeError, ValueError) as exc:  # text where a number belongs (rows in memory: the Python API)
        raise FramesError(f"frame {fid!r}: a value is not a number ({str(exc)[:120]})") from None
    if world is not None:
        doc["world"] = world
    try:
        scene = scene_from_dict(doc)
    except SceneError as exc:
        raise FramesError(f"frame {fid!r}: {exc}") from None
    return scene if road is None else replace(scene, road=road)
