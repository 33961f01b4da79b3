"""A scene or variant as a ScenarioNet scenario (MetaDrive's scenario description, metadrive/scenario/
scenario_description.py), and the database that holds them (docs/formats.md, "Exported scenarios").

`scenario` is pure: a Scene, its world (synth.world) and its road in, the scenario dict out, laid out as
ScenarioNet's converters write them: `id`, `version`, `length`, `metadata` (ts, metadrive_processed, coordinate,
dataset, scenario_id, sdc_id, ...), `tracks` (one per entity: MetaDrive `type`, `state` arrays of T steps, and
`metadata` with the dataset's own type, object_id, track_length), `dynamic_map_states` and `map_features`.
`Database` writes the scenario files and streams dataset_summary.pkl / dataset_mapping.pkl as it goes, so memory
does not grow with the number of scenarios (each is written and dropped).
"""

from __future__ import annotations

import io
import math
import os
import pickle
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from pipeline.export.motion import RECORDED, STEP_S, Motion, Trajectory, straight
from synth.road.roadmap import CROSSWALK, DRIVABLE_AREA, LANE, ROAD_LINE, RoadMap
from synth.scene import ENTITY_TYPES, Scene
from synth.version import __version__
from synth.world import WorldPose, road_in_world

DATASET = "r2sgen"
SUMMARY, MAPPING = "dataset_summary.pkl", "dataset_mapping.pkl"
# Scenic class -> (MetaDrive track type, the dataset's own type kept in the track's metadata.type). The MetaDrive
# type is what MetaDrive replays (only its agent and traffic-object types are allowed); the own type is a name
# `r2s extract scenarionet` reads back as the same class (extractors.scenarionet.TAXONOMY: nuScenes' names).
TRACK_TYPES: dict[str, tuple[str, str]] = {
    "Car": ("VEHICLE", "vehicle.car"),
    "Truck": ("VEHICLE", "vehicle.truck"),
    "Bus": ("VEHICLE", "vehicle.bus.rigid"),
    "Trailer": ("VEHICLE", "vehicle.trailer"),
    "ConstructionVehicle": ("VEHICLE", "vehicle.construction"),
    "EmergencyVehicle": ("VEHICLE", "vehicle.emergency.police"),
    "Motorcycle": ("VEHICLE", "vehicle.motorcycle"),
    "Bicycle": ("CYCLIST", "vehicle.bicycle"),
    "Pedestrian": ("PEDESTRIAN", "human.pedestrian.adult"),
    "Animal": ("OTHER", "animal"),
    "Barrier": ("TRAFFIC_BARRIER", "movable_object.barrier"),
    "TrafficCone": ("TRAFFIC_CONE", "movable_object.trafficcone"),
    "PushableObject": ("TRAFFIC_OBJECT", "movable_object.pushable_pullable"),
    "Debris": ("TRAFFIC_OBJECT", "movable_object.debris"),
    "BicycleRack": ("TRAFFIC_OBJECT", "static_object.bicycle_rack"),
    "Object": ("TRAFFIC_OBJECT", "OTHER"),
}
# Heights (metres) by class: scene JSON has none, MetaDrive draws one.
HEIGHTS: dict[str, float] = {"Car": 1.7, "Truck": 3.2, "Bus": 3.2, "Trailer": 3.5, "ConstructionVehicle": 3.0,
                             "EmergencyVehicle": 2.2, "Motorcycle": 1.5, "Bicycle": 1.7, "Pedestrian": 1.75,
                             "Animal": 0.8, "Barrier": 1.0, "TrafficCone": 0.7, "PushableObject": 1.0,
                             "Debris": 0.3, "BicycleRack": 1.0, "Object": 1.0}
