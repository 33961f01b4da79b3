"""ScenarioNet scenario descriptions (.pkl, one scenario each) as frames.

Input: a ScenarioNet database directory (dataset_summary.pkl + dataset_mapping.pkl, as ScenarioNet writes
them: a converter's output, its per-worker sub-databases, or a merged database whose mapping points into other
database folders), any directory of scenario .pkl files, or one .pkl file. Every pickle goes through the restricted
unpickler. Ego = the track named by metadata.sdc_id. nuScenes-derived scenarios are 10 Hz interpolations of
the 2 Hz keyframes: step 5k holds nuScenes sample k unchanged, so one frame per keyframe, frame_id
`<scene>/<k>`. Other datasets (Waymo, nuPlan, Lyft, Argoverse) give a frame per step. `--every K` keeps every
K-th of those frames. An object is classified by its dataset's own type (metadata.type) if the "scenarionet"
taxonomy knows it, else by its MetaDrive type (the track's type); see extractors.base.FrameBuilder.classify.
"""

from __future__ import annotations

import errno
import os
from collections.abc import Iterator
from itertools import chain
from operator import itemgetter
from pathlib import Path
from typing import Any

import numpy as np

from extractors import nuscenes
from extractors.base import (
    ExtractError,
    ExtractOptions,
    ExtractTally,
    FrameBuilder,
    LongLived,
    Look,
    MapSink,
    RecordedObject,
    Source,
    gc_paused,
    global_to_ego,
    prefetch_facts,
    recorded_road,
    require_path,
)
from extractors.base import utf8_writable as _writable
from extractors.categories import Taxonomy
from extractors.safe_pickle import load_pickle
from synth.road.lane_facts import RoadIndex
from synth.road.lane_geometry import DEFAULT_LANE_WIDTH, MAX_HALF_WIDTH, MIN_HALF_WIDTH, lane_polygons, neighbours
from synth.road.roadmap import (
    CROSSWALK,
    DROPPED_BROKEN,
    DROPPED_LINKS,
    LANE,
    ROAD_LINE,
    ArrayPoints,
    FloatPairs,
    MapError,
    MapFeature,
    MapRepairs,
    Points,
    RoadMap,
    links_within,
    open_ring,
    points,
)

DESCRIPTION = "ScenarioNet database directory or .pkl scenario files (nuScenes, Waymo, nuPlan, Lyft, Argoverse)"
# What ScenarioNet's converters (metadriverse/scenarionet, converter/*/utils.py and type.py) write: MetaDrive
# object types in every track's `type` (Waymo's VEHICLE / PEDESTRIAN / CYCLIST / OTHER, nuPlan's and Argoverse 2's
# mapped to those, TRAFFIC_CONE / TRAFFIC_BARRIER / TRAFFIC_OBJECT), and the dataset's own type in `metadata.type`
# where the converter keeps one: the nuScenes names (nuScenes converter), the Lyft names, and the raw nuPlan names
# of older conversions.
TAXONOMY = Taxonomy("scenarionet", {
    # MetaDrive object types (metadrive/type.py MetaDriveType) that converters give tracks. GROUND, BUILDING,
    # INVISIBLE_WALL and TRAFFIC_LIGHT are scenery, not road users: left unmapped, so they are counted as unknown.
    "VEHICLE": "Car",
    "PEDESTRIAN": "Pedestrian",
    "CYCLIST": "Bicycle",
    "MOTORCYCLIST": "Motorcycle",
    "TRAFFIC_CONE": "TrafficCone",
    "TRAFFIC_BARRIER": "Barrier",
    "TRAFFIC_OBJECT": "Object",
    "GROUND_ANIMAL": "Animal",
    "OTHER": "Object",
    "UNSET": "Object",
    # nuPlan tracked object types as kept in metadata.type
    "vehicle": "Car",
    "pedestrian": "Pedestrian",
    "bicycle": "Bicycle",
    "traffic_cone": "TrafficCone",
    "barrier": "Barrier",
    "czone_sign": "Object",
    "generic_object": "Object",
    # Lyft Level 5 classes as kept in metadata.type
    "car": "Car",
    "truck": "Truck",
    "bus": "Bus",
    "other_vehicle": "Car",
    "emergency_vehicle": "EmergencyVehicle",
    "motorcycle": "Motorcycle",
    "animal": "Animal",
    # nuScenes names, as the nuScenes converter keeps them in metadata.type
    **nuscenes.TAXONOMY.classes,
})
SUMMARY, MAPPING = "dataset_summary.pkl", "dataset_mapping.pkl"
NUSCENES_KEYFRAME_STEP = 5
MAX_STEPS = 10**6
# tracks x steps a scenario may stack: one per BYTES_PER_CELL bytes of its file, and MIN_CELLS whatever its size
BYTES_PER_CELL, MIN_CELLS = 4, 2**20


