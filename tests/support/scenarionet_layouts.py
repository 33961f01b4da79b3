"""ScenarioNet databases laid out the way ScenarioNet's own tools write them, for the extractor tests.

Each function names the upstream function it mirrors (metadriverse/scenarionet at cebcbe6, metadriverse/metadrive
at 85e5dad); they are written here from reading those, with the same file names, mapping values and pickled
types, and a `protocol` where upstream calls pickle.dump with Python's default (4 up to Python 3.13, 5 from 3.14).
The scenarios themselves are real: nuScenes-mini scenarios as ScenarioNet converted them, and the same tracks
re-laid out as the Waymo / nuPlan / Argoverse 2 converters lay out theirs.
"""

from __future__ import annotations

import copy
import os
import pickle
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

SUMMARY, MAPPING = "dataset_summary.pkl", "dataset_mapping.pkl"


# --- metadrive/scenario/scenario_description.py ---------------------------------------------------------------

def export_file_name(dataset: str, version: str, scenario_id: str) -> str:
    """ScenarioDescription.get_export_file_name."""
    return f"sd_{dataset}_{version}_{scenario_id}.pkl"


def object_summary(track: dict, track_id: Any) -> dict:
    """ScenarioDescription.get_object_summary: moving distance over the valid steps, valid lengths."""
    state = track["state"]
    valid = np.asarray(state["valid"]).reshape(-1).astype(int)
    pos = np.asarray(state["position"])[np.where(valid)][..., :2]
    run = 0
    for v in valid:
        if v:
            run += 1
        if run > 0 and not v:
            break
    return {"type": track["type"], "object_id": str(track_id), "track_length": int(len(state["position"])),
            "moving_distance": float(np.linalg.norm(np.diff(pos, axis=0), axis=1).sum()),
            "valid_length": int(valid.sum()), "continuous_valid_length": int(run)}


def update_summaries(sd: dict) -> dict:
    """ScenarioDescription.update_summaries / get_number_summary / _calculate_num_moving_objects, in place:
    metadata.object_summary, and metadata.number_summary whose num_moving_objects_each_type is a
    collections.defaultdict(int) and whose object / traffic-light type fields are sets."""
    meta = sd["metadata"]
    meta["object_summary"] = {tid: object_summary(t, tid) for tid, t in sd["tracks"].items()}
    counts: defaultdict[str, int] = defaultdict(int)
    for t in sd["tracks"].values():
        counts[t["type"]] += 1
    moving: defaultdict[str, int] = defaultdict(int)
    for s in meta["object_summary"].values():
        if s["moving_distance"] > 1:
            moving[s["type"]] += 1
    light_states: defaultdict[str, int] = defaultdict(int)
    for light in sd.get("dynamic_map_states", {}).values():
        for step_state in light["state"]["object_state"]:
            if step_state is not None:
                light_states[step_state] += 1
    meta["number_summary"] = {
        "num_objects": len(sd["tracks"]),
        "object_types": {t["type"] for t in sd["tracks"].values()},
        "num_objects_each_type": dict(counts),
        "num_moving_objects": sum(moving.values()),
        "num_moving_objects_each_type": moving,
        "num_traffic_lights": len(sd.get("dynamic_map_states", {})),
        "num_traffic_light_types": set(light_states),
        "num_traffic_light_each_step": dict(light_states),
        "num_map_features": len(sd.get("map_features", {})),
        "map_height_diff": 0.0,
    }
    return sd


# --- scenarionet/common_utils.py --------------------------------------------------------------------------------

def remove_array_and_set(d: Any) -> Any:
    """dict_recursive_remove_array_and_set: arrays to lists, sets to tuples, in place through every dict
    (a defaultdict stays a defaultdict: only its values are replaced)."""
    if isinstance(d, np.ndarray):
        return d.tolist()
    if isinstance(d, set):
        return tuple(d)
    if isinstance(d, dict):
        for k in d.keys():
            d[k] = remove_array_and_set(d[k])
    return d


def save_summary_and_mapping(summary_path: Path, mapping_path: Path, summary: dict, mapping: dict,
                             protocol: int) -> None:
    """save_summary_and_mapping."""
    with open(summary_path, "wb") as fh:
        pickle.dump(remove_array_and_set(summary), fh, protocol=protocol)
    with open(mapping_path, "wb") as fh:
        pickle.dump(mapping, fh, protocol=protocol)


# --- scenarionet/converter/utils.py and scenarionet/builder/utils.py ----------------------------------------------

