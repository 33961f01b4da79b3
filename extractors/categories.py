"""How dataset categories become Scenic classes (synth.scene.ENTITY_TYPES), and what `--categories` keeps.

Each source declares the Taxonomy of its raw categories in its own module (extractors.nuscenes, .argoverse2,
.scenarionet; extractors.messages for the logs of mcap and rosbag) and every extractor resolves a raw category
through `taxonomy.scenic_class(raw)`. A category no map knows is
never guessed at: it is typed UNKNOWN_CLASS (Object, the generic class) and kept under `--categories all` (or a
list naming Object), left out under `vehicles`, and counted by name in the summary line of `r2s extract`
either way. ScenarioNet tracks whose own type is unknown are typed by their MetaDrive type first (see
extractors.base.FrameBuilder.classify). A `--categories` item must be a name some map or class knows
(`CategorySelection.parse`), so a typo is an error (exit 2) instead of an empty selection.

Choices that are judgement calls, so they are written down: every `human.*` is a Pedestrian (strollers and
wheelchairs move with people); cyclists and motorcyclists are Bicycle / Motorcycle (the rider and the vehicle
are one box); bollards and construction barrels are Barriers; signs and unspecified objects are Object.
"""

from __future__ import annotations

import difflib
from collections.abc import Mapping
from dataclasses import dataclass, field

# --categories vehicles keeps VEHICLE_CLASSES (defined beside the entity types, since patterns use them too).
from synth.scene import ENTITY_TYPES, VEHICLE_CLASSES

# A category no map knows becomes this (the generic Scenic class), counted in the extract summary.
UNKNOWN_CLASS = "Object"
assert VEHICLE_CLASSES <= set(ENTITY_TYPES) and UNKNOWN_CLASS in ENTITY_TYPES


@dataclass(frozen=True)
class Taxonomy:
    """The raw categories of a dataset and the Scenic class of each; a source declares its own (its module)."""

    name: str
    classes: Mapping[str, str] = field(hash=False)  # raw category -> Scenic class

    def __post_init__(self) -> None:
        # every map must land in the synthesizer's closed set of classes
        wrong = sorted({c for c in self.classes.values() if c not in ENTITY_TYPES})
        if wrong:
            raise ValueError(f"taxonomy {self.name}: {', '.join(wrong)} are not entity types")

    def scenic_class(self, raw: str) -> str | None:
        """The Scenic class of a raw category, or None if this taxonomy does not know it."""
        return self.classes.get(raw)

    def raw_names(self) -> frozenset[str]:
        """The raw categories and their dotted prefixes ("vehicle", "vehicle.bus", ...)."""
        names = set(self.classes)
        for name in self.classes:
            parts = name.split(".")
            names.update(".".join(parts[:i]) for i in range(1, len(parts)))
        return frozenset(names)


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
    def parse(text: str, taxonomy: Taxonomy | None = None) -> CategorySelection:
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
            known = taxonomy.raw_names()
            for item in raw:
                if item not in known:
                    raise ValueError(_unknown_item(item, taxonomy))
        return CategorySelection("list", classes, raw)

    def _names_raw(self, raw: str) -> bool:
        return any(raw == r or raw.startswith(r + ".") for r in self.raw)

    def select(self, taxonomy: Taxonomy, raw: str) -> str | None:
        """The Scenic class to give an entity of this raw category, or None to leave it out."""
        cls = taxonomy.scenic_class(raw) or UNKNOWN_CLASS
        if self.mode == "all":
            return cls
        if self.mode == "vehicles":
            return cls if cls in VEHICLE_CLASSES else None
        return cls if cls in self.classes or self._names_raw(raw) else None


def _unknown_item(item: str, taxonomy: Taxonomy) -> str:
    classes = sorted(ENTITY_TYPES)
    raw = sorted(taxonomy.classes)
    # closest by spelling, ignoring case; a class wins over a raw name that differs from it only in case
    candidates = {n.lower(): n for n in [*taxonomy.raw_names(), "vehicles", "all", *classes]}
    best = difflib.get_close_matches(item.lower(), list(candidates), n=1, cutoff=0.0)
    closest = f"closest: {candidates[best[0]]!r}; " if best else ""
    prefixes = " (or a dotted prefix of one)" if any("." in r for r in raw) else ""
    return (f"unknown category {item!r} in --categories; {closest}known: vehicles, all, the classes "
            f"{', '.join(classes)}, and the {taxonomy.name} categories {', '.join(raw)}{prefixes}")


VEHICLES = CategorySelection("vehicles")
ALL = CategorySelection("all")
