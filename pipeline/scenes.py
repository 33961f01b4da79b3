"""One frame as a Scene (`r2s scene`, and its Python API `from pipeline import scene`): from a frames file or dataset
by its id, with its road, or from frames rows already in memory (a pandas DataFrame, a pyarrow Table or a list of
row dicts, as `rows.to_dict("records")` gives them), validated as a file is.

Only the frame's own rows are read from a file (row-group statistics skip the rest of a large dataset) and
checked. A frame that names a map gets its road: the map features within `radius` of ego, from the maps beside
the frames (frames.maps), brought into the frame's ego frame by the ego's place in the map (its map_x, map_y,
map_heading), and each entity its lane facts."""

from __future__ import annotations

import os
import sys

import pandas as pd
import pyarrow as pa

from frames.dataset import FramesDataset
from frames.maps import FrameRoads, maps_dir
from frames.rows import frame_to_scene, to_table, validate_frames
from frames.scene import EgoPlace, FrameColumns
from pipeline.errors import UserError
from synth.scene import Scene

# Beyond this many frames, "did you mean" only looks at ids of the same scene (the part before the last '/').
MAX_HINT_POOL = 200_000


def scene(frames, frame_id: str | None = None, *, radius: float = 50.0) -> Scene:
    """The Scene of one frame. `frames` is a frames file or dataset path (then `frame_id` names the frame and the
    maps beside the frames give its road), or frames rows (a DataFrame, a pyarrow Table or a list of row dicts
    in the frames layout, docs/formats.md): one frame's rows, or several frames' with `frame_id` picking one.
    Bad input raises an InputError (FramesError, UserError; one line)."""
    if not radius > 0:
        raise UserError(f"--radius must be positive, got {radius}")
    if isinstance(frames, (str, os.PathLike)):
        if frame_id is None:
            raise UserError(f"which frame of {frames}? give a frame id")
        return _from_file(str(frames), frame_id, radius)
    rows = _rows(frames)
    ids = rows["frame_id"].unique() if len(rows) else ()
    if frame_id is not None:
        rows = rows[rows["frame_id"] == frame_id]
        if rows.empty:
            raise UserError(f"the rows have no frame {frame_id!r} ({len(ids)} frames, e.g. {ids[0]!r})"
                            if len(ids) else "the rows are empty: no frame")
    elif len(ids) != 1:
        raise UserError("the rows are empty: no frame" if not len(ids) else
                        f"the rows hold {len(ids)} frames ({ids[0]!r}, {ids[1]!r}, ...): give the frame id")
    return frame_to_scene(rows.reset_index(drop=True))


def _rows(frames) -> pd.DataFrame:
    """Frames rows in memory as a validated DataFrame (to_table checks them as the frames check does)."""
    if isinstance(frames, pa.Table):
        frames = frames.to_pandas()
    elif isinstance(frames, (list, tuple)):
        if not all(isinstance(r, dict) for r in frames):
            raise UserError("frames rows must be dicts (rows.to_dict('records')), a DataFrame or a pyarrow Table")
        frames = to_table(list(frames)).to_pandas()
    elif not isinstance(frames, pd.DataFrame):
        raise UserError(f"frames must be a path, a DataFrame, a pyarrow Table or a list of row dicts, "
                        f"not {type(frames).__name__}")
    validate_frames(frames)
    return frames


def _from_file(frames: str, frame_id: str, radius: float) -> Scene:
    dataset = FramesDataset.open(frames)
    table = dataset.find(frame_id)
    if table is None:
        raise UserError(f"{frames} has no frame {frame_id!r}{_hint(dataset, frame_id)}")
    validate_frames(table.to_pandas())
    rows = FrameColumns.of(table)  # read once, and the ego row once, for the road and the world
    place = EgoPlace.of(rows)
    return frame_to_scene(rows, _road(frames, rows, radius, place), place)


def _road(frames: str, rows: FrameColumns, radius: float, place: EgoPlace):
    """The frame's road in its ego frame, or None when the frame names no map (its maps missing: a warning)."""
    road, missing = FrameRoads(maps_dir(frames), radius).road(rows, place)
    if missing is not None:
        sys.stderr.write(f"r2s scene: warning: the frame names map {missing!r}, which is not in {maps_dir(frames)}; "
                         "the scene has no road\n")
    return road


def _hint(dataset, frame_id: str) -> str:
    import difflib  # only a frame that is not there loads it

    scene_name = frame_id.rsplit("/", 1)[0]
    pool, count, example = [], 0, None
    for runs in dataset.runs():
        for fid in runs.ids:
            example = example or fid
            count += 1
            if count <= MAX_HINT_POOL or fid.rsplit("/", 1)[0] == scene_name:
                pool.append(fid)
    close = difflib.get_close_matches(frame_id, pool, n=3, cutoff=0.5)
    return f"; did you mean {', '.join(close)}?" if close else f" ({count} frames, e.g. {example})" if example else ""
