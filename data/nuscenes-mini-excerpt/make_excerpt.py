"""Rebuild this excerpt from ../shared/data/nuscenes-mini (see NOTICE). Run from the repository root:

    .venv/bin/python data/nuscenes-mini-excerpt/make_excerpt.py

scenarionet/: the first keyframes of three scenes, cut from the real ScenarioNet pickles (all tracks valid in
the window, every state value unchanged; map features near the ego kept, see `near`), with the
dataset_summary.pkl / dataset_mapping.pkl of a ScenarioNet database.
v1.0-mini/: the 13 nuScenes JSON tables for the same keyframes, built from the same real values (positions,
yaws, sizes, categories, instance and scene tokens, map names); see NOTICE for the fields that are filled in.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import pickle
import shutil
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path.insert(0, str(ROOT))
from extractors.safe_pickle import load_pickle  # noqa: E402

SHARED = Path(os.environ.get("R2S_SHARED", ROOT.parent / "shared")) / "data" / "nuscenes-mini" / "scenarionet"
KEEP = {"scene-0103": 4, "scene-0796": 3, "scene-0061": 2}  # scene -> number of leading keyframes
STEP = 5
MAP_RADIUS = 60.0  # metres around the ego: r2s extract's default radius (50 m) and a margin
VERSION = "v1.0-mini"


def token(*parts: object) -> str:
    return hashlib.md5("/".join(map(str, parts)).encode()).hexdigest()


def trim(sd: dict, keyframes: int) -> dict:
    steps = STEP * (keyframes - 1) + 1
    tracks = {}
    for tid, tr in sd["tracks"].items():
        state = {k: np.asarray(v)[:steps].copy() for k, v in tr["state"].items()}
        if (state["valid"] > 0).any():
            tracks[tid] = {**tr, "state": state, "metadata": {**tr["metadata"], "track_length": steps}}
    meta = dict(sd["metadata"])
    meta["ts"] = np.asarray(meta["ts"])[:steps].copy()
    meta["object_summary"] = {k: v for k, v in meta.get("object_summary", {}).items() if k in tracks}
    meta.pop("number_summary", None)
    ego = np.asarray(sd["tracks"][meta["sdc_id"]]["state"]["position"])[:steps, :2]
    return {**sd, "length": steps, "metadata": meta, "tracks": tracks, "map_features": near(sd["map_features"], ego),
            "dynamic_map_states": {}}


def near(features: dict, ego: np.ndarray) -> dict:
    """The map features with a vertex within MAP_RADIUS of an ego position of the window, unchanged, except that
    a road line keeps only the stretch from the vertex before its first to the vertex after its last within that
    distance (the converter's road lines are the whole boundary of the drivable area, thousands of points)."""
    kept = {}
    for fid, f in features.items():
        pts = np.asarray(f.get("polygon", f.get("polyline")))[:, :2]
        close = np.flatnonzero((np.hypot(pts[:, None, 0] - ego[None, :, 0], pts[:, None, 1] - ego[None, :, 1])
                                <= MAP_RADIUS).any(axis=1))
        if not len(close):
            continue
        if f["type"].startswith("ROAD_LINE") and "polygon" not in f:
            f = {**f, "polyline": np.asarray(f["polyline"])[max(close[0] - 1, 0):close[-1] + 2].copy()}
        kept[fid] = f
    return kept


def quat(yaw: float) -> list[float]:
    return [math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)]


