"""Real nuScenes-mini keyframes as scenes, straight from ../shared/data/nuscenes-mini/keyframes.csv.

Benchmarks use this so they do not depend on the extractors; the extractors' own tests check that they give
the same boxes. Each keyframe becomes one scene in the ego frame (+x right, +y forward, heading CCW from +y).
"""

from __future__ import annotations

import math
import os
from pathlib import Path

from synth.scene import Scene, scene_from_dict

SHARED = Path(os.environ.get("R2S_SHARED", Path(__file__).resolve().parents[2] / "shared"))
KEYFRAMES = SHARED / "data" / "nuscenes-mini" / "keyframes.csv"

_TYPES = {
    "vehicle.car": "Car", "vehicle.truck": "Truck", "vehicle.bus.rigid": "Bus", "vehicle.bus.bendy": "Bus",
    "vehicle.trailer": "Trailer", "vehicle.construction": "ConstructionVehicle", "vehicle.motorcycle": "Motorcycle",
    "vehicle.bicycle": "Bicycle", "vehicle.emergency.ambulance": "EmergencyVehicle",
    "vehicle.emergency.police": "EmergencyVehicle", "movable_object.barrier": "Barrier",
    "movable_object.trafficcone": "TrafficCone", "animal": "Animal",
}
VEHICLES = {"Car", "Truck", "Bus", "Trailer", "ConstructionVehicle", "Motorcycle", "Bicycle", "EmergencyVehicle"}


def scenic_type(category: str) -> str:
    if category.startswith("human.pedestrian"):
        return "Pedestrian"
    return _TYPES.get(category, "Object")


def available() -> bool:
    return KEYFRAMES.exists()


def keyframe_scenes(radius: float = 50.0, vehicles_only: bool = False) -> list[Scene]:
    """Every keyframe as a scene: entities within `radius` m of ego, ids by distance (car1, pedestrian2, ...)."""
    import pandas as pd

    df = pd.read_csv(KEYFRAMES)
    scenes = []
    for (name, k), g in df.groupby(["scene_name", "sample_index"], sort=True):
        ex, ey, eyaw = (float(g[c].iloc[0]) for c in ("ego_x", "ego_y", "ego_yaw"))
        c, s = math.cos(math.pi / 2 - eyaw), math.sin(math.pi / 2 - eyaw)
        ents = []
        for r in g.itertuples(index=False):
            if r.category_name == "vehicle.ego":
                continue
            t = scenic_type(r.category_name)
            if vehicles_only and t not in VEHICLES:
                continue
            dx, dy = r.x - ex, r.y - ey
            x, y = c * dx - s * dy, s * dx + c * dy
            if math.hypot(x, y) > radius:
                continue
            ents.append((math.hypot(x, y), t, x, y, math.degrees(r.yaw - eyaw) % 360.0, r.length, r.width))
        ents.sort(key=lambda e: e[0])
        entities = [{"id": "ego", "type": "Car", "x": 0.0, "y": 0.0, "heading": 0.0, "length": 4.08, "width": 1.73}]
        for i, (_, t, x, y, h, length, width) in enumerate(ents, start=1):
            entities.append({"id": f"{t.lower()}{i}", "type": t, "x": x, "y": y, "heading": h,
                             "length": length, "width": width})
        scenes.append(scene_from_dict({"frame_id": f"{name}/{int(k)}", "entities": entities}))
    return scenes