assert set(TRACK_TYPES) == set(ENTITY_TYPES) == set(HEIGHTS)
LINE_TYPE = "ROAD_LINE_SOLID_SINGLE_WHITE"  # a road line whose source type MetaDrive does not know
# The source's own type where it is one of MetaDrive's (a ScenarioNet source wrote it), else what ScenarioNet's
# Argoverse 2 converter writes for AV2's own (converter/argoverse2/type.py: bus lanes are street lanes).
LANE_TYPES = ("LANE_SURFACE_STREET", "LANE_UNKNOWN", "LANE_FREEWAY", "LANE_BIKE_LANE")
LINE_TYPES = ("UNKNOWN_LINE", "ROAD_LINE_BROKEN_SINGLE_WHITE", "ROAD_LINE_SOLID_SINGLE_WHITE",
              "ROAD_LINE_SOLID_DOUBLE_WHITE", "ROAD_LINE_BROKEN_SINGLE_YELLOW", "ROAD_LINE_BROKEN_DOUBLE_YELLOW",
              "ROAD_LINE_SOLID_SINGLE_YELLOW", "ROAD_LINE_SOLID_DOUBLE_YELLOW", "ROAD_LINE_PASSING_DOUBLE_YELLOW",
              "ROAD_EDGE_BOUNDARY", "ROAD_EDGE_MEDIAN")
AV2_LANE_TYPES = {"VEHICLE": "LANE_SURFACE_STREET", "BUS": "LANE_SURFACE_STREET", "BIKE": "LANE_BIKE_LANE"}
EDGE_TYPE = "ROAD_EDGE_BOUNDARY"  # a drivable area's ring, as a road edge (ScenarioNet has no area feature)


@dataclass(frozen=True)
class Provenance:
    """What a scenario names: the recorded frame, the variant file (None: the frame itself) and the program."""

    frame_id: str
    variant: str | None = None
    program: str | None = None
    program_file: str | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"frame_id": self.frame_id, "variant": self.variant, "program": self.program,
                "program_file": self.program_file, "version": __version__}


def scenario(scene: Scene, name: str, world: WorldPose, road: RoadMap | None, provenance: Provenance,
             steps: int = 1) -> dict[str, Any]:
    """The scenario of one scene: every entity at its world pose (ego = the sdc track, id `ego`), moving at its
    speed along its heading for `steps` steps of 0.1 s (1: the instant itself), on the road put back in the world."""
    return scenario_of(straight(scene, world, steps), name, world, road, provenance)


def scenario_of(motion: Motion, name: str, world: WorldPose, road: RoadMap | None, provenance: Provenance,
                more: dict[str, Any] | None = None) -> dict[str, Any]:
    """The scenario of a Motion (pipeline/export/motion.py: one frame moved on, or a clip's recorded steps): every
    step of every track (`valid` false where it is not there), the Motion's times as `ts`, on the road put back in
    the world; `more` adds to the metadata's r2sgen entry (a clip's frames)."""
    tracks = {t.id: _track(t) for t in motion.trajectories}
    features = map_features(road_in_world(world, road)) if road is not None else {}
    steps = motion.steps
    meta = {
        "ts": motion.times,
        "metadrive_processed": False,
        "coordinate": "right-handed",
        "dataset": DATASET,
        "scenario_id": name,
        "id": name,
        "sdc_id": "ego",
        # a clip's own rate (its mean step; ts holds every step's time), else 10 Hz
        "sample_rate": STEP_S if motion.how != RECORDED or steps < 2 else float(motion.times[-1] / (steps - 1)),
        "map": world.map_id,
        "r2sgen": {**provenance.to_dict(), "world": world.to_dict(), "map_features": len(features), **(more or {})},
        "object_summary": {tid: _object_summary(tid, t) for tid, t in tracks.items()},
    }
    return {"id": name, "version": f"{DATASET} {__version__}", "length": steps, "metadata": meta,
            "tracks": tracks, "dynamic_map_states": {}, "map_features": features}


