"""Argoverse 2 sensor-log annotations (annotations.feather) as frames.

Input: a log directory, or a directory of log directories (each with annotations.feather, or the
annotations_with_ego.feather of the scenario-mining release). Boxes are already in the ego-vehicle frame
(x forward, y left, yaw CCW from +x), so our (x, y) = (-y_av, x_av) and heading = yaw_av; no pose is needed
(city_SE3_egovehicle.feather, where present, holds the ego's city pose, which ego-centric frames do not use).
One frame per annotated timestamp (10 Hz), frame_id `<log id>/<index>`; the EGO_VEHICLE row, where present,
gives the ego's box. Speeds need ground positions: with city_SE3_egovehicle.feather beside the annotations, each
box is placed in the city frame by the ego pose of its timestamp and each track (and the ego's pose track) is
differenced over neighbours at most 0.5 s apart (extractors.speed); without it speeds are null.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from extractors.base import (
    ExtractError,
    ExtractOptions,
    ExtractTally,
    FrameBuilder,
    RecordedObject,
    Source,
    quaternion_yaw,
    require_path,
    vehicle_to_ego,
)
from extractors.categories import Taxonomy
from extractors.sniff import Look
from extractors.speed import speeds_by_track, track_speeds
from storage.regular_files import open_regular

DESCRIPTION = "Argoverse 2 log directory (annotations.feather), or a directory of logs"
# Argoverse 2 sensor-dataset annotation categories (30 classes).
TAXONOMY = Taxonomy("argoverse2", {
    "ANIMAL": "Animal",
    "ARTICULATED_BUS": "Bus",
    "BICYCLE": "Bicycle",
    "BICYCLIST": "Bicycle",
    "BOLLARD": "Barrier",
    "BOX_TRUCK": "Truck",
    "BUS": "Bus",
    "CONSTRUCTION_BARREL": "Barrier",
    "CONSTRUCTION_CONE": "TrafficCone",
    "DOG": "Animal",
    "EGO_VEHICLE": "Car",
    "LARGE_VEHICLE": "Truck",
    "MESSAGE_BOARD_TRAILER": "Trailer",
    "MOBILE_PEDESTRIAN_CROSSING_SIGN": "Object",
    "MOTORCYCLE": "Motorcycle",
    "MOTORCYCLIST": "Motorcycle",
    "OFFICIAL_SIGNALER": "Pedestrian",
    "PEDESTRIAN": "Pedestrian",
    "RAILED_VEHICLE": "Bus",
    "REGULAR_VEHICLE": "Car",
    "SCHOOL_BUS": "Bus",
    "SIGN": "Object",
    "STOP_SIGN": "Object",
    "STROLLER": "Pedestrian",
    "TRUCK": "Truck",
    "TRUCK_CAB": "Truck",
    "VEHICULAR_TRAILER": "Trailer",
    "WHEELCHAIR": "Pedestrian",
    "WHEELED_DEVICE": "PushableObject",
    "WHEELED_RIDER": "Bicycle",
})
NAMES = ("annotations.feather", "annotations_with_ego.feather")
COLUMNS = ("timestamp_ns", "track_uuid", "category", "length_m", "width_m", "qw", "qx", "qy", "qz", "tx_m", "ty_m")
EGO_CATEGORY = "EGO_VEHICLE"
POSES = "city_SE3_egovehicle.feather"
POSE_COLUMNS = ("timestamp_ns", "qw", "qx", "qy", "qz", "tx_m", "ty_m")
ARROW_MAGIC = b"ARROW1"  # Feather v2 is the Arrow IPC file format


def annotation_files(path: Path) -> list[Path]:
    if path.is_file():
        return [path]
    found = sorted(p for p in path.rglob("*.feather") if p.name in NAMES)
    if not found:
        raise ExtractError(f"{path} holds no Argoverse 2 annotations ({' or '.join(NAMES)})")
    return found


def _read_columns(path: Path, columns: tuple[str, ...], floats: tuple[str, ...], what: str) -> dict[str, np.ndarray]:
    try:
        with open_regular(path) as source:  # never a FIFO or a device
            table = pa.ipc.open_file(source).read_all()
    except (pa.ArrowException, OSError) as exc:
        raise ExtractError(f"{path} is not a readable Feather (Arrow IPC) file ({str(exc)[:100]})") from None
    missing = [c for c in columns if c not in table.column_names]
    if missing:
        raise ExtractError(f"{path} is not an Argoverse 2 {what} file: it lacks {', '.join(missing)}")
    try:
        cols = {c: table.column(c).to_numpy(zero_copy_only=False) for c in columns}
        for c in floats:
            cols[c] = cols[c].astype(float)
        cols["timestamp_ns"] = cols["timestamp_ns"].astype(np.int64)
    except (pa.ArrowException, ValueError, TypeError) as exc:
        raise ExtractError(f"{path}: a column has the wrong type ({str(exc)[:100]})") from None
    return cols


def read_annotations(path: Path) -> dict[str, np.ndarray]:
    return _read_columns(path, COLUMNS, COLUMNS[3:], "annotations")


def read_poses(path: Path) -> dict[str, np.ndarray] | None:
    """The ego's city poses beside an annotations file (city_SE3_egovehicle.feather), or None where there is none."""
    poses = path.parent / POSES
    return _read_columns(poses, POSE_COLUMNS, POSE_COLUMNS[1:], "ego pose") if poses.is_file() else None


