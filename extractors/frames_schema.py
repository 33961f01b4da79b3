"""The one frames schema every extractor writes and the pipeline reads (docs/formats.md, "Frames Parquet"), and
the error that names a file or table not of it. Here alone so that the readers of frames (extractors.frames,
extractors.frames_dataset) can share it without importing each other."""

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
# What extractors write: every column of the schema and each entity's speed (null where the source cannot say).
EXTRACTED_SCHEMA = pa.schema(list(FRAMES_SCHEMA) + [("speed", OPTIONAL_COLUMNS["speed"])])


class FramesError(InputError, ValueError):
    """A frames file or table that is not what the schema says. One line, fit for a user."""