def _track(t: Trajectory) -> dict[str, Any]:
    steps = len(t.valid)
    position = np.zeros((steps, 3))
    position[:, 0], position[:, 1] = t.x, t.y
    # each step's velocity by the scalar cos / sin (numpy's may differ in the last bit from the instant's own)
    velocity = np.array([(s * math.cos(y), s * math.sin(y)) for s, y in zip(t.speed.tolist(), t.yaw.tolist())],
                        dtype=float).reshape(steps, 2)
    velocity[~t.valid] = 0.0  # MetaDrive's valid_check: an absent step's values are zeros
    metadrive_type, own_type = TRACK_TYPES[t.type]
    box = np.where(t.valid, 1.0, 0.0)[:, None]
    return {
        "type": metadrive_type,
        "state": {
            "position": position,
            "heading": t.yaw.copy(),
            "velocity": velocity,
            "valid": t.valid.copy(),
            "length": box * t.length,
            "width": box * t.width,
            "height": box * HEIGHTS[t.type],
        },
        "metadata": {"track_length": steps, "type": own_type, "object_id": t.id, "original_id": t.id,
                     "dataset": DATASET},
    }


def _object_summary(tid: str, track: dict) -> dict[str, Any]:
    """ScenarioNet's get_object_summary: the distance moved over the valid steps, how many are valid, and the run
    of valid steps from the first."""
    valid = track["state"]["valid"]
    steps = len(valid)
    xy = track["state"]["position"][valid, :2]
    first = int(np.argmax(valid)) if valid.any() else steps
    run = int(np.argmin(valid[first:])) if not valid[first:].all() else steps - first
    return {"type": track["type"], "object_id": tid, "track_length": steps,
            "moving_distance": float(np.sum(np.hypot(*np.diff(xy, axis=0).T))) if len(xy) > 1 else 0.0,
            "valid_length": int(valid.sum()), "continuous_valid_length": run}


def map_features(road: RoadMap) -> dict[str, dict[str, Any]]:
    """A road (in the world frame) as ScenarioNet map_features: lanes (centre line `polyline`, `polygon`, the
    lane graph as entry / exit lanes and neighbours; intersection lanes LANE_SURFACE_UNSTRUCTURE, the others their
    source's lane type: lane_type), road lines (their source's type: line_type), crosswalks, drivable areas as road
    edges; intersection areas have no ScenarioNet feature and are left out."""
    out: dict[str, dict[str, Any]] = {}
    for f in road.features:
        if f.kind == LANE:
            n = len(f.line)
            d: dict[str, Any] = {
                "type": "LANE_SURFACE_UNSTRUCTURE" if f.is_intersection else lane_type(f.source_type),
                "polyline": np.asarray(f.line, dtype=float), "polygon": np.asarray(f.polygon, dtype=float),
                "entry_lanes": list(f.predecessors), "exit_lanes": list(f.successors),
                "left_neighbor": _neighbour(f.left, n), "right_neighbor": _neighbour(f.right, n)}
        elif f.kind == ROAD_LINE:
            d = {"type": line_type(f.source_type), "polyline": np.asarray(f.line, dtype=float)}
        elif f.kind == CROSSWALK:
            d = {"type": "CROSSWALK", "polygon": np.asarray(f.polygon, dtype=float)}
        elif f.kind == DRIVABLE_AREA:
            d = {"type": EDGE_TYPE, "polyline": np.asarray(f.polygon + f.polygon[:1], dtype=float)}
        else:
            continue
        out[f.feature_id] = d
    return out


def lane_type(source_type: str) -> str:
    """A lane's ScenarioNet type from its source's (a lane in no intersection: the reader makes
    LANE_SURFACE_UNSTRUCTURE an intersection lane, which map_features writes as such)."""
    return source_type if source_type in LANE_TYPES else AV2_LANE_TYPES.get(source_type, "LANE_SURFACE_STREET")


