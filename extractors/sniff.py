"""What an extractor input looks like, so that a wrong `r2s extract SOURCE` gets a line naming the right one.

Only consulted when the asked-for source found nothing it could read (it never overrides a source that works).
Cheap on any input: a file is told by its first bytes; a folder by the names of at most MAX_ENTRIES entries,
up to MAX_DEPTH levels down (a ScenarioNet database or an Argoverse 2 split can hold 10^5 files).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from itertools import islice
from pathlib import Path

MAX_ENTRIES = 2000
MAX_DEPTH = 4
MCAP_MAGIC = b"\x89MCAP0\r\n"
ROSBAG1_MAGIC = b"#ROSBAG V2.0"
ARROW_MAGIC = b"ARROW1"
ROSBAG2_METADATA = b"rosbag2_bagfile_information"
AV2_NAMES = ("annotations.feather", "annotations_with_ego.feather")


@dataclass(frozen=True)
class Look:
    source: str  # the r2s extract SOURCE that reads it
    what: str  # what it looks like, for the user
    path: str  # the INPUT to give that source


def _head(path: Path, n: int = 32) -> bytes:
    try:
        with open(path, "rb") as fh:
            return fh.read(n)
    except OSError:
        return b""


def _file_look(path: Path) -> Look | None:
    head = _head(path)
    if head.startswith(MCAP_MAGIC):
        return Look("mcap", "an MCAP file", str(path))
    if head.startswith(ROSBAG1_MAGIC):
        return Look("rosbag", "a ROS 1 bag", str(path))
    if path.name in AV2_NAMES and head.startswith(ARROW_MAGIC):
        return Look("argoverse2", f"Argoverse 2 annotations ({path.name})", str(path.parent))
    if path.name == "metadata.yaml" and ROSBAG2_METADATA in _head(path, 256):
        return Look("rosbag", "the metadata.yaml of a ROS 2 bag", str(path.parent))
    if path.suffix == ".pkl" and head.startswith(b"\x80"):
        return Look("scenarionet", "a ScenarioNet scenario (.pkl)", str(path))
    if path.suffix == ".json" and path.parent.name.startswith("v1.0-") and (path.parent / "sample.json").is_file():
        return Look("nuscenes", f"a nuScenes table ({path.parent.name}/{path.name})", str(path.parent.parent))
    return None


def _dir_look(top: str, entry: os.DirEntry, depth: int) -> Look | None:
    name, path = entry.name, Path(entry.path)
    if entry.is_dir(follow_symlinks=False):
        if name.startswith("v1.0-") and (path / "sample.json").is_file():
            where = top if depth == 0 else str(path.parent)
            return Look("nuscenes", f"a nuScenes dataroot ({name}/ with JSON tables)", where)
        return None
    if name == "dataset_summary.pkl":
        return Look("scenarionet", "a ScenarioNet database (dataset_summary.pkl)", top)
    if name.endswith(".pkl") and name != "dataset_mapping.pkl":
        return Look("scenarionet", "a folder of ScenarioNet scenarios (.pkl)", top)
    if name in AV2_NAMES:
        return Look("argoverse2", f"Argoverse 2 logs ({name})", top)
    if name == "metadata.yaml" and ROSBAG2_METADATA in _head(path, 256):
        return Look("rosbag", "a ROS 2 bag (metadata.yaml)", top if depth == 0 else str(path.parent))
    if name.endswith(".bag") and _head(path).startswith(ROSBAG1_MAGIC):
        return Look("rosbag", "a folder of ROS 1 bags (.bag)", top)
    if name.endswith(".mcap") and _head(path).startswith(MCAP_MAGIC):
        return Look("mcap", "a folder of MCAP files", top)
    return None


def looks_like(input_path: str) -> list[Look]:
    """The sources whose input this looks like, one Look each, nearest evidence first."""
    path = Path(input_path)
    if path.is_file():
        look = _file_look(path)
        return [look] if look else []
    if not path.is_dir():
        return []
    found: dict[str, Look] = {}
    level, seen = [path], 0
    for depth in range(MAX_DEPTH + 1):
        below = []
        for folder in level:
            try:
                with os.scandir(folder) as it:
                    entries = sorted(islice(it, MAX_ENTRIES - seen), key=lambda e: e.name)
            except OSError:
                continue
            for entry in entries:
                seen += 1
                look = _dir_look(input_path, entry, depth)
                if look and look.source not in found:
                    found[look.source] = look
                if entry.is_dir(follow_symlinks=False):
                    below.append(Path(entry.path))
            if seen >= MAX_ENTRIES:
                return list(found.values())
        level = below
    return list(found.values())


def wrong_source_hint(source: str, input_path: str) -> str | None:
    """One line saying what INPUT looks like and which source reads it, when it does not look like `source`."""
    looks = looks_like(input_path)
    if not looks or any(look.source == source for look in looks):
        return None
    what = " and ".join(look.what for look in looks)
    use = " or ".join(f"`r2s extract {look.source} {look.path}`" for look in looks)
    return f"{input_path} looks like {what}, not input of the {source} source: use {use}"