def write_single_worker(scenarios: list[dict], output_path: Path, dataset: str, version: str,
                        protocol: int = 4) -> Path:
    """write_to_directory_single_worker: each scenario (after update_summaries) to sd_<dataset>_<version>_<id>.pkl,
    summary[name] = deepcopy(metadata), mapping[name] = "" (the same folder), all written into
    <output>_tmp which is then renamed to <output>. A repeated name is overwritten (upstream only warns)."""
    tmp = Path(str(output_path) + "_tmp")
    tmp.mkdir(parents=True)
    summary, mapping = {}, {}
    for sd in scenarios:
        update_summaries(sd)
        name = export_file_name(dataset, version, sd["id"])
        summary[name] = copy.deepcopy(sd["metadata"])
        mapping[name] = ""
        with open(tmp / name, "wb") as fh:
            pickle.dump(dict(sd), fh, protocol=protocol)
    save_summary_and_mapping(tmp / SUMMARY, tmp / MAPPING, summary, mapping, protocol)
    os.rename(tmp, output_path)
    return output_path


def write_to_directory(scenarios: list[dict], output_path: Path, dataset: str, version: str, num_workers: int,
                       protocol: int = 4) -> list[Path]:
    """write_to_directory: the scenarios split into num_workers slices (the last takes the remainder), worker i
    writes the sub-database <output>/<basename>_<i>, then merge_database(<output>, *subdirs) makes <output> the
    top database whose mapping points into them ("db_0", "db_1", ...). Returns the worker folders."""
    output_path.mkdir(parents=True)
    if len(scenarios) < num_workers:
        num_workers = 1
    each = len(scenarios) // num_workers
    subdirs = []
    for i in range(num_workers):
        end = len(scenarios) if i == num_workers - 1 else (i + 1) * each
        sub = output_path / f"{output_path.name}_{i}"
        write_single_worker(scenarios[i * each:end], sub, dataset, version, protocol)
        subdirs.append(sub)
    merge_database(output_path, *subdirs, protocol=protocol)
    return subdirs


def merge_database(output_path: Path, *dataset_paths: Path, protocol: int = 4) -> tuple[dict, dict]:
    """merge_database (builder/utils.py): summaries.update() over the databases in order (a repeated file name
    keeps the later one; upstream logs "Repeat scenarios"), and each mapping value rewritten as
    os.path.relpath(os.path.join(<source dir>, <its value>), <output dir>)."""
    out = os.path.abspath(output_path)
    os.makedirs(out, exist_ok=True)
    summaries: dict = {}
    mappings: dict = {}
    for path in dataset_paths:
        src = os.path.abspath(path)
        with open(os.path.join(src, SUMMARY), "rb") as fh:
            summaries.update(pickle.load(fh))
        with open(os.path.join(src, MAPPING), "rb") as fh:
            mapping = pickle.load(fh)
        mappings.update({name: os.path.relpath(os.path.join(src, rel), out) for name, rel in mapping.items()})
    save_summary_and_mapping(Path(out) / SUMMARY, Path(out) / MAPPING, summaries, mappings, protocol)
    return summaries, mappings


# --- the converters' track layouts --------------------------------------------------------------------------------

# scenarionet/converter/waymo/type.py WaymoAgentType: the only object types the Waymo converter writes.
WAYMO_TYPES = ("VEHICLE", "PEDESTRIAN", "CYCLIST", "OTHER")


def as_waymo(sd: dict, ids_as_int: bool = False) -> dict:
    """A real scenario's tracks as scenarionet/converter/waymo/utils.py lays them out (extract_tracks,
    convert_waymo_scenario): float32 position (T, 3), heading, length, width, height (T,), velocity (T, 2),
    bool valid (T,), one of the four Waymo types (others become OTHER), string ids and sdc_id, dataset "waymo",
    float32 metadata.ts. With ids_as_int the ids are ints, as older converters and hand-made files have them."""
    steps = int(sd["length"])
    tracks = {}
    key = {tid: (i if ids_as_int else str(i)) for i, tid in enumerate(sd["tracks"])}
    for tid, tr in sd["tracks"].items():
        st = tr["state"]
        kind = tr["type"] if tr["type"] in WAYMO_TYPES else "OTHER"
        oid = key[tid]
        tracks[oid] = {
            "type": kind,
            "state": {
                "position": np.asarray(st["position"], dtype=np.float32).reshape(steps, -1)[:, :3],
                "length": np.asarray(st["length"], dtype=np.float32).reshape(steps),
                "width": np.asarray(st["width"], dtype=np.float32).reshape(steps),
                "height": np.asarray(st.get("height", st["length"]), dtype=np.float32).reshape(steps),
                "heading": np.asarray(st["heading"], dtype=np.float32).reshape(steps),
                "velocity": np.asarray(st["velocity"], dtype=np.float32).reshape(steps, 2),
                "valid": np.asarray(st["valid"]).reshape(steps) > 0,
            },
            "metadata": {"track_length": steps, "type": kind, "object_id": oid if ids_as_int else str(oid),
                         "dataset": "waymo"},
        }
    sdc = key[sd["metadata"]["sdc_id"]]
    sid = f"wm{sd['id'].replace('-', '')}"
    meta = {"id": sid, "coordinate": "waymo", "ts": np.arange(steps, dtype=np.float32) / 10,
            "metadrive_processed": False, "sdc_id": sdc, "dataset": "waymo", "scenario_id": sid,
            "source_file": "training_20s.tfrecord-00000-of-01000", "track_length": steps, "current_time_index": 10,
            "sdc_track_index": list(tracks).index(sdc), "objects_of_interest": [], "tracks_to_predict": {}}
    return {"id": sid, "version": "v1.2", "length": steps, "tracks": tracks, "dynamic_map_states": {},
            "map_features": {}, "metadata": meta}


