"""nuScenes annotations (the 13 JSON tables, through nuscenes-devkit) as frames.

One frame per sample (2 Hz keyframe), frame_id `<scene name>/<0-based sample index>`. The ego pose is the
LIDAR_TOP sample_data's ego_pose (the pose the annotations were made against); each sample_annotation's
translation and rotation yaw go into the ego frame. Speeds: the devkit's annotation velocity (box_velocity: a
centred difference over the neighbouring annotations of the instance; null where it gives NaN) and, for the
ego, the same rule over the neighbouring samples' ego poses. Optional filters: visibility level and lidar points.
Only the JSON tables are read: no sensor files, and map masks named in map.json may be missing.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import math
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from extractors.base import (
    ExtractError,
    ExtractOptions,
    ExtractTally,
    FrameBuilder,
    Look,
    MapSink,
    RecordedObject,
    Source,
    comma_list,
    global_to_ego,
    quaternion_yaw,
    require_path,
)
from extractors.categories import Taxonomy
from storage.regular_files import check_regular

DESCRIPTION = "nuScenes dataroot (JSON tables of --version) through nuscenes-devkit"
# nuScenes v1.0 category names (23 classes), and the name of the ego vehicle.
TAXONOMY = Taxonomy("nuscenes", {
    "animal": "Animal",
    "human.pedestrian.adult": "Pedestrian",
    "human.pedestrian.child": "Pedestrian",
    "human.pedestrian.construction_worker": "Pedestrian",
    "human.pedestrian.personal_mobility": "Pedestrian",
    "human.pedestrian.police_officer": "Pedestrian",
    "human.pedestrian.stroller": "Pedestrian",
    "human.pedestrian.wheelchair": "Pedestrian",
    "movable_object.barrier": "Barrier",
    "movable_object.debris": "Debris",
    "movable_object.pushable_pullable": "PushableObject",
    "movable_object.trafficcone": "TrafficCone",
    "static_object.bicycle_rack": "BicycleRack",
    "vehicle.bicycle": "Bicycle",
    "vehicle.bus.bendy": "Bus",
    "vehicle.bus.rigid": "Bus",
    "vehicle.car": "Car",
    "vehicle.construction": "ConstructionVehicle",
    "vehicle.emergency.ambulance": "EmergencyVehicle",
    "vehicle.emergency.police": "EmergencyVehicle",
    "vehicle.motorcycle": "Motorcycle",
    "vehicle.trailer": "Trailer",
    "vehicle.truck": "Truck",
    "vehicle.ego": "Car",
})
EGO_CATEGORY = "vehicle.ego"


@dataclass(frozen=True)
class NuScenesOptions(ExtractOptions):
    version: str = "v1.0-mini"
    scenes: tuple[str, ...] = ()
    min_visibility: int = 0
    min_lidar_pts: int = 0

    @classmethod
    def add_options(cls, g: argparse._ArgumentGroup) -> None:
        g.add_argument("--version", default="v1.0-mini", help="nuScenes version folder (v1.0-mini, v1.0-trainval, ...)")
        g.add_argument("--scenes", type=comma_list, default=(), metavar="S,...",
                       help="only these scene names (default: all)")
        g.add_argument("--min-visibility", type=int, default=0, metavar="V",
                       help="keep annotations with visibility level >= V (1-4; 0 keeps all)")
        g.add_argument("--min-lidar-pts", type=int, default=0, metavar="N",
                       help="keep annotations with >= N lidar points")

    @classmethod
    def options_from(cls, args: argparse.Namespace, **common: Any) -> NuScenesOptions:
        return cls(version=args.version, scenes=args.scenes, min_visibility=args.min_visibility,
                   min_lidar_pts=args.min_lidar_pts, **common)


class _AbsentMapMask:
    """Stands in for nuscenes-devkit's MapMask, which asserts that the mask PNG exists; frames never use it."""

    def __init__(self, img_file: str, resolution: float = 0.1) -> None:
        self.img_file = img_file
        self.resolution = resolution


