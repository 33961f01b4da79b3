"""Source name -> extractor module. Modules are imported only when their source is asked for, so the heavy
optional readers (nuscenes-devkit, mcap, rosbags) cost nothing to the other sources."""

from __future__ import annotations

import importlib
from types import ModuleType

SOURCES: dict[str, str] = {
    "nuscenes": "extractors.nuscenes",
    "scenarionet": "extractors.scenarionet",
    "argoverse2": "extractors.argoverse2",
    "mcap": "extractors.mcap",
    "rosbag": "extractors.rosbag",
}


def source_module(name: str) -> ModuleType:
    """The module of a source; it has DESCRIPTION and extract(input_path, options) -> Iterator[rows]."""
    if name not in SOURCES:
        raise KeyError(f"unknown source {name!r} (sources: {', '.join(SOURCES)})")
    return importlib.import_module(SOURCES[name])