def line_type(source_type: str) -> str:
    """A road line's ScenarioNet type: its source's where MetaDrive knows it (road edges included), else LINE_TYPE."""
    return source_type if source_type in LINE_TYPES else LINE_TYPE


def _neighbour(lane: str | None, n: int) -> list[dict[str, Any]]:
    # Waymo's layout: the neighbour and the stretch of both centre lines alongside (here: the whole lane)
    return [] if lane is None else [{"feature_id": lane, "self_start_index": 0, "self_end_index": n - 1,
                                     "neighbor_start_index": 0, "neighbor_end_index": n - 1}]


def summary_entry(sd: dict[str, Any]) -> dict[str, Any]:
    """The scenario's entry of dataset_summary.pkl: its metadata, arrays as lists (ScenarioNet's
    dict_recursive_remove_array_and_set)."""
    def plain(v: Any) -> Any:
        if isinstance(v, np.ndarray):
            return v.tolist()
        if isinstance(v, dict):
            return {k: plain(x) for k, x in v.items()}
        return v

    return plain(sd["metadata"])


def file_name(name: str) -> str:
    """A scenario's file name (sd_...: metadrive's is_scenario_file)."""
    return f"sd_{DATASET}_{name}.pkl"


class _StreamedDict:
    """A pickled dict written item by item (pickle protocol 2, no memo: fragments stand alone), so a summary of
    any number of scenarios is never held whole."""

    def __init__(self, f: BinaryIO) -> None:
        self._f = f
        f.write(b"\x80\x02}")  # PROTO 2, EMPTY_DICT

    @staticmethod
    def _body(value: Any) -> bytes:
        buf = io.BytesIO()
        p = pickle.Pickler(buf, protocol=2)
        p.fast = True  # no memo: each fragment refers to nothing outside itself
        p.dump(value)
        return buf.getvalue()[2:-1]  # without PROTO and STOP

    def add(self, key: str, value: Any) -> None:
        self._f.write(b"(" + self._body(key) + self._body(value) + b"u")  # MARK key value SETITEMS

    def close(self) -> None:
        self._f.write(b".")
        self._f.close()


class Database:
    """A ScenarioNet database being written into `folder` (a staged directory): one scenario file each, the
    summary and the mapping streamed beside them."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        self.names: set[str] = set()
        self._summary = _StreamedDict((folder / SUMMARY).open("wb"))
        self._mapping = _StreamedDict((folder / MAPPING).open("wb"))

    def add(self, sd: dict[str, Any]) -> str:
        name = file_name(sd["id"])
        with (self.folder / name).open("wb") as f:
            pickle.dump(sd, f, protocol=4)
        self._summary.add(name, summary_entry(sd))
        self._mapping.add(name, "")  # every scenario in the database's own folder
        self.names.add(name)
        return name

    def close(self) -> None:
        self._summary.close()
        self._mapping.close()


class _Writer:
    def __init__(self, folder: Path, recorded_frame: str, options) -> None:
        self.db = Database(folder)
        self.recorded_frame = recorded_frame
        self.options = options

    def add(self, item, world: WorldPose, road: RoadMap | None) -> None:
        o = self.options
        provenance = Provenance(item.scene.frame_id if item.variant is None else self.recorded_frame, item.variant,
                                o.program_text, o.program_file)
        more = {"clip": item.clip.to_dict()} if item.clip is not None else None
        self.db.add(scenario_of(item.motion, item.name, world, road, provenance, more))

    def close(self) -> None:
        self.db.close()


class ScenarioNetTarget:
    name = "scenarionet"
    needs_road = False

    def owns(self, entry: os.DirEntry) -> bool:
        name = entry.name
        return name in (SUMMARY, MAPPING) or (name.startswith(f"sd_{DATASET}_") and name.endswith(".pkl"))

    def open(self, folder: Path, recorded: Scene, options) -> _Writer:
        return _Writer(folder, recorded.frame_id, options)


TARGET = ScenarioNetTarget()