def load(dataroot: Path, version: str) -> Any:
    """nuscenes-devkit's NuScenes on the tables alone; every failure is one ExtractError."""
    if not dataroot.is_dir():
        raise ExtractError(f"nuScenes dataroot {dataroot} is not a directory")
    if not (dataroot / version).is_dir():
        found = sorted(p.name for p in dataroot.iterdir() if p.is_dir() and (p / "sample.json").is_file())
        raise ExtractError(
            f"{dataroot} has no nuScenes tables for version {version!r}"
            + (f" (versions here: {', '.join(found)})" if found else " (no version folder with sample.json)")
        )
    for table in sorted((dataroot / version).glob("*.json")):  # the devkit reads each whole: regular files only
        try:
            check_regular(table)
        except OSError as exc:
            raise ExtractError(f"{table} {exc.strerror}") from None
    try:
        import nuscenes.nuscenes as devkit
    except ImportError:
        raise ExtractError("the nuscenes source needs nuscenes-devkit (pip install 'r2sgen[nuscenes]')") from None
    original = devkit.MapMask
    devkit.MapMask = _AbsentMapMask
    try:
        with contextlib.redirect_stdout(io.StringIO()):  # the devkit prints while it loads
            return devkit.NuScenes(version=version, dataroot=str(dataroot), verbose=False)
    except Exception as exc:  # missing / corrupt / inconsistent tables surface as many exception types
        raise ExtractError(
            f"{dataroot}/{version}: not a loadable nuScenes table set ({type(exc).__name__}: {str(exc)[:120]})"
        ) from None
    finally:
        devkit.MapMask = original


def extract(input_path: str, options: NuScenesOptions, tally: ExtractTally | None = None,
            maps: MapSink | None = None) -> Iterator[list[dict[str, Any]]]:
    """Frames without maps (this source's recordings carry none): `maps` is never called."""
    nusc = load(require_path(input_path, "nuScenes dataroot"), options.version)
    scenes = list(nusc.scene)
    if options.scenes:
        names = {s["name"] for s in scenes}
        unknown = [s for s in options.scenes if s not in names]
        if unknown:
            raise ExtractError(f"{input_path} {options.version} has no scene {unknown[0]!r}")
        scenes = [s for s in scenes if s["name"] in options.scenes]
    builder = FrameBuilder("nuscenes", TAXONOMY, options, tally)
    for scene in scenes:
        try:
            yield from _scene_frames(nusc, scene, builder, options)
        except KeyError as exc:
            raise ExtractError(f"{input_path} {options.version}: scene {scene['name']} refers to a missing "
                               f"record {exc}") from None
        except (TypeError, ValueError, IndexError) as exc:
            raise ExtractError(f"{input_path} {options.version}: scene {scene['name']} has a malformed record "
                               f"({type(exc).__name__}: {str(exc)[:100]})") from None


def _scene_frames(nusc: Any, scene: dict, builder: FrameBuilder, options: NuScenesOptions) -> Iterator[list[dict]]:
    token, index, seen = scene["first_sample_token"], 0, set()
    while token and token not in seen:
        seen.add(token)
        sample = nusc.get("sample", token)
        if index % options.every == 0:
            yield _sample_frame(nusc, scene["name"], index, sample, builder, options)
        token, index = sample["next"], index + 1


