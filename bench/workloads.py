"""The frame sets bench_synth.py times, as scene JSON dicts (so that any source tree can read them).

- keyframes: all 242 shipped nuScenes-mini keyframes, every category within 50 m (data/nuscenes-mini-keyframes).
- waymo-like: real nuScenes-mini tracks (../shared/data/nuscenes-mini/scenarionet, the six scenes ScenarioNet
  ships) re-laid out as ScenarioNet's Waymo converter writes them (tests/support/scenarionet_layouts.as_waymo: float32
  states, Waymo's four object types, string ids), written as a converter database and read back by
  `r2s extract scenarionet --categories all`, one frame every `every` steps of the 10 Hz tracks. The shared
  data has no Waymo recording; this is the Waymo layout and rate over real boxes. Steps 5k hold the nuScenes
  annotations themselves, the others ScenarioNet's interpolation between them.
- crowds: tests/support/crowds.py, dense crowds of 50-60 pedestrians with barriers, cones and cars (seeds 0..count-1).
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
KEYFRAMES = ROOT / "data" / "nuscenes-mini-keyframes" / "frames.parquet"
for p in (str(ROOT), str(HERE)):  # ROOT: tests.support
    if p not in sys.path:
        sys.path.insert(0, p)

from realdata import SHARED  # noqa: E402

SCENARIONET = SHARED / "data" / "nuscenes-mini" / "scenarionet"


def _scene_dicts(frames) -> list[dict]:
    from frames.rows import iter_scenes

    return [s.to_dict() for s in iter_scenes(frames)]


def keyframes() -> list[dict]:
    from frames.rows import read_frames

    return _scene_dicts(read_frames(KEYFRAMES))


def waymo_like(every: int = 10) -> list[dict]:
    """[] without ../shared (the caller says so)."""
    if not SCENARIONET.is_dir():
        return []
    import pandas as pd

    from extractors import scenarionet
    from extractors.base import ExtractOptions
    from extractors.categories import CategorySelection
    from tests.support.scenarionet_layouts import as_waymo, load_real, write_single_worker

    scenarios = [as_waymo(load_real(p)) for p in sorted(SCENARIONET.glob("*.pkl"))]
    with tempfile.TemporaryDirectory() as tmp:
        db = write_single_worker(scenarios, Path(tmp) / "waymo", "waymo", "v1.2")
        options = ExtractOptions(categories=CategorySelection.parse("all", scenarionet.TAXONOMY), every=every)
        rows = [r for chunk in scenarionet.extract(str(db), options) for r in chunk]
    return _scene_dicts(pd.DataFrame(rows))


def crowds(count: int) -> list[dict]:
    from tests.support.crowds import crowd_scenes

    return [s.to_dict() for s in crowd_scenes(count)]
