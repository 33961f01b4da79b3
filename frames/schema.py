"""The one frames schema every extractor writes and the pipeline reads (docs/formats.md, "Frames Parquet"), and
the error that names a file or table not of it. Here alone so that the readers of frames (frames.rows,
frames.dataset) can share it without importing each other."""

from __future__ import annotations

import pyarrow as pa

from synth.errors import InputError

FRAMES_SCHEMA = pa.schema(
    [
        ("frame_id", pa.string()),
        ("source", pa.string()),
        ("scene", pa.string()),
        ("frame_index", pa.int32()),
        ("timestamp_us", pa.int64()),
        ("entity_id", pa.string()),
        ("track_id", pa.string()),
        ("type", pa.string()),
        ("category", pa.string()),
        ("x", pa.float64()),
        ("y", pa.float64()),
        ("heading", pa.float64()),
        ("length", pa.float32()),
        ("width", pa.float32()),
        ("is_ego", pa.bool_()),
    ]
)
FRAMES_COLUMNS = tuple(FRAMES_SCHEMA.names)
# Optional per-entity columns, null where unknown: speed (m/s, the magnitude of the ground velocity; motion needs
# it) and measurement uncertainty (robust synthesis). Readers accept files without them.
OPTIONAL_COLUMNS = {"speed": pa.float64(), "pos_sigma": pa.float64(), "heading_sigma": pa.float64(),
                    "speed_sigma": pa.float64()}
# The folder of a frames dataset that holds its maps (frames.maps). Its leading "_" makes every reader of the
# dataset skip it (ours, pandas / pyarrow.dataset, Spark), so the frames still read as one table.
MAPS_DIR = "_maps"
# Where each entity is on its scenario's map (docs/formats.md, "Lane facts"): the map the frame names (a map_id
# of the maps written beside the frames) and the entity's lane facts (synth.road.lane_facts); null without a map.
# map_x, map_y, map_heading: the entity's place in its map's frame (metres; degrees CCW from +x), as the source
# gives it: where the facts were decided, and how the map is brought into a frame's ego frame (r2s scene).
ROAD_COLUMNS = {"map_id": pa.string(), "map_x": pa.float64(), "map_y": pa.float64(), "map_heading": pa.float64(),
                "lanes": pa.list_(pa.string()), "lane": pa.string(), "in_intersection": pa.bool_(),
                "on_crosswalk": pa.bool_(), "off_road": pa.bool_()}
# The lane facts among them, which a scene's entities carry (synth.scene.Entity, scene JSON keys of these names).
LANE_FACT_COLUMNS = ("lanes", "lane", "in_intersection", "on_crosswalk", "off_road")
# What extractors write: every column of the schema, each entity's speed (null where the source cannot say) and
# the road columns.
EXTRACTED_SCHEMA = pa.schema(list(FRAMES_SCHEMA) + [("speed", OPTIONAL_COLUMNS["speed"])]
                             + list(ROAD_COLUMNS.items()))


class FramesError(InputError, ValueError):
    """A frames file or table that is not what the schema says. One line, fit for a user."""
