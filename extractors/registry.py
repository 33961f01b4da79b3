"""Source name -> the module that holds it (its Source subclass and SOURCE, its instance). Modules are imported
only when a source is asked for, so the heavy optional readers (nuscenes-devkit, mcap, rosbags) cost nothing
until then. A new source is a module plus its line here (docs/layout.md, "Add a source")."""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from extractors.base import Source

SOURCES: dict[str, str] = {
    "nuscenes": "extractors.nuscenes",
    "scenarionet": "extractors.scenarionet",
    "argoverse2": "extractors.argoverse2",
    "mcap": "extractors.mcap",
    "rosbag": "extractors.rosbag",
}


def source(name: str) -> Source:
    """The source of this name (KeyError naming the known ones if there is none)."""
    if name not in SOURCES:
        raise KeyError(f"unknown source {name!r} (sources: {', '.join(SOURCES)})")
    found = importlib.import_module(SOURCES[name]).SOURCE
    if found.name != name:
        raise KeyError(f"{SOURCES[name]}.SOURCE is named {found.name!r}, not {name!r} as registry.SOURCES says")
    return found


def sources() -> list[Source]:
    """Every source, in the order of SOURCES."""
    return [source(name) for name in SOURCES]
