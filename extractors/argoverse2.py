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
import math
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from itertools import chain
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from extractors.base import (
    ExtractError,
    ExtractOptions,
    ExtractTally,
    FrameBuilder,
    Look,
    MapSink,
    RecordedObject,
    Source,
    prefetch_facts,
    quaternion_yaw,
    recorded_road,
    require_path,
    utf8_writable,
    vehicle_to_ego,
)
from extractors.categories import Taxonomy
from extractors.speed import speeds_by_track, track_speeds
from storage.regular_files import open_regular, read_regular
from synth.pose import SE2
from synth.road.lane_facts import RoadIndex
from synth.road.roadmap import (
    CROSSWALK,
    DRIVABLE_AREA,
    DROPPED_BROKEN,
    DROPPED_LINKS,
    LANE,
    FloatPairs,
    MapError,
    MapFeature,
    MapRepairs,
    RoadMap,
    links_within,
    open_ring,
    packed_subset,
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

        ego = SE2.body(*pose_at(cols["timestamp_ns"]))  # one pose per row: the vehicle's frame at its stamp
        box_yaw = quaternion_yaw(cols["qw"], cols["qx"], cols["qy"], cols["qz"])
        return cls(*ego.apply(cols["tx_m"], cols["ty_m"]), ego.heading_out(box_yaw), *pose_at(stamps))


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
        road = log_road(f.parent, options.strict_maps, tally) if maps is not None else None
        if road is not None:
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
        prefetch_facts(road, np.concatenate([places.x[boxes], places.ego_x[egos]]),
                       np.concatenate([places.y[boxes], places.ego_y[egos]]),
                       np.concatenate([places.yaw[boxes], places.ego_yaw[egos]]))
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
# A log's map archive is a few hundred KB; reading one costs some 11 MB of memory per MB (its JSON objects, the
# lanes' points as Python floats, their centre lines), so 256 MB keeps the largest near 3 GB.
MAX_MAP_BYTES = 256 << 20


def map_files(log_dir: Path) -> list[Path]:
    """The log's map archives (map/log_map_archive_*.json; the forecasting release puts it beside the scenario): a
    log has one; none where its release ships no map (the scenario-mining logs)."""
    for where in (log_dir / "map", log_dir):
        found = sorted(where.glob(MAP_GLOB)) if where.is_dir() else []
        if found:
            return found
    return []


def log_road(log_dir: Path, strict: bool, tally: ExtractTally | None) -> RoadIndex | None:
    """The log's map (map id = the log id), indexed for lane facts, by the rule of every recorded map
    (extractors.base.recorded_road): None without an archive (no word: a release without maps); an archive
    that cannot be used at all, or two archives, leave the frames without road columns (a line naming it), or
    with `strict` are a MapError."""
    found = map_files(log_dir)
    if not found:
        return None

    def read(repairs: MapRepairs) -> RoadMap:
        if len(found) > 1:
            raise MapError(f"{len(found)} map archives ({MAP_GLOB}); a log has one")
        return read_map(found[0], log_dir.name, repairs)

    return recorded_road(found[0] if len(found) == 1 else found[0].parent, read, strict, tally)


def read_map(path: Path, map_id: str, repairs: MapRepairs | None = None) -> RoadMap:
    """The map of a log's map archive. A feature that breaks a rule (a lane segment, crossing or drivable area
    with a field missing or of the wrong type, a coordinate that is not a finite number, an id that is not an
    integer, a boundary of fewer than two distinct points, a polygon that is not simple) is dropped, and a link
    that names no lane (not an integer, the lane itself, a lane the map does not keep) dropped, the lane kept:
    each counted in `repairs`, which refuses instead when strict (the default). A MapError (its message without
    the path: the caller names the archive) for an archive that cannot be used at all (_archive)."""
    repairs = repairs if repairs is not None else MapRepairs(strict=True)
    data = _archive(path)
    features = _lanes(map_id, list(data["lane_segments"].values()), repairs)
    features += _each(map_id, "crosswalk", (data.get("pedestrian_crossings") or {}).values(), _crossing, repairs)
    features += _each(map_id, "drivable area", (data.get("drivable_areas") or {}).values(), _area, repairs)
    return RoadMap.of(map_id, links_within(features, neighbours=True), repairs)


SECTIONS = ("lane_segments", "pedestrian_crossings", "drivable_areas")
# Integer literals of more digits than this are read as the float they overflow to (inf), a coordinate or id
# that breaks a rule of one feature, where Python's int would refuse the whole archive (its 4,300-digit limit).
MAX_DIGITS = 4000


def _archive(path: Path) -> dict:
    """An archive's JSON: an object whose lane_segments is an object (pedestrian_crossings, drivable_areas
    objects too, where present), else a MapError: the archive cannot be used at all. NaN, Infinity and numbers
    beyond a float are read as floats (not finite), for the features that hold them to be dropped."""
    try:
        # a FIFO or a device is refused, never read forever; never more than MAX_MAP_BYTES + 1 bytes
        data = json.loads(read_regular(path, MAX_MAP_BYTES).decode("utf-8"), parse_constant=float,
                          parse_int=_integer)
    except OSError as exc:
        raise MapError(f"not a readable Argoverse 2 map archive ({exc.strerror or exc})") from None
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise MapError(f"not a readable Argoverse 2 map archive ({str(exc)[:100]})") from None
    except RecursionError:  # an archive is four levels deep: the parser's stack ends before anything real
        raise MapError("not an Argoverse 2 map archive: its JSON is nested too deeply") from None
    if not isinstance(data, dict) or not isinstance(data.get("lane_segments"), dict):
        raise MapError("not an Argoverse 2 map archive (no lane_segments object)")
    wrong = [k for k in SECTIONS[1:] if data.get(k) is not None and not isinstance(data[k], dict)]
    if wrong:
        raise MapError(f"not an Argoverse 2 map archive ({wrong[0]} is not an object)")
    return data


def _integer(text: str) -> int | float:
    return int(text) if len(text) <= MAX_DIGITS else float(text)


def _each(map_id: str, kind: str, values: Iterable[Any], read: Callable[[str, Any], Any],
          repairs: MapRepairs) -> list:
    """read(map_id, v) of every element; one that breaks a rule (a MapError, or a field missing or of the wrong
    type) is dropped and counted in `repairs` (or refused, if it is strict)."""
    out = []
    for v in values:
        try:
            out.append(read(map_id, v))
        except MapError as exc:
            repairs.broken(DROPPED_BROKEN, str(exc))
        except (KeyError, TypeError, AttributeError, ValueError, OverflowError) as exc:
            repairs.broken(DROPPED_BROKEN, f"map {map_id!r}: a {kind} lacks a field or has the wrong type "
                           f"({type(exc).__name__}: {str(exc)[:80]})")
    return out


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
    """A map element's id as text: Argoverse 2 writes integers (an integral float or decimal text is read as one);
    anything else, 1e400 (a float overflowing to inf) or 1.5 among them, is a MapError, never truncated."""
    if isinstance(v, float) and not (math.isfinite(v) and v.is_integer()) or isinstance(v, bool):
        raise MapError(f"a map element's id {_shown(v)} is not an integer (Argoverse 2 ids are integers)")
    try:
        return str(int(v))
    except (TypeError, ValueError, OverflowError):
        raise MapError(f"a map element's id {_shown(v)} is not an integer (Argoverse 2 ids are integers)") from None


def _shown(v: Any) -> str:
    text = repr(v)
    return text if len(text) <= 40 else text[:37] + "..."


def _raw(pts: Any) -> list[tuple[Any, Any]]:
    """A boundary's (x, y) values as the archive writes them (checked to be numbers by _numbers)."""
    return [(p["x"], p["y"]) for p in pts]


def _numbers(lines: list[list[tuple[Any, Any]]]) -> tuple[np.ndarray, np.ndarray] | None:
    """Lines of raw (x, y) values packed as floats (points, each line's count), if every value is a finite number
    (an int or a float, never a bool or text); else None."""
    values = list(chain.from_iterable(chain.from_iterable(lines)))
    if not set(map(type, values)) <= {float, int}:
        return None
    try:
        flat = np.array(values, dtype=float)
    except OverflowError:  # an int beyond a float
        return None
    if not np.isfinite(flat).all():
        return None
    return flat.reshape(-1, 2), np.fromiter(map(len, lines), dtype=np.int64, count=len(lines))


def _line(where: str, pts: Any) -> np.ndarray:
    """One boundary, edge or area boundary as an (N, 2) float array; MapError for a value that is not a finite
    number, naming it."""
    return _checked(where, _raw(pts))


def _checked(where: str, raw: list[tuple[Any, Any]]) -> np.ndarray:
    """Raw (x, y) values as an (N, 2) float array; MapError for a value that is not a finite number."""
    got = _numbers([raw])
    if got is None:
        bad = next(p for p in raw if _numbers([[p]]) is None)
        raise MapError(f"{where} has a point that is not two finite numbers ({_shown(bad)})")
    return got[0]


def _lanes(map_id: str, segments: list[Any], repairs: MapRepairs) -> list[MapFeature]:
    """The lanes of a map's lane segments, their centre lines computed for all lanes at once (_centres); a segment
    that breaks a rule is dropped (counted in `repairs`). The common case checks every coordinate in one pass."""
    read = _each(map_id, "lane", segments, lambda _, v: (
        v, _id(v["id"]), _raw(v["left_lane_boundary"]), _raw(v["right_lane_boundary"]), _lane_type(v)), repairs)
    got = _numbers([r[2] for r in read] + [r[3] for r in read])
    if got is None:  # a value that is not a finite number: find its lane (and any other), drop it
        read = _each(map_id, "lane", read, _numbers_checked, repairs)
        got = _numbers([r[2] for r in read] + [r[3] for r in read])
    xy, counts = got
    two = _two_distinct(xy, counts)
    ok = two[:len(read)] & two[len(read):]
    if not ok.all():
        for i in np.flatnonzero(~ok).tolist():
            repairs.broken(DROPPED_BROKEN, f"map {map_id!r}: lane {read[i][1]!r} has a boundary of fewer than two "
                           "distinct points")
        read = [r for r, k in zip(read, ok.tolist()) if k]
        xy, counts = packed_subset((xy, counts), np.concatenate([ok, ok]))
    centres = _packed_centres(xy, counts)
    pts = list(zip(xy[:, 0].tolist(), xy[:, 1].tolist()))  # the boundaries' own floats, for the polygons
    ends = np.cumsum(counts).tolist()
    starts = [e - c for e, c in zip(ends, counts.tolist())]
    n = len(read)
    out = []
    for i, ((v, fid, _, _, source_type), centre) in enumerate(zip(read, centres)):
        left, right = pts[starts[i]:ends[i]], pts[starts[n + i]:ends[n + i]]
        out.append(MapFeature.fast(
            map_id, fid, LANE, polygon=open_ring(FloatPairs(right + left[::-1])), line=centre,
            source_type=source_type,
            left=_link(map_id, fid, v.get("left_neighbor_id"), "left neighbour", repairs),
            right=_link(map_id, fid, v.get("right_neighbor_id"), "right neighbour", repairs),
            successors=_links(map_id, fid, v.get("successors"), "successor", repairs),
            predecessors=_links(map_id, fid, v.get("predecessors"), "predecessor", repairs),
            is_intersection=bool(v.get("is_intersection", False))))
    return out


def _numbers_checked(map_id: str, r: tuple) -> tuple:
    """A lane as _lanes reads it, if both its boundaries are finite numbers (else a MapError naming the point)."""
    for side in (2, 3):
        _checked(f"map {map_id!r}: lane {r[1]!r}", r[side])
    return r


def _lane_type(v: dict) -> str:
    t = v.get("lane_type", "")
    if not isinstance(t, str) or not utf8_writable(t):
        raise MapError(f"a lane's lane_type {_shown(t)} is not text (VEHICLE, BIKE, BUS)")
    return t


def _two_distinct(xy: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """For each packed line, whether it has two distinct points (one unlike its first)."""
    line = np.repeat(np.arange(len(counts)), counts)
    first = np.repeat(np.cumsum(counts) - counts, counts)
    unlike = (xy != xy[first]).any(axis=1)
    return np.bincount(line, weights=unlike, minlength=len(counts)) > 0


def _link(map_id: str, fid: str, value: Any, what: str, repairs: MapRepairs) -> str | None:
    """A lane's neighbour (null: none); one that is not an id is dropped, counted."""
    if value is None:
        return None
    try:
        return _id(value)
    except MapError:
        repairs.broken(DROPPED_LINKS, f"map {map_id!r}: lane {fid!r} has {what} {_shown(value)}, which is not a "
                       "lane id (an integer)")
        return None


def _links(map_id: str, fid: str, value: Any, what: str, repairs: MapRepairs) -> tuple[str, ...]:
    """A lane's successors or predecessors (a list of ids); an item that is not an id is dropped, counted."""
    if value is None:
        return ()
    if not isinstance(value, list):
        repairs.broken(DROPPED_LINKS, f"map {map_id!r}: lane {fid!r} has {what}s {_shown(value)}, not a list of ids")
        return ()
    ids = (_link(map_id, fid, x, what, repairs) if x is not None else _nothing(map_id, fid, what, repairs)
           for x in value)
    return tuple(i for i in ids if i is not None)


def _nothing(map_id: str, fid: str, what: str, repairs: MapRepairs) -> None:
    repairs.broken(DROPPED_LINKS, f"map {map_id!r}: lane {fid!r} has a {what} null, which names no lane")


def _centres(lefts: list[list[tuple[float, float]]], rights: list[list[tuple[float, float]]]) -> list[FloatPairs]:
    """Each lane's centre line: (_resample(left, n) + _resample(right, n)) / 2, n the larger point count, for all
    lanes at once, with the same arithmetic (the polygon keeps the boundaries' own floats)."""
    lines = lefts + rights
    xy = np.array([p for line in lines for p in line], dtype=float).reshape(-1, 2)
    return _packed_centres(xy, np.array([len(line) for line in lines], dtype=np.int64))


def _packed_centres(xy: np.ndarray, counts: np.ndarray) -> list[FloatPairs]:
    """_centres of packed lines: the lanes' left boundaries, then their right boundaries in the same order."""
    lanes = len(counts) // 2
    if not lanes:
        return []
    n = np.maximum(counts[:lanes], counts[lanes:])
    ns = np.concatenate([n, n])
    both = _resample_many(xy, counts, ns)
    half = int(n.sum())
    centre = (both[:half] + both[half:]) / 2
    xs, ys, ends = centre[:, 0].tolist(), centre[:, 1].tolist(), np.cumsum(n).tolist()
    return [FloatPairs(zip(xs[end - k:end], ys[end - k:end])) for end, k in zip(ends, n.tolist())]


# Cells a padded matrix of running lengths may hold beyond twice the points it sums (see _running_lengths).
ROW_SLACK = 1 << 16


def _running_lengths(xy: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """Each line's running length at each of its points (0 at its first), packed like xy: each line's segment
    lengths summed in order by np.cumsum along a row of a zero-padded matrix, as _resample's np.cumsum sums them.
    The lines share one matrix when padding them to the longest costs little (a map's lanes: a few dozen points
    each), else take one matrix per power of two of their point counts, so the matrices hold at most twice the
    points plus ROW_SLACK cells: one boundary of 10^6 points does not pad every other lane to 10^6."""
    start = np.cumsum(counts) - counts
    d = np.diff(xy, axis=0)
    seg = np.empty(len(xy))
    seg[1:] = np.hypot(d[:, 0], d[:, 1])
    seg[start] = 0.0  # a line's first point ends no segment of it
    run = np.empty(len(xy))
    if len(counts) * int(counts.max()) <= 2 * len(xy) + ROW_SLACK:
        groups = [np.arange(len(counts))]
    else:
        size = np.frexp(counts.astype(float))[1]  # counts in [2^(e-1), 2^e) share exponent e
        order = np.argsort(size, kind="stable")
        groups = np.split(order, np.flatnonzero(np.diff(size[order])) + 1)
    for lines in groups:
        c = counts[lines]
        first = np.cumsum(c) - c
        row = np.repeat(np.arange(len(lines)), c)
        col = np.arange(len(row)) - np.repeat(first, c)
        at = np.repeat(start[lines], c) + col
        grid = np.zeros((len(lines), int(c.max())))
        grid[row, col] = seg[at]
        run[at] = np.cumsum(grid, axis=1)[row, col]
    return run


def _resample_many(xy: np.ndarray, counts: np.ndarray, ns: np.ndarray) -> np.ndarray:
    """`_resample` of many lines (packed: points xy, each line's count) to ns[b] points each, packed, bit for bit:
    each line's running length as np.cumsum sums it (_running_lengths), np.linspace's points, and np.interp's
    interpolation (compiled_base.c's arr_interp: the knot at or below the point, the knot's own value where the
    point is on one or beyond the last, else slope * (x - x0) + y0). A line that takes np.linspace's or
    np.interp's rarer paths (no length, a subnormal step, overflow) is resampled by _resample itself. Memory:
    a few arrays of the points and of the points made (no matrix of lines x the longest line)."""
    b_count = len(counts)
    start = np.cumsum(counts) - counts
    s = _running_lengths(xy, counts)
    total = s[start + counts - 1]
    with np.errstate(all="ignore"):
        step = total / (ns - 1)
    # a line's running lengths are all finite when its total is (they only grow, and NaN stays NaN)
    odd = ~np.isfinite(total) | (total == 0) | (step == 0)
    out_start = np.cumsum(ns) - ns
    out = np.empty((int(ns.sum()), 2))
    r = np.repeat(np.arange(b_count), ns)
    k = np.arange(len(out)) - np.repeat(out_start, ns)
    x = k * step[r]
    last = k == ns[r] - 1
    x[last] = total[r[last]]
    j = np.empty(len(out), dtype=np.int64)
    for b in np.flatnonzero(~odd).tolist():  # the knot at or below each point: np.interp's binary search
        m, o, n, a = int(counts[b]), int(out_start[b]), int(ns[b]), int(start[b])
        j[o:o + n] = np.searchsorted(s[a:a + m], x[o:o + n], "right") - 1
    ok = ~odd[r]
    jo, ro, xo = j[ok], r[ok], x[ok]
    at = start[ro] + np.clip(jo, 0, None)
    f0 = xy[at]
    res = f0.copy()
    inner = (jo >= 0) & (jo < counts[ro] - 1)
    s0 = s[at]
    between = inner & (s0 != xo)
    bi = np.flatnonzero(between)
    s1 = s[at[bi] + 1]
    f1 = xy[at[bi] + 1]
    with np.errstate(all="ignore"):
        slope = (f1 - f0[bi]) / (s1 - s0[bi])[:, None]
        val = slope * (xo[bi] - s0[bi])[:, None] + f0[bi]
        again = np.isnan(val)
        if again.any():  # "if we get nan in one direction, try the other", then the knot's value
            other = slope * (xo[bi] - s1)[:, None] + f1
            val = np.where(again, other, val)
            val = np.where(np.isnan(val) & (f0[bi] == f1), f0[bi], val)
    res[bi] = val
    beyond = jo >= counts[ro] - 1
    res[beyond] = xy[start[ro[beyond]] + counts[ro[beyond]] - 1]
    out[ok] = res
    for b in np.flatnonzero(odd).tolist():
        o, n = int(out_start[b]), int(ns[b])
        out[o:o + n] = _resample(xy[start[b]:start[b] + counts[b]], n)
    return out


def _crossing(map_id: str, v: dict) -> MapFeature:
    fid = _id(v["id"])
    where = f"map {map_id!r}: crosswalk {fid!r}"
    e1, e2 = _line(where, v["edge1"]), _line(where, v["edge2"])
    if len(e1) != 2 or len(e2) != 2:
        raise MapError(f"{where} has edges that are not two points each")
    ring = np.array([e1[0], e1[1], e2[1], e2[0]])
    return MapFeature(map_id, fid, CROSSWALK, polygon=open_ring(points(ring[:, 0], ring[:, 1])),
                      source_type="PEDESTRIAN_CROSSING")


def _area(map_id: str, v: dict) -> MapFeature:
    fid = _id(v["id"])
    ring = _line(f"map {map_id!r}: drivable area {fid!r}", v["area_boundary"])
    return MapFeature(map_id, fid, DRIVABLE_AREA, polygon=open_ring(points(ring[:, 0], ring[:, 1])),
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