def nuscenes_tables(scenarios: list[dict]) -> dict[str, list[dict]]:
    t: dict[str, list[dict]] = {k: [] for k in (
        "attribute", "calibrated_sensor", "category", "ego_pose", "instance", "log", "map", "sample",
        "sample_annotation", "sample_data", "scene", "sensor", "visibility")}
    t["visibility"] = [{"token": str(i), "level": lvl, "description": f"visibility of whole object is {lvl}"}
                       for i, lvl in enumerate(["v0-40", "v40-60", "v60-80", "v80-100"], start=1)]
    t["sensor"] = [{"token": token("sensor", "LIDAR_TOP"), "channel": "LIDAR_TOP", "modality": "lidar"}]
    categories: dict[str, str] = {}
    maps: dict[str, list[str]] = {}
    for sd in scenarios:
        meta, name = sd["metadata"], sd["metadata"]["scenario_id"]
        log_tok = token("log", name)
        t["log"].append({"token": log_tok, "logfile": "", "vehicle": "", "date_captured": meta["date"],
                         "location": meta["map"]})
        maps.setdefault(meta["map"], []).append(log_tok)
        cs_tok = token("calibrated_sensor", name)
        t["calibrated_sensor"].append({"token": cs_tok, "sensor_token": t["sensor"][0]["token"],
                                       "translation": [0.0, 0.0, 0.0], "rotation": [1.0, 0.0, 0.0, 0.0],
                                       "camera_intrinsic": []})
        keyframes = range(0, sd["length"], STEP)
        samples = [token("sample", name, k) for k in range(len(keyframes))]
        ego = sd["tracks"][meta["sdc_id"]]["state"]
        anns_of: dict[str, list[dict]] = {}
        for k, step in enumerate(keyframes):
            ts = int(round(float(meta["ts"][step]) * 1e6))
            t["sample"].append({"token": samples[k], "timestamp": ts, "scene_token": meta["scenario_token"],
                                "prev": samples[k - 1] if k else "",
                                "next": samples[k + 1] if k + 1 < len(samples) else ""})
            pose_tok = token("ego_pose", name, k)
            t["ego_pose"].append({"token": pose_tok, "timestamp": ts,
                                  "translation": [float(ego["position"][step][0]), float(ego["position"][step][1]),
                                                  0.0],
                                  "rotation": quat(float(ego["heading"][step]))})
            sd_tok = token("sample_data", name, k)
            t["sample_data"].append({
                "token": sd_tok, "sample_token": samples[k], "ego_pose_token": pose_tok,
                "calibrated_sensor_token": cs_tok, "timestamp": ts, "fileformat": "pcd", "is_key_frame": True,
                "height": 0, "width": 0, "filename": f"samples/LIDAR_TOP/{name}_{k}.pcd.bin",
                "prev": token("sample_data", name, k - 1) if k else "",
                "next": token("sample_data", name, k + 1) if k + 1 < len(samples) else ""})
            for tid, tr in sd["tracks"].items():
                st = tr["state"]
                if tid == meta["sdc_id"] or not st["valid"][step] > 0:
                    continue
                cat = tr["metadata"]["type"]
                categories.setdefault(cat, token("category", cat))
                p = st["position"][step]
                anns_of.setdefault(tid, []).append({
                    "token": token("sample_annotation", name, tid, k), "sample_token": samples[k],
                    "instance_token": tid, "visibility_token": "4", "attribute_tokens": [],
                    "translation": [float(p[0]), float(p[1]), float(p[2])],
                    "size": [float(st["width"][step][0]), float(st["length"][step][0]),
                             float(st["height"][step][0])],
                    "rotation": quat(float(st["heading"][step])), "num_lidar_pts": 1, "num_radar_pts": 0})
        for tid, anns in anns_of.items():
            for i, a in enumerate(anns):
                a["prev"] = anns[i - 1]["token"] if i else ""
                a["next"] = anns[i + 1]["token"] if i + 1 < len(anns) else ""
            t["sample_annotation"].extend(anns)
            cat = sd["tracks"][tid]["metadata"]["type"]
            t["instance"].append({"token": tid, "category_token": categories[cat], "nbr_annotations": len(anns),
                                  "first_annotation_token": anns[0]["token"],
                                  "last_annotation_token": anns[-1]["token"]})
        t["scene"].append({"token": meta["scenario_token"], "log_token": log_tok, "nbr_samples": len(samples),
                           "first_sample_token": samples[0], "last_sample_token": samples[-1], "name": name,
                           "description": "excerpt"})
    t["category"] = [{"token": tok, "name": cat, "description": ""} for cat, tok in sorted(categories.items())]
    t["map"] = [{"token": token("map", m), "category": "semantic_prior", "filename": f"maps/{token('map', m)}.png",
                 "log_tokens": logs} for m, logs in sorted(maps.items())]
    return t


def main() -> None:
    out_sn = HERE / "scenarionet"
    shutil.rmtree(out_sn, ignore_errors=True)
    out_sn.mkdir(parents=True)
    scenarios, summary = [], {}
    for scene, n in KEEP.items():
        src = SHARED / f"sd_nuscenes_{VERSION}_{scene}.pkl"
        sd = trim(load_pickle(src), n)
        scenarios.append(sd)
        with open(out_sn / src.name, "wb") as fh:
            pickle.dump(sd, fh, protocol=4)
        summary[src.name] = sd["metadata"]
    with open(out_sn / "dataset_summary.pkl", "wb") as fh:
        pickle.dump(summary, fh, protocol=4)
    with open(out_sn / "dataset_mapping.pkl", "wb") as fh:
        pickle.dump({name: "" for name in summary}, fh, protocol=4)

    tables = nuscenes_tables(scenarios)
    shutil.rmtree(HERE / VERSION, ignore_errors=True)
    (HERE / VERSION).mkdir()
    for name, rows in tables.items():
        (HERE / VERSION / f"{name}.json").write_text(json.dumps(rows, indent=0) + "\n")
    # nuscenes-devkit asserts that map masks exist; the excerpt ships empty placeholders (never read).
    (HERE / "maps").mkdir(exist_ok=True)
    for m in tables["map"]:
        (HERE / m["filename"]).write_bytes(b"")
    print(f"wrote {out_sn} and {HERE / VERSION}")


if __name__ == "__main__":
    main()
