"""The one small interface every source module implements, and what they share.

A source module (nuscenes, scenarionet, argoverse2, mcap, rosbag) has `DESCRIPTION` and
`extract(input_path, options) -> Iterator[list[row dict]]`, one list of frames rows per frame, built with
`FrameBuilder.frame(...)` so that the ego-frame transform, category selection, radius and entity cap are the
same for all sources. Problems with the input raise ExtractError (a FramesError: one line, exit 2).
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from extractors.categories import VEHICLES, CategorySelection
from extractors.frames import FramesError, _dim, frame_rows
from synth.scene import DEFAULT_MAX_ENTITIES


class ExtractError(FramesError):
    """The input of an extractor is missing, corrupt, or not what it claims. One line, fit for a user."""


@dataclass(frozen=True)
class ExtractOptions:
    radius: float = 50.0
    categories: CategorySelection = VEHICLES
    every: int = 1
    max_entities: int = DEFAULT_MAX_ENTITIES
    # nuscenes
    version: str = "v1.0-mini"
    scenes: tuple[str, ...] = ()
    min_visibility: int = 0
    min_lidar_pts: int = 0
    # mcap / rosbag
    topics: tuple[str, ...] = ()
    pose_topic: str | None = None
    fixed_frame: str = "map"
    ego_frame: str = "base_link"
    max_chunk_bytes: int = 256 * 2**20

    def __post_init__(self) -> None:
        if not (self.radius > 0):
            raise ValueError("--radius must be positive")
        if self.every < 1:
            raise ValueError("--every must be at least 1")
        if self.max_entities < 1:
            raise ValueError("--max-entities must be at least 1")


@dataclass(frozen=True)
class Box:
    """One recorded object in the ego frame (+x right, +y forward, heading degrees CCW from +y)."""

    track_id: str
    category: str
    x: float
    y: float
    heading: float
    length: float | None = None
    width: float | None = None


def global_to_ego(
    ego_x: float, ego_y: float, ego_yaw: float, xs: Any, ys: Any, yaws: Any
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Global positions and yaws (radians, CCW from +x, as nuScenes / ScenarioNet / AV2 city) into the ego frame.

    Offsets are rotated by (90 deg - ego_yaw) so that the ego's forward axis becomes +y; headings are
    yaw - ego_yaw in degrees, in [0, 360).
    """
    dx = np.asarray(xs, dtype=float) - ego_x
    dy = np.asarray(ys, dtype=float) - ego_y
    c, s = math.cos(ego_yaw), math.sin(ego_yaw)
    x = dx * s - dy * c  # minus the leftward component
    y = dx * c + dy * s  # the forward component
    heading = np.degrees(np.asarray(yaws, dtype=float) - ego_yaw) % 360.0
    return x, y, heading


def vehicle_to_ego(xs: Any, ys: Any, yaws: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Boxes in a vehicle frame with x forward, y left (ROS base_link, Argoverse 2 egovehicle) into ours."""
    return (-np.asarray(ys, dtype=float), np.asarray(xs, dtype=float),
            np.degrees(np.asarray(yaws, dtype=float)) % 360.0)


def quaternion_yaw(w: Any, x: Any, y: Any, z: Any) -> np.ndarray:
    """Rotation about +z (radians) of unit quaternions, as nuscenes-devkit's quaternion_yaw for level boxes."""
    w, x, y, z = (np.asarray(v, dtype=float) for v in (w, x, y, z))
    return np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


@dataclass(frozen=True)
class FrameBuilder:
    """Turns one frame's boxes into frames rows: category selection, radius, cap, deterministic ids."""

    source: str
    taxonomy: str
    options: ExtractOptions

    def frame(
        self,
        scene: str,
        frame_index: int,
        timestamp_us: int | None,
        ego: Box,
        others: Iterable[Box],
        frame_id: str | None = None,
    ) -> list[dict[str, Any]]:
        opts = self.options
        fid = frame_id or f"{scene}/{frame_index}"
        kept = []
        for b in others:
            if not (math.isfinite(b.x) and math.isfinite(b.y) and math.isfinite(b.heading)):
                raise ExtractError(f"frame {fid}: object {b.track_id} has a non-finite position or heading")
            if math.hypot(b.x, b.y) > opts.radius:
                continue
            try:
                cls = opts.categories.select(self.taxonomy, b.category)
            except LookupError as exc:
                raise ExtractError(f"frame {fid}: {exc}") from None
            if cls is not None:
                kept.append(_as_entity(b, cls))
        if len(kept) + 1 > opts.max_entities:
            raise ExtractError(
                f"frame {fid} has {len(kept) + 1} entities, more than the cap of {opts.max_entities} "
                "(raise --max-entities, or lower --radius)"
            )
        return frame_rows(self.source, scene, frame_index, timestamp_us, _as_entity(ego, "Car"), kept, fid)


def _as_entity(b: Box, cls: str) -> dict[str, Any]:
    return {"track_id": b.track_id, "type": cls, "category": b.category, "x": b.x, "y": b.y,
            "heading": b.heading, "length": _dim(b.length), "width": _dim(b.width)}


def require_path(path: str | os.PathLike, what: str) -> Path:
    p = Path(path)
    if not p.exists():
        raise ExtractError(f"{what} {path} does not exist")
    return p


def files_with_suffix(path: Path, suffixes: Sequence[str], what: str) -> list[Path]:
    """A file, or the files under a directory (recursively, sorted) whose names end in one of suffixes."""
    if path.is_file():
        return [path]
    found = sorted(p for p in path.rglob("*") if p.is_file() and p.name.endswith(tuple(suffixes)))
    if not found:
        raise ExtractError(f"{path} holds no {what} ({' / '.join(suffixes)} files)")
    return found