def scenario_files(path: Path) -> list[Path]:
    """The scenario pickles of a database (in its summary's order) or directory (sorted), or the file itself."""
    if path.is_file():
        return [path]
    if (path / SUMMARY).is_file():
        return database_files(path)
    found = sorted(p for p in path.rglob("*.pkl") if p.name not in (SUMMARY, MAPPING))
    if not found:
        raise ExtractError(f"{path} holds no ScenarioNet .pkl files")
    return found


def database_files(db: Path) -> list[Path]:
    """Where each scenario of a ScenarioNet database lives, as metadrive's read_dataset_summary finds it:
    db / mapping[name] / name. A converter's own database maps every name to "" (the same folder); the top
    database of a converter run with --num_workers maps them to its per-worker sub-databases ("db_0", ...);
    `scenarionet.merge` maps them to os.path.relpath(source database, merged database), e.g. "../waymo_0".
    All of these are followed; each target must be an existing file (a symlink loop is not).

    The mapping is the index: every ScenarioNet tool that writes a database (write_to_directory, merge, split,
    filter, copy) writes summary and mapping with the same names in the same order, and the mapping holds a
    short string per scenario where the summary holds its whole metadata (about 100 KB in memory for a Waymo
    scenario of 200 tracks: gigabytes for a full dataset). The summary is read only when there is no mapping,
    in which case ScenarioNet takes every scenario to be in the database folder itself."""
    mapping = load_pickle(db / MAPPING) if (db / MAPPING).is_file() else None
    if mapping is not None and not isinstance(mapping, dict):
        raise ExtractError(f"{db}: {MAPPING} is not a ScenarioNet index (it holds {_kind(mapping)}, not a dict)")
    index = mapping if mapping else load_pickle(db / SUMMARY)
    if not isinstance(index, dict):
        raise ExtractError(f"{db}: {MAPPING if mapping else SUMMARY} is not a ScenarioNet index (a dict)")
    where = MAPPING if mapping else SUMMARY
    files = []
    for name, rel in index.items():
        rel = rel if mapping else ""
        if not isinstance(name, str) or not name.endswith(".pkl") or Path(name).name != name:
            raise ExtractError(f"{db}: {where} entry {_shown(name)} is not the file name of a scenario (.pkl)")
        if not isinstance(rel, str):
            raise ExtractError(f"{db}: {where} entry {_shown(name)} maps to {_shown(rel)}, not a folder")
        target = db / rel / name
        try:
            # strict: a missing file or a symlink loop (ELOOP) raises instead of resolving forever
            is_file = Path(os.path.realpath(target, strict=True)).is_file()
        except (OSError, RuntimeError, ValueError) as exc:
            why = "is a symlink loop" if getattr(exc, "errno", None) == errno.ELOOP else "does not exist"
            raise ExtractError(f"{db}: {where} entry {_shown(name)} maps to {target}, which {why}") from None
        if not is_file:
            raise ExtractError(f"{db}: {where} entry {_shown(name)} maps to {target}, which is not a file")
        files.append(target)
    return files


def extract(input_path: str, options: ExtractOptions, tally: ExtractTally | None = None,
            maps: MapSink | None = None) -> Iterator[list[dict[str, Any]]]:
    """Every scenario's frames, in the database's order. A scenario id met again (ScenarioNet's merge only warns
    about repeats; the same scene converted twice, under two versions, has two files) is skipped with a warning
    naming both files, since its frame ids would clash with the first one's. With `maps`, a scenario's map
    (`scenario_map`; map id = the scenario id) goes to it before the scenario's frames, which carry their lane
    facts."""
    tally = tally if tally is not None else ExtractTally()
    files = scenario_files(require_path(input_path, "ScenarioNet input"))
    first: dict[str, int] = {}  # scenario id -> index in files of the file that gave it
    for i, f in enumerate(files):
        sd = load_pickle(f)
        scene = scenario_id(f, sd)
        if scene in first:
            tally.skip("duplicate scenario id",
                       f"r2s extract: skipping {f}: scenario {scene!r} was already read from {files[first[scene]]}")
            continue
        first[scene] = i
        n = 0
        with LongLived() as scope:  # the scenario and its map live as long as its frames: no sweep need visit them
            scope.keep()
            road = None
            if maps is not None:
                with gc_paused():
                    road = scenario_road(f, sd, scene, options.strict_maps, tally)
                    scope.keep()
            if road is not None:
                maps(road.road)
            for rows in scenario_frames(f, sd, options, tally, road):
                n += 1
                yield rows
        if n == 0:
            tally.skip("no step with a valid ego")


def _kind(value: Any) -> str:
    """What a value of a pickle is, in a message: its type, never its repr (which may nest without end)."""
    if isinstance(value, str) and not _writable(value):
        return "text with a lone surrogate, which UTF-8 cannot write"
    name = f"{type(value).__module__}.{type(value).__qualname__}".removeprefix("builtins.")
    return f"{'an' if name[0] in 'aeiou' else 'a'} {name}"


