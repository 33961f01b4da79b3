"""A small Argoverse 2 sensor log written by the tests in av2's own layout (so that CI without ../shared covers the
map reader): `<log id>/annotations.feather` and `city_SE3_egovehicle.feather` with av2's columns, and
`map/log_map_archive_<log id>____PIT_city_1.json` with av2's keys (lane_segments, pedestrian_crossings,
drivable_areas; points as {"x", "y", "z"}, ids integers, as av2's ArgoverseStaticMap.from_json reads them).

The road: three lane segments along +x (10 then 11 ahead, 12 to the left of 10, neighbours both ways), a
pedestrian crossing over them at x 60-64 and a drivable area around all. The ego drives along y = 0 at 10 m/s
for 10 frames (0.1 s apart), a car 8 m ahead of it and a pedestrian 3 m to its left."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.ipc as ipc

LOG_ID = "00000000-0000-0000-0000-00000000a0a0"
FRAMES = 10
T0_NS = 315_966_265_659_927_216  # a stamp of av2's epoch, so stamps are realistic
HALF = 1.75  # half a lane's width (m)


def _pts(*xy: tuple[float, float]) -> list[dict]:
    return [{"x": float(x), "y": float(y), "z": 12.5} for x, y in xy]


def _lane(lane_id: int, x0: float, x1: float, y: float, **links: Any) -> dict:
    """A lane segment from x0 to x1 centred on y (boundaries of three points in the direction of travel)."""
    xm = (x0 + x1) / 2
    return {"id": lane_id, "is_intersection": False, "lane_type": "VEHICLE",
            "left_lane_boundary": _pts((x0, y + HALF), (xm, y + HALF), (x1, y + HALF)), "left_lane_mark_type": "NONE",
            "right_lane_boundary": _pts((x0, y - HALF), (xm, y - HALF), (x1, y - HALF)),
            "right_lane_mark_type": "SOLID_WHITE", "successors": [], "predecessors": [], "right_neighbor_id": None,
            "left_neighbor_id": None, **links}


def log_map() -> dict:
    """The log's map archive as av2 writes it."""
    return {
        "pedestrian_crossings": {"20": {"edge1": _pts((60, -3), (60, 7)), "edge2": _pts((64, -3), (64, 7)),
                                        "id": 20}},
        "lane_segments": {
            "10": _lane(10, 0, 50, 0, successors=[11], left_neighbor_id=12),
            "11": _lane(11, 50, 100, 0, predecessors=[10]),
            "12": _lane(12, 0, 50, 2 * HALF, right_neighbor_id=10),
        },
        "drivable_areas": {"30": {"area_boundary": _pts((-10, -6), (110, -6), (110, 10), (-10, 10)), "id": 30}},
    }


def _yaw_quat(yaw: float) -> tuple[float, float, float, float]:
    return math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)


def write_log(root: Path, archive: dict | str | bytes | None = "default") -> Path:
    """The log in `root/<LOG_ID>`; its map archive is `archive` (a dict as JSON, text or bytes as they are; default
    log_map(); None: no map). Returns the log directory."""
    log = root / LOG_ID
    (log / "map").mkdir(parents=True)
    stamps = [T0_NS + i * 100_000_000 for i in range(FRAMES)]
    qw, qx, qy, qz = _yaw_quat(0.0)
    _feather(pa.table({
        "timestamp_ns": stamps, "qw": [qw] * FRAMES, "qx": [qx] * FRAMES, "qy": [qy] * FRAMES, "qz": [qz] * FRAMES,
        "tx_m": [1.0 + i for i in range(FRAMES)], "ty_m": [0.0] * FRAMES, "tz_m": [12.5] * FRAMES}),
        log / "city_SE3_egovehicle.feather")
    rows = [(t, uuid, cat, length, width, x, y) for t in stamps for uuid, cat, length, width, x, y in (
        ("car-1", "REGULAR_VEHICLE", 4.5, 1.9, 8.0, 0.0), ("ped-1", "PEDESTRIAN", 0.6, 0.6, 0.0, 3.0))]
    n = len(rows)
    _feather(pa.table({
        "timestamp_ns": [r[0] for r in rows], "track_uuid": [r[1] for r in rows], "category": [r[2] for r in rows],
        "length_m": [r[3] for r in rows], "width_m": [r[4] for r in rows], "height_m": [1.6] * n,
        "qw": [qw] * n, "qx": [qx] * n, "qy": [qy] * n, "qz": [qz] * n,
        "tx_m": [r[5] for r in rows], "ty_m": [r[6] for r in rows], "tz_m": [0.8] * n,
        "num_interior_pts": [50] * n}), log / "annotations.feather")
    archive = log_map() if archive == "default" else archive
    path = log / "map" / f"log_map_archive_{LOG_ID}____PIT_city_1.json"
    if isinstance(archive, dict):
        path.write_text(json.dumps(archive))
    elif isinstance(archive, str):
        path.write_text(archive)
    elif isinstance(archive, bytes):
        path.write_bytes(archive)
    return log


def _feather(table: pa.Table, path: Path) -> None:
    """Feather v2 (the Arrow IPC file format), as av2 writes its tables."""
    with ipc.new_file(str(path), table.schema) as w:
        w.write_table(table)


def archive_of(log: Path) -> Path:
    return next((log / "map").glob("log_map_archive_*.json"))
