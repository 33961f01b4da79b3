"""Argoverse 2 sensor-log annotations (annotations.feather) as frames.

Input: a log directory, or a directory of log directories (each with annotations.feather, or the
annotations_with_ego.feather of the scenario-mining release). Boxes are already in the ego-vehicle frame
(x forward, y left, yaw CCW from +x), so our (x, y) = (-y_av, x_av) and heading = yaw_av; no pose is needed
(city_SE3_egovehicle.feather, where present, holds the ego's city pose, which ego-centric frames do not use).
One frame per annotated timestamp (10 Hz), frame_id `<log id>/<index>`; the EGO_VEHICLE row, where present,
gives the ego's box.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from extractors.base import (
    Box,
    ExtractError,
    ExtractOptions,
    ExtractTally,
    FrameBuilder,
    quaternion_yaw,
    require_path,
    vehicle_to_ego,
)

DESCRIPTION = "Argoverse 2 log directory (annotations.feather), or a directory of logs"
TAXONOMY = "argoverse2"
NAMES = ("annotations.feather", "annotations_with_ego.feather")
COLUMNS = ("timestamp_ns", "track_uuid", "category", "length_m", "width_m", "qw", "qx", "qy", "qz", "tx_m", "ty_m")
EGO_CATEGORY = "EGO_VEHICLE"


def annotation_files(path: Path) -> list[Path]:
    if path.is_file():
        return [path]
    found = sorted(p for p in path.rglob("*.feather") if p.name in NAMES)
    if not found:
        raise ExtractError(f"{path} holds no Argoverse 2 annotations ({' or '.join(NAMES)})")
    return found


def read_annotations(path: Path) -> dict[str, np.ndarray]:
    try:
        with pa.memory_map(str(path)) as source:
            table = pa.ipc.open_file(source).read_all()
    except (pa.ArrowException, OSError) as exc:
        raise ExtractError(f"{path} is not a readable Feather (Arrow IPC) file ({str(exc)[:100]})") from None
    missing = [c for c in COLUMNS if c not in table.column_names]
    if missing:
        raise ExtractError(f"{path} is not an Argoverse 2 annotations file: it lacks {', '.join(missing)}")
    try:
        cols = {c: table.column(c).to_numpy(zero_copy_only=False) for c in COLUMNS}
        for c in COLUMNS[3:]:
            cols[c] = cols[c].astype(float)
        cols["timestamp_ns"] = cols["timestamp_ns"].astype(np.int64)
    except (pa.ArrowException, ValueError, TypeError) as exc:
        raise ExtractError(f"{path}: a column has the wrong type ({str(exc)[:100]})") from None
    return cols


def extract(input_path: str, options: ExtractOptions, tally: ExtractTally | None = None) -> Iterator[list[dict[str, Any]]]:
    builder = FrameBuilder("argoverse2", TAXONOMY, options, tally)
    for f in annotation_files(require_path(input_path, "Argoverse 2 input")):
        yield from log_frames(f, read_annotations(f), builder)


def log_frames(path: Path, cols: dict[str, np.ndarray], builder: FrameBuilder) -> Iterator[list[dict[str, Any]]]:
    log_id = path.parent.name
    x, y, heading = vehicle_to_ego(cols["tx_m"], cols["ty_m"], quaternion_yaw(cols["qw"], cols["qx"], cols["qy"],
                                                                                cols["qz"]))
    ts = cols["timestamp_ns"]
    order = np.argsort(ts, kind="stable")
    stamps, starts = np.unique(ts[order], return_index=True)
    bounds = list(starts) + [len(order)]
    for index, stamp in enumerate(stamps):
        if index % builder.options.every:
            continue
        rows = order[bounds[index]:bounds[index + 1]]
        ego = Box("ego", EGO_CATEGORY, 0.0, 0.0, 0.0)
        boxes = []
        for i in rows:
            cat = str(cols["category"][i])
            if cat == EGO_CATEGORY:
                ego = Box(str(cols["track_uuid"][i]), cat, 0.0, 0.0, 0.0, cols["length_m"][i], cols["width_m"][i])
                continue
            boxes.append(Box(str(cols["track_uuid"][i]), cat, float(x[i]), float(y[i]), float(heading[i]),
                             cols["length_m"][i], cols["width_m"][i]))
        yield builder.frame(log_id, index, int(stamp) // 1000, ego, boxes)
