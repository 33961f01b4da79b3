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
from storage.regular_files import open_regular, read_regular
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
    """The map of a log's map archive; a MapError (its message without the path: extract names the archive) for
    a file that is not one, or a map that breaks a rule of RoadMap.of."""
    try:
        # a FIFO or a device is refused, never read forever; never more than MAX_MAP_BYTES + 1 bytes
        data = json.loads(read_regular(path, MAX_MAP_BYTES).decode("utf-8"), parse_constant=_no_constant)
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise MapError(f"not a readable Argoverse 2 map archive ({str(exc)[:100]})") from None
    except ValueError as exc:  # NaN / Infinity, an integer of more than 4300 digits
        raise MapError(str(exc)) from None
    except RecursionError:  # an archive is four levels deep: the parser's stack ends before anything real
        raise MapError("not an Argoverse 2 map archive: its JSON is nested too deeply") from None
    if not isinstance(data, dict) or not isinstance(data.get("lane_segments"), dict):
        raise MapError("not an Argoverse 2 map archive (no lane_segments)")
    try:
        features = _lanes(map_id, list(data["lane_segments"].values()))
        features += [_crossing(map_id, v) for v in (data.get("pedestrian_crossings") or {}).values()]
        features += [_area(map_id, v) for v in (data.get("drivable_areas") or {}).values()]
    except (KeyError, TypeError, ValueError, AttributeError, OverflowError) as exc:
        if isinstance(exc, MapError):
            raise
        # OverflowError: an integer coordinate beyond a float (JSON's 1 followed by 400 zeros)
        raise MapError(f"a map element lacks a field or has the wrong type ({type(exc).__name__}: "
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
    """A map element's id as text: Argoverse 2 writes integers (an integral float or decimal text is read as one);
    anything else, 1e400 (a float overflowing to inf) or 1.5 among them, is a MapError, never truncated."""
    if isinstance(v, float) and not (math.isfinite(v) and v.is_integer()) or isinstance(v, bool):
        raise MapError(f"a map element's id {v!r} is not an integer (Argoverse 2 ids are integers)")
    return str(int(v))


def _pairs(pts: list[dict]) -> list[tuple[float, float]]:
    return [(float(p["x"]), float(p["y"])) for p in pts]


def _lanes(map_id: str, segments: list[dict]) -> list[MapFeature]:
    """The lanes of a map's lane segments, their centre lines computed for all lanes at once (_centres)."""
    bounds = []
    for v in segments:
        left, right = _pairs(v["left_lane_boundary"]), _pairs(v["right_lane_boundary"])
        if len(left) < 2 or len(right) < 2:
            raise MapError(f"map {map_id!r}: lane {_id(v['id'])!r} has a boundary of fewer than two points")
        bounds.append((left, right))
    centres = _centres([b[0] for b in bounds], [b[1] for b in bounds])
    return [MapFeature.fast(
        map_id, _id(v["id"]), LANE, polygon=open_ring(FloatPairs(right + left[::-1])), line=centre,
        source_type=str(v.get("lane_type", "")),
        left=None if v.get("left_neighbor_id") is None else _id(v["left_neighbor_id"]),
        right=None if v.get("right_neighbor_id") is None else _id(v["right_neighbor_id"]),
        successors=tuple(_id(s) for s in v.get("successors") or ()),
        predecessors=tuple(_id(s) for s in v.get("predecessors") or ()),
        is_intersection=bool(v.get("is_intersection", False)))
        for v, (left, right), centre in zip(segments, bounds, centres)]


def _centres(lefts: list[list[tuple[float, float]]], rights: list[list[tuple[float, float]]]) -> list[FloatPairs]:
    """Each lane's centre line: (_resample(left, n) + _resample(right, n)) / 2, n the larger point count, for all
    lanes at once, with the same arithmetic (the polygon keeps the boundaries' own floats)."""
    if not lefts:
        return []
    lines = lefts + rights
    counts = np.array([len(line) for line in lines], dtype=np.int64)
    xy = np.array([p for line in lines for p in line], dtype=float).reshape(-1, 2)
    n = np.maximum(counts[:len(lefts)], counts[len(lefts):])
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
