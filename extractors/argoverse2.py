"""Argoverse 2 sensor-log annotations (annotations.feather) as frames.

Input: a log directory, or a directory of log directories (each with annotations.feather, or the
annotations_with_ego.feather of the scenario-mining release). Boxes are already in the ego-vehicle frame
(x forward, y left, yaw CCW from +x), so our (x, y) = (-y_av, x_av) and heading = yaw_av; no pose is needed
(city_SE3_egovehicle.feather, where present, holds the ego's city pose, which ego-centric frames do not use).
One frame per annotated timestamp (10 Hz), frame_id `<log id>/<index>`; the EGO_VEHICLE row, where present,
gives the ego's box. Speeds need ground positions: with city_SE3_egovehicle.feather beside the annotations, each
box is placed in the city frame by the ego pose of its timestamp and each track (and the ego's pose track) is
differenced over neighbours at most 0.5 s apart (extractors.speed); without it speeds are null. The same poses
place the boxes on the log's map (map/log_map_archive_*.json, read below) for their lane facts.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from extractors.base import (
    ExtractError,
    ExtractOptions,
    ExtractTally,
    FrameBuilder,
    MapSink,
    RecordedObject,
    Source,
    gc_paused,
    prefetch_facts,
    quaternion_yaw,
    require_path,
    vehicle_to_ego,
)
from extractors.categories import Taxonomy
from extractors.sniff import Look
from extractors.speed import speeds_by_track, track_speeds
from storage.regular_files import open_regular
from synth.lane_facts import RoadIndex
from synth.roadmap import (
    CROSSWALK,
    DRIVABLE_AREA,
    LANE,
    FloatPairs,
    MapError,
    MapFeature,
    RoadMap,
    links_within,
    open_ring,
    points,
)

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


@dataclass(frozen=True)
class CityPlaces:
    """Where the boxes and the ego are in the city frame (the frame of the log's map), by the ego pose recorded at
    each timestamp; NaN where no pose has that timestamp."""

    x: np.ndarray  # every annotation row: the box centre (ground plane)
    y: np.ndarray
    yaw: np.ndarray  # radians CCW from +x
    ego_x: np.ndarray  # every frame stamp: the ego pose
    ego_y: np.ndarray
    ego_yaw: np.ndarray

    @classmethod
    def of(cls, cols: dict[str, np.ndarray], poses: dict[str, np.ndarray] | None, stamps: np.ndarray) -> CityPlaces:
        if poses is None:
            rows, frames = np.full(len(cols["timestamp_ns"]), np.nan), np.full(len(stamps), np.nan)
            return cls(rows, rows, rows, frames, frames, frames)
        order = np.argsort(poses["timestamp_ns"], kind="stable")
        pt = poses["timestamp_ns"][order]

        def pose_at(t: np.ndarray) -> tuple[np.ndarray, ...]:
            """(x, y, yaw) of the ego pose recorded at exactly these timestamps, NaN where there is none."""
            i = np.clip(np.searchsorted(pt, t), 0, len(pt) - 1)
            found = pt[i] == t
            j = order[i]
            yaw = quaternion_yaw(poses["qw"][j], poses["qx"][j], poses["qy"][j], poses["qz"][j])
            return tuple(np.where(found, v, np.nan) for v in (poses["tx_m"][j], poses["ty_m"][j], yaw))

        ex, ey, eyaw = pose_at(cols["timestamp_ns"])
        c, s = np.cos(eyaw), np.sin(eyaw)
        box_yaw = quaternion_yaw(cols["qw"], cols["qx"], cols["qy"], cols["qz"])
        return cls(ex + c * cols["tx_m"] - s * cols["ty_m"], ey + s * cols["tx_m"] + c * cols["ty_m"],
                   eyaw + box_yaw, *pose_at(stamps))


def ground_speeds(cols: dict[str, np.ndarray], places: CityPlaces, stamps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(speed of every annotation row, speed of the ego at every frame stamp), NaN where unknown."""
    # Seconds from the log's first stamp: nanoseconds since 1970 as a float would blur 0.1 s steps by 1e-6.
    t0 = int(stamps.min()) if len(stamps) else 0
    t = (cols["timestamp_ns"] - t0) * 1e-9
    found = np.isfinite(places.x)
    rows = np.where(found, speeds_by_track(cols["track_uuid"], np.where(found, t, np.nan), places.x, places.y),
                    np.nan)
    found = np.isfinite(places.ego_x)
    frames = np.where(found, track_speeds(np.where(found, (stamps - t0) * 1e-9, np.nan), places.ego_x,
                                          places.ego_y), np.nan)
    return rows, frames


def extract(input_path: str, options: ExtractOptions, tally: ExtractTally | None = None,
            maps: MapSink | None = None) -> Iterator[list[dict[str, Any]]]:
    """Every log's frames; with `maps`, a log's map (`read_map`; map id = the log id) goes to it
    before the log's frames, which carry their lane facts where the ego poses place the boxes in the city."""
    builder = FrameBuilder("argoverse2", TAXONOMY, options, tally)
    for f in annotation_files(require_path(input_path, "Argoverse 2 input")):
        road = None
        if maps is not None and (archive := map_file(f.parent)) is not None:
            try:
                with gc_paused():
                    road = RoadIndex(read_map(archive, f.parent.name))
            except MapError as exc:
                raise MapError(f"{archive}: {exc}") from None
            maps(road.road)
        yield from log_frames(f, read_annotations(f), builder, read_poses(f), road)


def log_frames(path: Path, cols: dict[str, np.ndarray], builder: FrameBuilder,
               poses: dict[str, np.ndarray] | None = None, road: RoadIndex | None = None
               ) -> Iterator[list[dict[str, Any]]]:
    log_id = path.parent.name
    x, y, heading = vehicle_to_ego(cols["tx_m"], cols["ty_m"], quaternion_yaw(cols["qw"], cols["qx"], cols["qy"],
                                                                                cols["qz"]))
    ts = cols["timestamp_ns"]
    order = np.argsort(ts, kind="stable")
    stamps, starts = np.unique(ts[order], return_index=True)
    bounds = list(starts) + [len(order)]
    places = CityPlaces.of(cols, poses, stamps)
    speed, ego_speed = ground_speeds(cols, places, stamps)
    if road is not None:  # every place a frame below will ask for: the boxes' within the radius (and a hair
        # beyond: FrameBuilder decides it again) and the ego's, where placed
        reach = builder.options.radius * (1 + 1e-9) + 1e-9
        with np.errstate(invalid="ignore"):
            boxes = np.isfinite(places.x) & (np.hypot(x, y) <= reach)
        egos = np.isfinite(places.ego_x)
        prefetch_facts(road, zip([*places.x[boxes].tolist(), *places.ego_x[egos].tolist()],
                                 [*places.y[boxes].tolist(), *places.ego_y[egos].tolist()],
                                 [*places.yaw[boxes].tolist(), *places.ego_yaw[egos].tolist()]))
    for index, stamp in enumerate(stamps):
        if index % builder.options.every:
            continue
        rows = order[bounds[index]:bounds[index + 1]]
        ego_world = _world(places.ego_x[index], places.ego_y[index], places.ego_yaw[index])
        ego = RecordedObject("ego", EGO_CATEGORY, 0.0, 0.0, 0.0, speed=ego_speed[index], world=ego_world)
        boxes = []
        for i in rows:
            cat = str(cols["category"][i])
            if cat == EGO_CATEGORY:
                ego = RecordedObject(str(cols["track_uuid"][i]), cat, 0.0, 0.0, 0.0, cols["length_m"][i],
                                     cols["width_m"][i], speed=ego_speed[index], world=ego_world)
                continue
            boxes.append(RecordedObject(str(cols["track_uuid"][i]), cat, float(x[i]), float(y[i]), float(heading[i]),
                                        cols["length_m"][i], cols["width_m"][i], speed=speed[i],
                                        world=_world(places.x[i], places.y[i], places.yaw[i])))
        yield builder.frame(log_id, index, int(stamp) // 1000, ego, boxes, road=road)


def _world(x: float, y: float, yaw: float) -> tuple[float, float, float] | None:
    return (float(x), float(y), float(yaw)) if np.isfinite(x) else None


# ------------------------------------------------------------------------------------------------- the map
# The vector map of an Argoverse 2 log (`map/log_map_archive_*.json` in the log directory) as a RoadMap.
#
# Lane segments are lanes: polygon = the right boundary then the left boundary reversed (as av2's
# LaneSegment.polygon_boundary), centre line = the midpoints of the two boundaries after resampling both to the
# larger of their point counts, evenly by length (boundaries run in the direction of travel); `lane_type`
# (VEHICLE / BIKE / BUS) is the source type, `is_intersection` kept, successors / predecessors /
# left_neighbor_id / right_neighbor_id the lane graph. Pedestrian crossings are crosswalks (polygon edge1[0],
# edge1[1], edge2[1], edge2[0], as av2's PedestrianCrossing.polygon); drivable areas keep their area_boundary.
# A log map is a crop of its city's map: lane-graph links to lanes outside the crop are dropped. The map's frame
# is the city frame of the log's ego poses (city_SE3_egovehicle.feather).

MAP_GLOB = "log_map_archive_*.json"
MAX_MAP_BYTES = 1 << 30  # a log's map archive is a few hundred KB


def map_file(log_dir: Path) -> Path | None:
    """The log's map archive (map/log_map_archive_*.json; the forecasting release puts it beside the scenario)."""
    for where in (log_dir / "map", log_dir):
        found = sorted(where.glob(MAP_GLOB)) if where.is_dir() else []
        if len(found) > 1:
            raise MapError(f"{where} holds {len(found)} map archives ({MAP_GLOB}); a log has one")
        if found:
            return found[0]
    return None


def read_map(path: Path, map_id: str) -> RoadMap:
    try:
        with open_regular(path, MAX_MAP_BYTES) as fh:  # a FIFO or a device is refused, never read forever
            data = json.loads(fh.read().decode("utf-8"), parse_constant=_no_constant)
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise MapError(f"{path} is not a readable Argoverse 2 map archive ({str(exc)[:100]})") from None
    except ValueError as exc:  # NaN / Infinity
        raise MapError(f"{path}: {exc}") from None
    if not isinstance(data, dict) or not isinstance(data.get("lane_segments"), dict):
        raise MapError(f"{path} is not an Argoverse 2 map archive (no lane_segments)")
    try:
        features = [_lane(map_id, v) for v in data["lane_segments"].values()]
        features += [_crossing(map_id, v) for v in (data.get("pedestrian_crossings") or {}).values()]
        features += [_area(map_id, v) for v in (data.get("drivable_areas") or {}).values()]
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        if isinstance(exc, MapError):
            raise
        raise MapError(f"{path}: a map element lacks a field or has the wrong type ({type(exc).__name__}: "
                       f"{str(exc)[:80]})") from None
    return RoadMap.of(map_id, links_within(features, neighbours=True))


def _no_constant(name: str) -> Any:
    raise ValueError(f"the map holds {name}, which is not a number")


def _xy(pts: list[dict]) -> np.ndarray:
    return np.array([[float(p["x"]), float(p["y"])] for p in pts], dtype=float).reshape(-1, 2)


def _resample(line: np.ndarray, n: int) -> np.ndarray:
    """n points evenly spaced by length along a polyline (its first and last point kept)."""
    d = np.diff(line, axis=0)
    s = np.empty(len(line))
    s[0] = 0.0
    np.cumsum(np.hypot(d[:, 0], d[:, 1]), out=s[1:])
    total = s[-1]
    if total == 0:
        return np.repeat(line[:1], n, axis=0)
    # np.linspace(0, total, n) without its generality (a map has hundreds of boundaries): the same arithmetic
    step = total / (n - 1)
    if step == 0:  # a subnormal total: linspace's own special case
        t = np.linspace(0.0, total, n)
    else:
        t = np.arange(n, dtype=float) * step
        t[-1] = total
    return np.stack([np.interp(t, s, line[:, 0]), np.interp(t, s, line[:, 1])], axis=1)


def _id(v: Any) -> str:
    return str(int(v))


def _pairs(pts: list[dict]) -> list[tuple[float, float]]:
    return [(float(p["x"]), float(p["y"])) for p in pts]


def _lane(map_id: str, v: dict) -> MapFeature:
    left_pts, right_pts = _pairs(v["left_lane_boundary"]), _pairs(v["right_lane_boundary"])
    fid = _id(v["id"])
    if len(left_pts) < 2 or len(right_pts) < 2:
        raise MapError(f"map {map_id!r}: lane {fid!r} has a boundary of fewer than two points")
    left, right = np.array(left_pts, dtype=float), np.array(right_pts, dtype=float)
    n = max(len(left), len(right))
    centre = (_resample(left, n) + _resample(right, n)) / 2
    ring = FloatPairs(right_pts + left_pts[::-1])  # the floats themselves: no round trip through numpy
    return MapFeature(
        map_id, fid, LANE, polygon=open_ring(ring), line=FloatPairs(map(tuple, centre.tolist())),
        source_type=str(v.get("lane_type", "")),
        left=None if v.get("left_neighbor_id") is None else _id(v["left_neighbor_id"]),
        right=None if v.get("right_neighbor_id") is None else _id(v["right_neighbor_id"]),
        successors=tuple(_id(s) for s in v.get("successors") or ()),
        predecessors=tuple(_id(s) for s in v.get("predecessors") or ()),
        is_intersection=bool(v.get("is_intersection", False)))


def _crossing(map_id: str, v: dict) -> MapFeature:
    e1, e2 = _xy(v["edge1"]), _xy(v["edge2"])
    if len(e1) != 2 or len(e2) != 2:
        raise MapError(f"map {map_id!r}: crosswalk {_id(v['id'])!r} has edges that are not two points each")
    ring = np.array([e1[0], e1[1], e2[1], e2[0]])
    return MapFeature(map_id, _id(v["id"]), CROSSWALK, polygon=open_ring(points(ring[:, 0], ring[:, 1])),
                      source_type="PEDESTRIAN_CROSSING")


def _area(map_id: str, v: dict) -> MapFeature:
    ring = _xy(v["area_boundary"])
    return MapFeature(map_id, _id(v["id"]), DRIVABLE_AREA, polygon=open_ring(points(ring[:, 0], ring[:, 1])),
                      source_type="DRIVABLE_AREA")


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