def _shown(value: Any) -> str:
    """A value of a pickle in a message: the repr of a short name or number, else its type."""
    if isinstance(value, (str, float, bool, type(None))) or (isinstance(value, int) and value.bit_length() < 64):
        return repr(value)[:80]
    return _kind(value)


def _as_id(value: Any) -> str | None:
    """A scenario or track id as text: converters write strings, older and hand-made files ints. None for
    anything else (str() of a pickled structure may recurse without end or take exponential time) and for a
    string UTF-8 cannot write."""
    if isinstance(value, str):
        return value if _writable(value) else None
    if isinstance(value, (int, np.integer)) and (not isinstance(value, int) or value.bit_length() < 64):
        return str(value)
    return None


def _scenario(path: Path, sd: Any) -> dict:
    if not isinstance(sd, dict):
        raise ExtractError(f"{path} is not a ScenarioNet scenario (it holds {_kind(sd)}, not a dict)")
    if not isinstance(sd.get("metadata"), dict):
        raise ExtractError(f"{path} is not a ScenarioNet scenario (missing 'metadata')")
    return sd


def scenario_id(path: Path, sd: Any) -> str:
    """The scene name frames are named after: metadata.scenario_id (every converter writes it), else an id."""
    meta = _scenario(path, sd)["metadata"]
    for where, value in (("metadata.scenario_id", meta.get("scenario_id")), ("metadata.id", meta.get("id")),
                         ("id", sd.get("id"))):
        if value is None:
            continue
        name = _as_id(value)
        if name is None:
            raise ExtractError(f"{path}: {where} is {_kind(value)}, not a scenario name")
        if value:
            return name
    return path.stem


def _numbers(value: Any, path: Path, tid: str, key: str) -> np.ndarray:
    """state.KEY as floats: a numeric array as converters write it, or numbers (a list of numbers or of short
    lists of numbers, as hand-made files may hold). Strings, objects and ints too large for a float are refused."""
    plain = (bool, int, float, np.bool_, np.integer, np.floating)
    if isinstance(value, np.ndarray):
        ok = value.dtype.kind in "biuf"
    elif isinstance(value, (list, tuple)):
        ok = len(value) <= MAX_STEPS and all(
            isinstance(v, plain) or (isinstance(v, (list, tuple)) and len(v) <= 16 and all(isinstance(w, plain)
                                                                                          for w in v))
            for v in value)
    else:
        ok = isinstance(value, plain)
    if ok:
        try:
            return np.asarray(value, dtype=float)
        except (ValueError, TypeError, OverflowError):
            pass  # ragged lists, ints beyond a float
    raise ExtractError(f"{path}: track {tid} state.{key} is {_kind(value)} that is not an array of numbers")


def _series(state: dict, key: str, steps: int, path: Path, tid: str, width: int | None = None) -> np.ndarray:
    """A per-step state array, checked for its length (ScenarioNet stores (T,), (T, 1) or (T, k))."""
    if key not in state:
        raise ExtractError(f"{path}: track {tid} lacks state.{key}")
    a = _numbers(state[key], path, tid, key)
    if width is None:
        a = a.reshape(-1)
        if a.size == 1:
            a = np.repeat(a, steps)
    if a.ndim == 0 or a.shape[0] != steps or (width is not None and (a.ndim != 2 or a.shape[1] < width)):
        raise ExtractError(f"{path}: track {tid} state.{key} has shape {a.shape}, not {steps} steps")
    return a


def scenario_road(path: Path, sd: Any, scene: str, strict: bool = True,
                  tally: ExtractTally | None = None) -> RoadIndex | None:
    """The scenario's map, indexed for lane facts; None when it has none (no or empty map_features). What the
    reading repaired or dropped is counted in the tally. A map that cannot be used at all (map_features not a
    dict of features) is a MapError when `strict` (--strict-maps), else None, with a line that says so: a map
    never costs the tracks (extractors.base.recorded_road, as for every source)."""
    features = sd.get("map_features") if isinstance(sd, dict) else None
    if features is None or (isinstance(features, (dict, list, tuple)) and not features):
        return None
    meta = sd.get("metadata")
    dataset = meta.get("dataset") if isinstance(meta, dict) else None
    dataset = dataset.lower() if isinstance(dataset, str) else ""
    return recorded_road(path, lambda repairs: scenario_map(scene, features, dataset, repairs), strict, tally)