def _sample_frame(nusc: Any, scene: str, index: int, sample: dict, builder: FrameBuilder,
                  options: NuScenesOptions) -> list[dict]:
    pose = _ego_pose(nusc, sample, f"sample {index} of {scene}")
    ego_yaw = float(quaternion_yaw(*pose["rotation"]))
    anns = [nusc.get("sample_annotation", t) for t in sample["anns"]]
    anns = [
        a for a in anns
        if int(a.get("num_lidar_pts", 0)) >= options.min_lidar_pts
        and (options.min_visibility <= 0 or int(a.get("visibility_token") or 0) >= options.min_visibility)
    ]
    x, y, h = global_to_ego(
        pose["translation"][0], pose["translation"][1], ego_yaw,
        [a["translation"][0] for a in anns], [a["translation"][1] for a in anns],
        [float(quaternion_yaw(*a["rotation"])) for a in anns],
    )
    # nuScenes sizes are [width, length, height]
    # world: the global frame's centre and yaw, which the frames keep (map_x, map_y, map_heading)
    boxes = [RecordedObject(a["instance_token"], a["category_name"], float(x[i]), float(y[i]), float(h[i]),
                            a["size"][1], a["size"][0], speed=_ground_speed(nusc.box_velocity(a["token"])),
                            world=(float(a["translation"][0]), float(a["translation"][1]),
                                   float(quaternion_yaw(*a["rotation"]))))
             for i, a in enumerate(anns)]
    ego = RecordedObject("ego", EGO_CATEGORY, 0.0, 0.0, 0.0, speed=_ground_speed(ego_velocity(nusc, sample)),
                         world=(float(pose["translation"][0]), float(pose["translation"][1]), ego_yaw))
    return builder.frame(scene, index, int(sample["timestamp"]), ego, boxes)


def _ego_pose(nusc: Any, sample: dict, where: str) -> dict:
    if "LIDAR_TOP" not in sample["data"]:
        raise ExtractError(f"{where} has no LIDAR_TOP sample_data (needed for the ego pose)")
    return nusc.get("ego_pose", nusc.get("sample_data", sample["data"]["LIDAR_TOP"])["ego_pose_token"])


def _ground_speed(v: Any) -> float | None:
    """|(vx, vy)| of a devkit velocity; None where the devkit gives NaN (no neighbour close enough)."""
    s = math.hypot(float(v[0]), float(v[1]))
    return s if math.isfinite(s) else None


def ego_velocity(nusc: Any, sample: dict, max_time_diff: float = 1.5) -> np.ndarray:
    """The ego's velocity at a sample, by the devkit's own rule for annotations (NuScenes.box_velocity): the
    centred difference of the LIDAR_TOP ego poses of the previous and next samples (up to 2 max_time_diff
    apart), else the one-sided difference with the one that exists (up to max_time_diff), else NaN."""
    first = nusc.get("sample", sample["prev"]) if sample["prev"] else sample
    last = nusc.get("sample", sample["next"]) if sample["next"] else sample
    if first is last:
        return np.full(3, np.nan)
    p0 = np.array(_ego_pose(nusc, first, "a neighbouring sample")["translation"], dtype=float)
    p1 = np.array(_ego_pose(nusc, last, "a neighbouring sample")["translation"], dtype=float)
    dt = 1e-6 * (last["timestamp"] - first["timestamp"])
    if sample["prev"] and sample["next"]:
        max_time_diff *= 2
    if not 0 < dt <= max_time_diff:
        return np.full(3, np.nan)
    return (p1 - p0) / dt


class NuScenes(Source):
    name = "nuscenes"
    description = DESCRIPTION
    input_help = "dataroot"
    taxonomy = TAXONOMY
    options = NuScenesOptions
    extract = staticmethod(extract)

    def look_at_file(self, path: Path, head: bytes) -> Look | None:
        if path.suffix == ".json" and path.parent.name.startswith("v1.0-") and (path.parent / "sample.json").is_file():
            return Look(self.name, f"a nuScenes table ({path.parent.name}/{path.name})", str(path.parent.parent))
        return None

    def look_at_entry(self, top: str, path: Path, is_dir: bool, depth: int) -> Look | None:
        if is_dir and path.name.startswith("v1.0-") and (path / "sample.json").is_file():
            where = top if depth == 0 else str(path.parent)
            return Look(self.name, f"a nuScenes dataroot ({path.name}/ with JSON tables)", where)
        return None


SOURCE = NuScenes()