def ground_speeds(cols: dict[str, np.ndarray], poses: dict[str, np.ndarray] | None,
                  stamps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(speed of every annotation row, speed of the ego at every frame stamp), NaN where unknown."""
    rows, frames = np.full(len(cols["timestamp_ns"]), np.nan), np.full(len(stamps), np.nan)
    if poses is None:
        return rows, frames
    order = np.argsort(poses["timestamp_ns"], kind="stable")
    pt = poses["timestamp_ns"][order]

    def pose_at(t: np.ndarray) -> tuple[np.ndarray, ...]:
        """(found, x, y, yaw) of the ego pose recorded at exactly these timestamps."""
        i = np.clip(np.searchsorted(pt, t), 0, len(pt) - 1)
        found = pt[i] == t
        j = order[i]
        yaw = quaternion_yaw(poses["qw"][j], poses["qx"][j], poses["qy"][j], poses["qz"][j])
        return found, poses["tx_m"][j], poses["ty_m"][j], yaw

    found, ex, ey, eyaw = pose_at(cols["timestamp_ns"])
    c, s = np.cos(eyaw), np.sin(eyaw)
    gx = ex + c * cols["tx_m"] - s * cols["ty_m"]  # the box centre in the city frame (ground plane)
    gy = ey + s * cols["tx_m"] + c * cols["ty_m"]
    # Seconds from the log's first stamp: nanoseconds since 1970 as a float would blur 0.1 s steps by 1e-6.
    t0 = int(stamps.min()) if len(stamps) else 0
    t = (cols["timestamp_ns"] - t0) * 1e-9
    rows = np.where(found, speeds_by_track(cols["track_uuid"], np.where(found, t, np.nan), gx, gy), np.nan)
    found, ex, ey, _ = pose_at(stamps)
    frames = np.where(found, track_speeds(np.where(found, (stamps - t0) * 1e-9, np.nan), ex, ey), np.nan)
    return rows, frames


def extract(input_path: str, options: ExtractOptions, tally: ExtractTally | None = None) -> Iterator[list[dict[str, Any]]]:
    builder = FrameBuilder("argoverse2", TAXONOMY, options, tally)
    for f in annotation_files(require_path(input_path, "Argoverse 2 input")):
        yield from log_frames(f, read_annotations(f), builder, read_poses(f))


def log_frames(path: Path, cols: dict[str, np.ndarray], builder: FrameBuilder,
               poses: dict[str, np.ndarray] | None = None) -> Iterator[list[dict[str, Any]]]:
    log_id = path.parent.name
    x, y, heading = vehicle_to_ego(cols["tx_m"], cols["ty_m"], quaternion_yaw(cols["qw"], cols["qx"], cols["qy"],
                                                                                cols["qz"]))
    ts = cols["timestamp_ns"]
    order = np.argsort(ts, kind="stable")
    stamps, starts = np.unique(ts[order], return_index=True)
    bounds = list(starts) + [len(order)]
    speed, ego_speed = ground_speeds(cols, poses, stamps)
    for index, stamp in enumerate(stamps):
        if index % builder.options.every:
            continue
        rows = order[bounds[index]:bounds[index + 1]]
        ego = RecordedObject("ego", EGO_CATEGORY, 0.0, 0.0, 0.0, speed=ego_speed[index])
        boxes = []
        for i in rows:
            cat = str(cols["category"][i])
            if cat == EGO_CATEGORY:
                ego = RecordedObject(str(cols["track_uuid"][i]), cat, 0.0, 0.0, 0.0, cols["length_m"][i],
                                     cols["width_m"][i], speed=ego_speed[index])
                continue
            boxes.append(RecordedObject(str(cols["track_uuid"][i]), cat, float(x[i]), float(y[i]), float(heading[i]),
                                        cols["length_m"][i], cols["width_m"][i], speed=speed[i]))
        yield builder.frame(log_id, index, int(stamp) // 1000, ego, boxes)


class Argoverse2(Source):
    name = "argoverse2"
    description = DESCRIPTION
    input_help = "log dir"
    taxonomy = TAXONOMY
    extract = staticmethod(extract)

    def unit_paths(self, path: Path) -> list[Path]:
        return annotation_files(path)

    def look_at_file(self, path: Path, head: bytes) -> Look | None:
        if path.name in NAMES and head.startswith(ARROW_MAGIC):
            return Look(self.name, f"Argoverse 2 annotations ({path.name})", str(path.parent))
        return None

    def look_at_entry(self, top: str, path: Path, is_dir: bool, depth: int) -> Look | None:
        if not is_dir and path.name in NAMES:
            return Look(self.name, f"Argoverse 2 logs ({path.name})", top)
        return None


SOURCE = Argoverse2()