def scenario_frames(
    path: Path, sd: Any, options: ExtractOptions, tally: ExtractTally | None = None, road: RoadIndex | None = None
) -> Iterator[list[dict[str, Any]]]:
    scene = scenario_id(path, sd)
    meta = sd["metadata"]
    for key, where in (("tracks", sd), ("length", sd), ("sdc_id", meta)):
        if key not in where:
            raise ExtractError(f"{path} is not a ScenarioNet scenario (missing {key!r})")
    tracks, sdc, ts, dataset = sd["tracks"], meta["sdc_id"], meta.get("ts"), meta.get("dataset", "")
    dataset = dataset.lower() if isinstance(dataset, str) else ""
    try:
        steps = int(sd["length"])
    except (TypeError, ValueError, OverflowError):
        raise ExtractError(f"{path}: scenario length is {_kind(sd['length'])}, not a number of steps") from None
    if not isinstance(tracks, dict):
        raise ExtractError(f"{path}: tracks is {_kind(tracks)}, not a dict of tracks")
    # Converters write string ids (Waymo: str(obj.id)); older and hand-made files have ints: compare as text.
    track_ids = [_as_id(t) for t in tracks]
    if None in track_ids:
        raise ExtractError(f"{path}: a track id is {_kind(list(tracks)[track_ids.index(None)])}, not a name")
    if _as_id(sdc) is None or track_ids.count(_as_id(sdc)) != 1:
        if isinstance(sdc, str) and not _writable(sdc):
            raise ExtractError(f"{path}: metadata.sdc_id is {_kind(sdc)}, not a track id")
        raise ExtractError(f"{path}: the ego track (metadata.sdc_id = {_shown(sdc)}) is not among the tracks")
    if steps < 1 or steps > MAX_STEPS:
        raise ExtractError(f"{path}: implausible scenario length {steps}")
    # Every track holds its own per-step arrays (at least a position: two numbers a step), so a file holds at
    # least 4 bytes per track and step; tracks sharing one array through the pickle's memo would otherwise make
    # the arrays stacked below (about 100 bytes per track and step) gigabytes from a few megabytes.
    cells, limit = len(tracks) * steps, max(MIN_CELLS, _file_size(path) // BYTES_PER_CELL)
    if cells > limit:
        raise ExtractError(f"{path}: {len(tracks)} tracks x {steps} steps is more than a file of its size holds "
                           f"(at most one track-step per {BYTES_PER_CELL} bytes, or {MIN_CELLS:,} in all)")

    nuscenes = dataset == "nuscenes"
    builder = FrameBuilder("scenarionet", TAXONOMY, options, tally)
    ids, cats, coarse, pos, yaw, valid, length, width, speed = [], [], [], [], [], [], [], [], []
    for tid, tr in zip(track_ids, tracks.values()):
        state = tr.get("state") if isinstance(tr, dict) else None
        tmeta = tr.get("metadata") if isinstance(tr, dict) else None
        tmeta = {} if tmeta is None else tmeta
        if not isinstance(state, dict) or not isinstance(tmeta, dict):
            raise ExtractError(f"{path}: track {tid!r} is not a ScenarioNet track")
        # metadata.type holds the dataset's own type where the converter keeps one (nuScenes, Lyft), else
        # the MetaDrive type again; `type` is the MetaDrive type (None for the nuScenes converter's animals).
        own, kind = tmeta.get("type"), tr.get("type")
        for where, value in (("metadata.type", own), ("type", kind)):
            if isinstance(value, str) and not _writable(value):
                raise ExtractError(f"{path}: track {tid!r} {where} is {_kind(value)}, not a category")
        kind = kind if isinstance(kind, str) and kind else None
        ids.append(tid)
        cats.append(str(own) if isinstance(own, str) and own else kind or "UNSET")
        coarse.append(kind if kind != cats[-1] else None)
        pos.append(_series(state, "position", steps, path, tid, width=2)[:, :2])
        yaw.append(_series(state, "heading", steps, path, tid))
        valid.append(_series(state, "valid", steps, path, tid) > 0)
        length.append(_series(state, "length", steps, path, tid) if "length" in state else np.full(steps, np.nan))
        width.append(_series(state, "width", steps, path, tid) if "width" in state else np.full(steps, np.nan))
        speed.append(_speeds(state, steps, path, tid))
    pos, yaw, valid = np.stack(pos), np.stack(yaw), np.stack(valid)
    length, width, speed = np.stack(length), np.stack(width), np.stack(speed)
    ego_i = ids.index(_as_id(sdc))

    stride = NUSCENES_KEYFRAME_STEP if nuscenes else 1
    kept = [step for step in range(0, steps, stride) if not (step // stride) % options.every and valid[ego_i, step]]
    if road is not None and kept:  # every place a frame below will ask for: the tracks' within the radius of the
        # ego (and a hair beyond: FrameBuilder decides it again, in the ego frame; any other is decided then)
        tracks_at, steps_at = np.nonzero(valid[:, kept])
        at = np.asarray(kept)[steps_at]
        px, py = pos[tracks_at, at, 0], pos[tracks_at, at, 1]
        with np.errstate(invalid="ignore"):
            near = np.hypot(px - pos[ego_i, at, 0], py - pos[ego_i, at, 1]) <= options.radius * (1 + 1e-9) + 1e-9
        prefetch_facts(road, px[near], py[near], yaw[tracks_at, at][near])
    for step in kept:
        index = step // stride
        ex, ey = pos[ego_i, step]
        ego_yaw = float(yaw[ego_i, step])
        others = [i for i in np.flatnonzero(valid[:, step]) if i != ego_i]
        with np.errstate(all="ignore"):  # no numpy warning line: FrameBuilder refuses a non-finite box itself
            x, y, h = global_to_ego(float(ex), float(ey), ego_yaw, pos[others, step, 0], pos[others, step, 1],
                                    yaw[others, step])
        boxes = [RecordedObject(ids[i], cats[i], float(x[k]), float(y[k]), float(h[k]), length[i, step],
                                width[i, step], coarse[i], speed[i, step],
                                (float(pos[i, step, 0]), float(pos[i, step, 1]), float(yaw[i, step])))
                 for k, i in enumerate(others)]
        # ScenarioNet's nuScenes converter stores the ego car as 1.73 m long and 4.08 m wide; no car is wider
        # than it is long, so the ego's box is read with its sides in order.
        ego_l, ego_w = sorted((length[ego_i, step], width[ego_i, step]), reverse=True)
        ego = RecordedObject(ids[ego_i], cats[ego_i], 0.0, 0.0, 0.0, ego_l, ego_w, speed=speed[ego_i, step],
                             world=(float(ex), float(ey), ego_yaw))
        yield builder.frame(scene, index, _timestamp_us(ts, step), ego, boxes, road=road)


def _file_size(path: Path) -> int:
    try:
        return os.path.getsize(path)
    except OSError:
        return 0


def _speeds(state: dict, steps: int, path: Path, tid: str) -> np.ndarray:
    """|state.velocity| per step (m/s; converters write (T, 2) in the scenario's ground frame), as recorded:
    nuScenes-derived scenarios hold the forward difference of the interpolated positions. NaN without one."""
    if "velocity" not in state:
        return np.full(steps, np.nan)
    v = _series(state, "velocity", steps, path, tid, width=2)
    return np.hypot(v[:, 0], v[:, 1])


def _timestamp_us(ts: Any, step: int) -> int | None:
    """metadata.ts is seconds from the scenario start; absent or odd values leave the timestamp empty."""
    try:
        t = float(ts[step])
    except (TypeError, ValueError, IndexError, KeyError, OverflowError):
        return None
    return round(t * 1e6) if np.isfinite(t) else None


# ------------------------------------------------------------------------------------------------- the map
# The map of a ScenarioNet scenario (`map_features`: a dict feature id -> feature with a `type`) as a RoadMap, read
# as ScenarioNet's converters write it (converter/{waymo,nuscenes,nuplan,argoverse2}/utils.py and type.py; MetaDrive's
# type.py); docs/formats.md ("What the sources give") states each rule.
#
# Kinds: LANE_* features are lanes (centre line = `polyline`, polygon = `polygon` where given); so is a feature of
# type UNKNOWN that has a lane's keys (older Waymo conversions wrote Waymo's undefined lane type as UNKNOWN, and
# other lanes name such lanes as neighbours); ROAD_LINE_*, UNKNOWN_LINE, ROAD_EDGE_BOUNDARY / _MEDIAN and a
# polyline of type UNKNOWN (MetaDrive's unknown boundary) are road lines; CROSSWALK a crosswalk; other types (stop
# signs, speed bumps, driveways, sidewalks: ROAD_EDGE_SIDEWALK is a polygon) are not kept. A lane without a
# polygon gets one from its centre line and its per-vertex `width` (N, 2: left, right; a value of 0 or out of
# [MIN_HALF_WIDTH, MAX_HALF_WIDTH] is unknown: the other side's there, else the default; the means of each side)
# (synth.road.lane_geometry). A lane is an intersection lane if its type is LANE_SURFACE_UNSTRUCTURE, or, in
# nuScenes-derived scenarios, if it has no polygon: ScenarioNet's nuScenes converter writes polygons for nuScenes
# lanes and none for lane connectors, the lanes through intersections. Successors / predecessors are `exit_lanes` /
# `entry_lanes` (links that leave the converter's crop of the map are dropped); neighbours are the first
# `feature_id` of `left_neighbor` / `right_neighbor`; a map in which no lane has one gets them by the geometric
# rule. A lane or line of fewer than two distinct points is dropped (the Waymo converter writes one-point lanes and
# road edges), with the links to it. Whatever else breaks a rule of the map format is dropped and counted in the
# MapRepairs (or refused with --strict-maps).

UNKNOWN = "UNKNOWN"
LANE_KEYS = ("entry_lanes", "exit_lanes", "left_neighbor", "right_neighbor", "left_boundaries", "right_boundaries")
# the repairs this reader counts (RoadMap.of counts its own)
ONE_POINT = "one-point features dropped"
WIDTHS_DEFAULT = "lane widths from the default"
WIDTHS_OTHER_SIDE = "lane widths from the other side"
NOT_WIDENED = "lanes whose centre line cannot be widened dropped"


def kind_of(source_type: str, feat: dict | None = None) -> str | None:
    if source_type.startswith("LANE_"):
        return LANE
    if source_type == UNKNOWN and feat is not None:
        return LANE if any(k in feat for k in LANE_KEYS) else ROAD_LINE if "polyline" in feat else None
    if source_type.startswith("ROAD_LINE_") or source_type in ("UNKNOWN_LINE", "ROAD_EDGE_BOUNDARY",
                                                               "ROAD_EDGE_MEDIAN"):
        return ROAD_LINE
    if source_type == CROSSWALK.upper():
        return CROSSWALK
    return None


def scenario_map(map_id: str, map_features: Any, dataset: str, repairs: MapRepairs | None = None) -> RoadMap | None:
    """The RoadMap of a scenario's map_features; None when it has no feature of a kept kind. `repairs` counts what
    was repaired or dropped (default: a strict one, which refuses a feature that breaks a rule)."""
    repairs = repairs if repairs is not None else MapRepairs(strict=True)
    if not isinstance(map_features, dict):
        raise MapError(f"map {map_id!r}: map_features is {_kind(map_features)}, not a dict of features")
    nuscenes = dataset == "nuscenes"
    features = []
    unwidened: dict[str, tuple[dict, int]] = {}  # lanes without polygon: their feature, number of points
    dropped: set[str] = set()  # lanes of one point: links to them go with them
    any_neighbour = False
    for raw_id, feat in map_features.items():
        fid = _text(raw_id)
        if fid is None:
            repairs.broken(DROPPED_BROKEN, f"map {map_id!r}: a feature id is {_kind(raw_id)}, not a name")
            continue
        if not isinstance(feat, dict) or _text(feat.get("type", "")) is None:
            repairs.broken(DROPPED_BROKEN, f"map {map_id!r}: feature {fid!r} is not a dict with a type (a name)")
            continue
        source_type = _text(feat.get("type", ""))
        kind = kind_of(source_type, feat)
        if kind is None:
            continue
        try:
            line = _xy(map_id, fid, feat.get("polyline"), "polyline") if kind in (LANE, ROAD_LINE) else ()
            polygon = open_ring(_xy(map_id, fid, feat.get("polygon"), "polygon")) if "polygon" in feat else ()
        except MapError as exc:
            repairs.broken(DROPPED_BROKEN, str(exc))
            continue
        if kind in (LANE, ROAD_LINE) and _one_point(line):
            repairs.repaired(ONE_POINT)
            if kind == LANE:
                dropped.add(fid)
            continue
        if kind != LANE:
            features.append(MapFeature.fast(map_id, fid, kind, polygon=polygon, line=line, source_type=source_type))
            continue
        left = _neighbour(map_id, fid, feat, "left_neighbor", repairs)
        right = _neighbour(map_id, fid, feat, "right_neighbor", repairs)
        any_neighbour = any_neighbour or left is not None or right is not None
        rule = "source"
        if not polygon:  # widths read and polygons built below, for all such lanes at once
            unwidened[fid], rule = (feat, len(line)), "centre line"
        features.append(MapFeature.fast(
            map_id, fid, kind, polygon=polygon, line=line, source_type=source_type, left=left, right=right,
            successors=_ids(map_id, fid, feat, "exit_lanes", repairs),
            predecessors=_ids(map_id, fid, feat, "entry_lanes", repairs),
            is_intersection=source_type == "LANE_SURFACE_UNSTRUCTURE" or (nuscenes and "polygon" not in feat),
            polygon_rule=rule))
    if unwidened:
        widths = _all_widths(map_id, unwidened, repairs)
        todo = [i for i, f in enumerate(features) if f.feature_id in widths and f.kind == LANE]
        rings = lane_polygons([features[i].line for i in todo], [widths[features[i].feature_id][0] for i in todo],
                              [widths[features[i].feature_id][1] for i in todo])
        gone = set()
        for i, ring in zip(todo, rings):
            if not ring:  # RoadMap.of would refuse it for want of a polygon: say why
                f = features[i]
                repairs.broken(NOT_WIDENED, f"map {map_id!r}: lane {f.feature_id!r} has a centre line that cannot be "
                               "widened into a polygon (not finite, or folding back on itself more than its size "
                               "allows)")
                gone.add(f.feature_id)
            features[i] = features[i].with_(polygon=ring)
        if gone:
            features = [f for f in features if f.feature_id not in gone]
            dropped |= gone
    if dropped:  # links to the lanes dropped above go with them
        features = [f.with_(left=None if f.left in dropped else f.left, right=None if f.right in dropped else f.right)
                    if f.kind == LANE and (f.left in dropped or f.right in dropped) else f for f in features]
    if not features:
        return None
    road = RoadMap.of(map_id, links_within(features, neighbours=False), repairs)
    if not any_neighbour:  # the geometric rule, on the validated map and its packed coordinates
        road = road.with_features(neighbours(road.lanes, road.packed("line", LANE), road.packed("polygon", LANE)))
    return road


def _one_point(line: Points) -> bool:
    """Whether a line has fewer than two distinct points (as a set of its pairs counts them: NaN is distinct)."""
    xy = getattr(line, "xy", None)
    if xy is not None:  # without making its pairs: almost every line has two distinct points among its first three
        first = xy[:3].tolist()
        if any(p != first[0] for p in first[1:]):  # lists compare as the pairs do (NaN unequal to itself)
            return False
        return len(xy) < 2 or not (xy[1:] != xy[0]).any()
    return len(set(line[:3])) < 2 and len(set(line)) < 2


XY = itemgetter(0, 1)  # a point's x and y, of [x, y] or (x, y, z)
FLOATS = (np.dtype(np.float64), np.dtype(np.float32))


def _text(value: Any) -> str | None:
    """A map feature's id, type or link as text: a string (that UTF-8 can write: no lone surrogate) or an int
    (numpy's too; converters write both); None for anything else."""
    # what converters write, decided first without the general checks (a Waymo map has ~2,000 ids and links):
    # an ASCII string, which UTF-8 writes; a plain int (not bool, whose type is not int) as _as_id bounds it
    kind = type(value)
    if kind is str and value.isascii():
        return value
    if kind is int:
        return str(value) if value.bit_length() < 64 else None
    return _as_id(value) if not isinstance(value, (bool, np.bool_)) else None


def _xy(map_id: str, fid: str, value: Any, what: str):
    if value is None:
        return ()
    # What converters write, converted without numpy's per-element work: a float array, or a list of [x, y]
    # (or [x, y, z]) float points (RoadMap.of checks that they are finite). Anything else takes the general way.
    if type(value) is np.ndarray and value.dtype in FLOATS and value.ndim == 2 and value.shape[1] >= 2:
        # float32 (the Waymo converter's) widens to a Python float exactly, as np.asarray(value, float) does; the
        # points keep that float64 array, which packing them later reuses, and make no Python pair unless asked
        return ArrayPoints(value[:, :2])
    if type(value) is list and value:
        try:
            lens = set(map(len, value))
            pts = FloatPairs(map(XY, value)) if len(lens) == 1 and min(lens) >= 2 else None
        except TypeError:  # an item that is not a sequence
            pts = None
        if pts is not None and set(map(type, chain.from_iterable(pts))) <= {float}:
            return pts
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError, OverflowError):  # OverflowError: an int beyond a float
        raise MapError(f"map {map_id!r}: feature {fid!r} has a {what} that is not an array of numbers") from None
    if a.ndim != 2 or a.shape[1] < 2:
        raise MapError(f"map {map_id!r}: feature {fid!r} has a {what} of shape {a.shape}, not (N, 2) or (N, 3)")
    return points(a[:, 0], a[:, 1])


LINKS = (list, tuple, np.ndarray)  # what converters write for a lane's links: lists (Waymo, nuScenes), arrays


def _ids(map_id: str, fid: str, feat: dict, key: str, repairs: MapRepairs) -> tuple[str, ...]:
    """A lane's successors or predecessors: the names in `key` (a list of ids); what is not a name is dropped."""
    value = feat.get(key)
    if value is None:
        return ()
    items = value.reshape(-1).tolist() if isinstance(value, np.ndarray) else value if isinstance(value, LINKS) else None
    ids = None if items is None else [_text(v) for v in items]
    if ids is None or None in ids:
        repairs.broken(DROPPED_LINKS, f"map {map_id!r}: lane {fid!r} has {key} that are not a list of names")
        return tuple(i for i in ids or () if i is not None)
    return tuple(ids)


def _neighbour(map_id: str, fid: str, feat: dict, key: str, repairs: MapRepairs) -> str | None:
    """The first neighbour of a lane on one side (Waymo: a list of dicts with feature_id; nuPlan: a list of ids)."""
    value = feat.get(key)
    if value is None or (isinstance(value, LINKS) and len(value) == 0):
        return None
    first = value[0] if isinstance(value, LINKS) else None
    ref = _text(first.get("feature_id", first.get("id")) if isinstance(first, dict) else first)
    if ref is None:
        repairs.broken(DROPPED_LINKS, f"map {map_id!r}: lane {fid!r} has a {key} that names no feature "
                       f"({_shown(first if first is not None else value)})")
    return ref


def _all_widths(map_id: str, lanes: dict[str, tuple[dict, int]], repairs: MapRepairs
                ) -> dict[str, tuple[float | None, float | None]]:
    """`_widths` of many lanes (id: feature, number of centre-line points): the (N, 2) float arrays converters
    write in one numpy pass over all of them (a map has hundreds), anything else one lane at a time."""
    out: dict[str, tuple[float | None, float | None]] = {}
    arrays, ids = [], []
    for fid, (feat, n) in lanes.items():
        w = feat.get("width")
        if type(w) is np.ndarray and w.dtype in FLOATS and w.shape == (n, 2) and n:
            arrays.append(w)
            ids.append(fid)
        else:
            out[fid] = _widths(map_id, fid, feat, n, repairs)
    if not arrays:
        return out
    n = np.fromiter(map(len, arrays), dtype=np.int64, count=len(arrays))
    lane = np.repeat(np.arange(len(arrays)), n)
    w = np.concatenate(arrays).astype(float)  # float32 (the Waymo converter's) widens exactly
    finite = np.bincount(lane, weights=~np.isfinite(w).all(axis=1), minlength=len(arrays)) == 0
    known = (w >= MIN_HALF_WIDTH) & (w <= MAX_HALF_WIDTH)
    other = known[:, ::-1] & ~known  # unknown here, known on the other side
    filled = np.where(known, w, np.where(other, w[:, ::-1], DEFAULT_LANE_WIDTH / 2))
    means = (np.add.reduceat(filled, np.cumsum(n) - n, axis=0) / n[:, None]).tolist()
    all_known = (np.bincount(lane, weights=~known.all(axis=1), minlength=len(arrays)) == 0).tolist()
    either = (np.bincount(lane, weights=~(known | other).all(axis=1), minlength=len(arrays)) == 0).tolist()
    for fid, ok, (left, right), all_, either_, k in zip(ids, finite.tolist(), means, all_known, either, n.tolist()):
        if not ok:
            out[fid] = _widths_unknown(map_id, fid, k, repairs)
            continue
        if not all_:
            repairs.repaired(WIDTHS_OTHER_SIDE if either_ else WIDTHS_DEFAULT)
        out[fid] = left, right
    return out


def _widths_unknown(map_id: str, fid: str, n: int, repairs: MapRepairs) -> tuple[None, None]:
    repairs.broken(WIDTHS_DEFAULT, f"map {map_id!r}: lane {fid!r} has a width that is not an ({n}, 2) array of "
                   "finite numbers")
    return None, None


def _widths(map_id: str, fid: str, feat: dict, n: int, repairs: MapRepairs) -> tuple[float | None, float | None]:
    """The widths to the left and to the right of the centre line: the means of `width` (N, 2: per vertex, the
    distances to the left and right boundaries), where a value of 0 or out of [MIN_HALF_WIDTH, MAX_HALF_WIDTH] is
    unknown: the other side's there (as the Waymo converter's compute_width does), else half the default width.
    (None, None) for the default (no width, or one that is not an (N, 2) array of finite numbers)."""
    if "width" not in feat:
        return None, None
    try:
        w = np.asarray(feat["width"], dtype=float)
    except (TypeError, ValueError, OverflowError):
        w = None
    if w is None or w.shape != (n, 2) or not np.isfinite(w).all():
        return _widths_unknown(map_id, fid, n, repairs)
    known = (w >= MIN_HALF_WIDTH) & (w <= MAX_HALF_WIDTH)
    if known.all():
        return float(w[:, 0].mean()), float(w[:, 1].mean())
    other = known[:, ::-1] & ~known  # unknown here, known on the other side
    w = np.where(known, w, np.where(other, w[:, ::-1], DEFAULT_LANE_WIDTH / 2))
    repairs.repaired(WIDTHS_OTHER_SIDE if (known | other).all() else WIDTHS_DEFAULT)
    return float(w[:, 0].mean()), float(w[:, 1].mean())


class ScenarioNet(Source):
    name = "scenarionet"
    description = DESCRIPTION
    input_help = "database dir or .pkl"
    taxonomy = TAXONOMY
    extract = staticmethod(extract)

    def unit_paths(self, path: Path) -> list[Path]:
        return scenario_files(path)

    def look_at_file(self, path: Path, head: bytes) -> Look | None:
        if path.suffix == ".pkl" and head.startswith(b"\x80"):  # a pickle's PROTO opcode
            return Look(self.name, "a ScenarioNet scenario (.pkl)", str(path))
        return None

    def look_at_entry(self, top: str, path: Path, is_dir: bool, depth: int) -> Look | None:
        if is_dir:
            return None
        if path.name == SUMMARY:
            return Look(self.name, f"a ScenarioNet database ({SUMMARY})", top)
        if path.name.endswith(".pkl") and path.name != MAPPING:
            return Look(self.name, "a folder of ScenarioNet scenarios (.pkl)", top)
        return None


SOURCE = ScenarioNet()
