"""The one place where dataset categories become Scenic classes (synth.scene.ENTITY_TYPES).

Every extractor resolves a raw category through `scenic_class(taxonomy, raw)`. A category no map knows is
never guessed at: it is typed UNKNOWN_CLASS (Object, the generic class) and kept under `--categories all` (or a
list naming Object), left out under `vehicles`, and counted by name in the summary line of `r2s extract`
either way. ScenarioNet tracks whose own type is unknown are typed by their MetaDrive type first (see
extractors.base.FrameBuilder.classify). A `--categories` item must be a name some map or class knows
(`CategorySelection.parse`), so a typo is an error (exit 2) instead of an empty selection.

Taxonomies:
- "nuscenes": nuScenes v1.0 category names (23 classes).
- "argoverse2": Argoverse 2 sensor-dataset annotation categories (30 classes).
- "scenarionet": what ScenarioNet's converters (metadriverse/scenarionet, converter/*/utils.py and type.py)
  write: MetaDrive object types in every track's `type` (Waymo's VEHICLE / PEDESTRIAN / CYCLIST / OTHER, nuPlan's
  and Argoverse 2's mapped to those, TRAFFIC_CONE / TRAFFIC_BARRIER / TRAFFIC_OBJECT), and the dataset's own type
  in `metadata.type` where the converter keeps one: the nuScenes names (nuScenes converter), the Lyft names, and
  the raw nuPlan names of older conversions.
- "logs": MCAP / ROS bag annotations: any of the above, or a Scenic class name itself.

Choices that are judgement calls, so they are written down: every `human.*` is a Pedestrian (strollers and
wheelchairs move with people); cyclists and motorcyclists are Bicycle / Motorcycle (the rider and the vehicle
are one box); bollards and construction barrels are Barriers; signs and unspecified objects are Object.
"""

from __future__ import annotations

import difflib
from collections.abc import Mapping
from dataclasses import dataclass

# --categories vehicles keeps VEHICLE_CLASSES (defined beside the entity types, since patterns use them too).
from synth.scene import ENTITY_TYPES, VEHICLE_CLASSES

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
    **NUSCENES,
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

# A category no map knows becomes this (the generic Scenic class), counted in the extract summary.
UNKNOWN_CLASS = "Object"

# Every map must land in the synthesizer's closed set of classes.
assert all(c in ENTITY_TYPES for m in TAXONOMIES.values() for c in m.values())
assert VEHICLE_CLASSES <= set(ENTITY_TYPES) and UNKNOWN_CLASS in ENTITY_TYPES


def scenic_class(taxonomy: str, raw: str) -> str | None:
    """The Scenic class of a raw category, or None if this taxonomy does not know it."""
    return TAXONOMIES[taxonomy].get(raw)


@dataclass(frozen=True)
class CategorySelection:
    """What `--categories` keeps: "vehicles", "all", or an explicit list of Scenic classes and raw categories.

    A raw item also selects its dotted sub-categories ("human.pedestrian" keeps "human.pedestrian.adult").
    A category no map knows is an UNKNOWN_CLASS: kept by "all" and by a list naming that class.
    """

    mode: str  # "vehicles" | "all" | "list"
    classes: frozenset[str] = frozenset()
    raw: tuple[str, ...] = ()

    @staticmethod
    def parse(text: str, taxonomy: str | None = None) -> CategorySelection:
        """`--categories` text; with a taxonomy, every list item must be a Scenic class, a raw category of that
        taxonomy or a dotted prefix of one (ValueError naming the known names and the closest one otherwise)."""
        items = [t.strip() for t in (text or "").split(",") if t.strip()]
        if not items:
            raise ValueError("--categories needs 'vehicles', 'all' or a comma-separated list")
        if any(t.lower() == "all" for t in items):
            return ALL
        if [t.lower() for t in items] == ["vehicles"]:
            return VEHICLES
        by_lower = {c.lower(): c for c in ENTITY_TYPES}
        # "vehicles" in a list stands for the vehicle classes ("vehicles,Pedestrian")
        classes = frozenset(by_lower[t.lower()] for t in items if t.lower() in by_lower).union(
            *(VEHICLE_CLASSES for t in items if t.lower() == "vehicles"))
        raw = tuple(t for t in items if t.lower() not in by_lower and t.lower() != "vehicles")
        if taxonomy is not None:
            known = raw_names(taxonomy)
            for item in raw:
                if item not in known:
                    raise ValueError(_unknown_item(item, taxonomy))
        return CategorySelection("list", classes, raw)

    def _names_raw(self, raw: str) -> bool:
        return any(raw == r or raw.startswith(r + ".") for r in self.raw)

    def select(self, taxonomy: str, raw: str) -> str | None:
        """The Scenic class to give an entity of this raw category, or None to leave it out."""
        cls = scenic_class(taxonomy, raw) or UNKNOWN_CLASS
        if self.mode == "all":
            return cls
        if self.mode == "vehicles":
            return cls if cls in VEHICLE_CLASSES else None
        return cls if cls in self.classes or self._names_raw(raw) else None


def raw_names(taxonomy: str) -> frozenset[str]:
    """The raw categories of a taxonomy and their dotted prefixes ("vehicle", "vehicle.bus", ...)."""
    names = set(TAXONOMIES[taxonomy])
    for name in TAXONOMIES[taxonomy]:
        parts = name.split(".")
        names.update(".".join(parts[:i]) for i in range(1, len(parts)))
    return frozenset(names)


def _unknown_item(item: str, taxonomy: str) -> str:
    classes = sorted(ENTITY_TYPES)
    raw = sorted(TAXONOMIES[taxonomy])
    # closest by spelling, ignoring case; a class wins over a raw name that differs from it only in case
    candidates = {n.lower(): n for n in [*raw_names(taxonomy), "vehicles", "all", *classes]}
    best = difflib.get_close_matches(item.lower(), list(candidates), n=1, cutoff=0.0)
    closest = f"closest: {candidates[best[0]]!r}; " if best else ""
    prefixes = " (or a dotted prefix of one)" if any("." in r for r in raw) else ""
    return (f"unknown category {item!r} in --categories; {closest}known: vehicles, all, the classes "
            f"{', '.join(classes)}, and the {taxonomy} categories {', '.join(raw)}{prefixes}")


VEHICLES = CategorySelection("vehicles")
ALL = CategorySelection("all")