def as_nuplan(sd: dict) -> dict:
    """scenarionet/converter/nuplan/utils.py extract_traffic: float64 arrays, valid as 0.0 / 1.0, length / width /
    height (T, 1), metadata.type the MetaDrive type and metadata.nuplan_type an int, sdc "ego", dataset "nuplan"."""
    steps = int(sd["length"])
    tracks = {}
    for tid, tr in sd["tracks"].items():
        st = tr["state"]
        oid = "ego" if tid == sd["metadata"]["sdc_id"] else str(tid)
        tracks[oid] = {
            "type": tr["type"],
            "state": {
                "position": np.asarray(st["position"], dtype=float).reshape(steps, -1)[:, :3],
                "heading": np.asarray(st["heading"], dtype=float).reshape(steps),
                "velocity": np.asarray(st["velocity"], dtype=float).reshape(steps, 2),
                "valid": (np.asarray(st["valid"]).reshape(steps) > 0).astype(float),
                "length": np.asarray(st["length"], dtype=float).reshape(steps, 1),
                "width": np.asarray(st["width"], dtype=float).reshape(steps, 1),
                "height": np.asarray(st.get("height", st["length"]), dtype=float).reshape(steps, 1),
            },
            "metadata": {"track_length": steps, "nuplan_type": 0, "type": tr["type"], "object_id": oid,
                         "nuplan_id": oid},
        }
    sid = f"np{sd['id'].replace('-', '')}"
    meta = {"dataset": "nuplan", "map": "us-nv-las-vegas-strip", "metadrive_processed": False,
            "coordinate": "right-handed", "scenario_token": sid, "scenario_id": sid, "id": sid,
            "scenario_type": "unknown", "sample_rate": 0.1, "ts": np.asarray([i * 0.1 for i in range(steps)]),
            "sdc_id": "ego"}
    return {"id": sid, "version": "nuplan_v1.1", "length": steps, "tracks": tracks, "dynamic_map_states": {},
            "map_features": {}, "metadata": meta}


# scenarionet/converter/argoverse2/utils.py: the estimated box sizes it writes for every step, by type
AV2_SIZES = {"VEHICLE": (4.0, 2.0), "CYCLIST": (2.0, 0.7), "PEDESTRIAN": (0.5, 0.5)}


def as_av2(sd: dict) -> dict:
    """scenarionet/converter/argoverse2/utils.py extract_tracks / convert_av2_scenario: float32 arrays, bool valid,
    types from type.py get_traffic_obj_type (VEHICLE / PEDESTRIAN / CYCLIST, anything else OTHER), the constant
    estimated length and width (1 x 1 for OTHER), position z = 0, the ego track "AV", dataset "av2", ts = steps / 10."""
    steps = int(sd["length"])
    tracks = {}
    for tid, tr in sd["tracks"].items():
        st = tr["state"]
        kind = tr["type"] if tr["type"] in AV2_SIZES else "OTHER"
        oid = "AV" if tid == sd["metadata"]["sdc_id"] else str(tid)
        length, width = AV2_SIZES.get(kind, (1.0, 1.0))
        pos = np.zeros((steps, 3), dtype=np.float32)
        pos[:, :2] = np.asarray(st["position"]).reshape(steps, -1)[:, :2]
        tracks[oid] = {
            "type": kind,
            "state": {"position": pos, "length": np.full(steps, length, dtype=np.float32),
                      "width": np.full(steps, width, dtype=np.float32), "height": np.ones(steps, dtype=np.float32),
                      "heading": np.asarray(st["heading"], dtype=np.float32).reshape(steps),
                      "velocity": np.asarray(st["velocity"], dtype=np.float32).reshape(steps, 2),
                      "valid": np.asarray(st["valid"]).reshape(steps) > 0},
            "metadata": {"track_length": steps, "type": kind, "object_id": oid, "dataset": "av2"},
        }
    sid = f"av{sd['id'].replace('-', '')}"
    meta = {"id": sid, "coordinate": "waymo", "ts": np.array(list(range(steps))) / 10, "metadrive_processed": False,
            "sdc_id": "AV", "dataset": "av2", "scenario_id": sid, "source_file": sid, "track_length": steps,
            "current_time_index": 49, "sdc_track_index": list(tracks).index("AV"), "objects_of_interest": [],
            "tracks_to_predict": {}}
    return {"id": sid, "version": "av2", "length": steps, "tracks": tracks, "dynamic_map_states": {},
            "map_features": {}, "metadata": meta}


def load_real(path: Path) -> dict:
    """A ScenarioNet pickle through the plain unpickler (the test's own files)."""
    with open(path, "rb") as fh:
        return pickle.load(fh)
