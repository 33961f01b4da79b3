"""Where one frame is, read once from its ego row: the map it names and its world pose (scene JSON's `world`).

Both readers of a frame take it from here: the Scene (frames.rows.frame_to_scene: `world`) and its road
(frames.maps.FrameRoads: the map's features moved into the frame's ego frame by that pose), so a frame's pose
is parsed once and a value is missing the one way: None or NaN (how pandas holds a null float), never a text or
an object compared with itself. The world is not validated here: scene JSON's validators are the one gate
(synth.world.world_from_dict, through synth.scene.scene_from_dict), and a pose they refuse refuses the frame.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import pandas as pd

POSE_COLUMNS = ("map_x", "map_y", "map_heading")
NAME_COLUMNS = ("source", "scene", "map_id")


def given(v: Any) -> float | None:
    """A number of a frames row, or None where it is missing (None, or what pandas holds a null as: NaN, pd.NA);
    anything else (negative, infinite) is for the scene's validators to refuse."""
    import pandas as pd  # loaded already: rows come as a DataFrame

    return None if v is None or pd.isna(v) else float(v)


@dataclass(frozen=True)
class FramePlace:
    """The map a frame's ego row names (None: none, or no map_id column) and its world (scene JSON's `world`:
    x, y, heading from map_x, map_y, map_heading, with the row's source, scene, frame index, timestamp and map; None where
    the ego row has no world pose)."""

    map_id: str | None
    world: dict[str, Any] | None

    @classmethod
    def of(cls, rows: pd.DataFrame) -> FramePlace:
        """The place of one frame's rows (a DataFrame with one ego row, as the frames check ensures)."""
        ego = rows[rows["is_ego"].astype(bool)] if "map_x" in rows.columns or "map_id" in rows.columns else ()
        if not len(ego):
            return cls(None, None)
        r = ego.iloc[0]
        raw_map = r.get("map_id")
        map_id = raw_map if isinstance(raw_map, str) else None
        pose = [given(r.get(c)) for c in POSE_COLUMNS]
        if None in pose:
            return cls(map_id, None)
        index, stamp = given(r.get("frame_index")), given(r.get("timestamp_us"))
        names = {c: v for c in NAME_COLUMNS if isinstance(v := r.get(c), str) and v}
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
