"""The one place where dataset categories become Scenic classes (synth.scene.ENTITY_TYPES).

Every extractor resolves a raw category through `scenic_class(taxonomy, raw)`; a category no map knows is an
error (exit 2) unless the user selects categories explicitly with `--categories LIST`, because silently
guessing would put wrong types into programs.

Taxonomies:
- "nuscenes": nuScenes v1.0 category names (23 classes, also nuScenes-derived ScenarioNet `metadata.type`).
- "argoverse2": Argoverse 2 sensor-dataset annotation categories (30 classes).
- "scenarionet": ScenarioNet / MetaDrive object types, the common denominator its converters write for
  Waymo, nuPlan, Lyft, Argoverse and nuScenes (VEHICLE, PEDESTRIAN, CYCLIST, ...), plus the raw nuPlan and Lyft
  type names that appear in converted `metadata.type`.
- "logs": MCAP / ROS bag annotations: any of the above, or a Scenic class name itself.

Choices that are judgement calls, so they are written down: every `human.*` is a Pedestrian (strollers and
wheelchairs move with people); cyclists and motorcyclists are Bicycle / Motorcycle (the rider and the vehicle
are one box); bollards and construction barrels are Barriers; signs and unspecified objects are Object.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from synth.scene import ENTITY_TYPES

# --categories vehicles keeps these classes.
VEHICLE_CLASSES = frozenset(
    {"Car", "Truck", "Bus", "Motorcycle", "Bicycle", "Trailer", "ConstructionVehicle", "EmergencyVehicle"}
)

NUSCENES: Mapping[str, str] = {
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
}

ARGOVERSE2: Mapping[str, str] = {
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
}

SCENARIONET: Mapping[str, str] = {
    # MetaDrive / ScenarioNet object types (scenarionet converters, all datasets)
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
}

# Robotics logs (MCAP, ROS bags) carry whatever category strings their writer chose: nuScenes names (the
# nuScenes-to-MCAP converters), Argoverse / ScenarioNet names, or the Scenic class itself.
LOGS: Mapping[str, str] = {**SCENARIONET, **ARGOVERSE2, **NUSCENES, **{c: c for c in ENTITY_TYPES}}

TAXONOMIES: Mapping[str, Mapping[str, str]] = {
    "nuscenes": NUSCENES,
    "argoverse2": ARGOVERSE2,
    "scenarionet": SCENARIONET,
    "logs": LOGS,
}

# Every map must land in the synthesizer's closed set of classes.
assert all(c in ENTITY_TYPES for m in TAXONOMIES.values() for c in m.values())
assert VEHICLE_CLASSES <= set(ENTITY_TYPES)


def scenic_class(taxonomy: str, raw: str) -> str | None:
    """The Scenic class of a raw category, or None if this taxonomy does not know it."""
    return TAXONOMIES[taxonomy].get(raw)


@dataclass(frozen=True)
class CategorySelection:
    """What `--categories` keeps: "vehicles", "all", or an explicit list of Scenic classes and raw categories.

    A raw item also selects its dotted sub-categories ("human.pedestrian" keeps "human.pedestrian.adult").
    Only an explicit list may keep a category no map knows (it becomes an Object); under "vehicles" and "all"
    an unknown category is an error, since whether it is a vehicle cannot be told.
    """

    mode: str  # "vehicles" | "all" | "list"
    classes: frozenset[str] = frozenset()
    raw: tuple[str, ...] = ()

    @staticmethod
    def parse(text: str) -> CategorySelection:
        text = (text or "").strip()
        if text.lower() in ("vehicles", "all"):
            return CategorySelection(text.lower())
        items = [t.strip() for t in text.split(",") if t.strip()]
        if not items:
            raise ValueError("--categories needs 'vehicles', 'all' or a comma-separated list")
        by_lower = {c.lower(): c for c in ENTITY_TYPES}
        classes = frozenset(by_lower[t.lower()] for t in items if t.lower() in by_lower)
        raw = tuple(t for t in items if t.lower() not in by_lower)
        return CategorySelection("list", classes, raw)

    def _names_raw(self, raw: str) -> bool:
        return any(raw == r or raw.startswith(r + ".") for r in self.raw)

    def select(self, taxonomy: str, raw: str) -> str | None:
        """The Scenic class to give an entity of this raw category, or None to leave it out.

        Raises LookupError for a category no map knows, unless an explicit list decides it.
        """
        cls = scenic_class(taxonomy, raw)
        if self.mode == "list":
            if cls is not None and cls in self.classes:
                return cls
            if self._names_raw(raw):
                return cls or "Object"
            return None
        if cls is None:
            known = ", ".join(sorted(TAXONOMIES[taxonomy])[:6])
            raise LookupError(
                f"unknown {taxonomy} category {raw!r} (known: {known}, ...); "
                "name the categories to keep with --categories LIST"
            )
        if self.mode == "vehicles" and cls not in VEHICLE_CLASSES:
            return None
        return cls


VEHICLES = CategorySelection("vehicles")
ALL = CategorySelection("all")
