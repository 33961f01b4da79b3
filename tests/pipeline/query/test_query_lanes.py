"""Lane clauses in queries (pipeline.query.lanes): the engine's matches are exactly the definition's
(synth.patterns.one_frame.matches on each frame as a scene whose road is its whole map) on the shipped nuScenes excerpt and
on the Argoverse 2 test log (../shared/data), for the shipped lane patterns and more; bad input is one line."""

from __future__ import annotations

import functools
from pathlib import Path

import pandas as pd
import pytest

from frames.maps import maps_dir, read_maps
from frames.rows import frame_to_scene
from pipeline.query import query
from synth.patterns.one_frame import matches, parse_pattern
from synth.patterns.temporal import is_temporal
from tests.support import ROOT, SHARED, assert_one_line_error, run_r2s

WAYMO = SHARED / "data" / "waymo" / "sd_waymo_v1.2_7e21cb7ea347ecaa.pkl"  # 147 tracks, as ScenarioNet converts them
AV2_LOG = Path("/work/shared/data/argoverse2/test_data/sensor_dataset_logs/adcf7d18-0510-35b0-a2fa-b4cea13a6d76")
# The one-frame lane patterns (the temporal ones beside them: tests/pipeline/query/test_temporal_lanes.py).
LANE_PATTERNS = [p for p in sorted((ROOT / "data" / "patterns" / "lanes").glob("*.dsl")) if not is_temporal(p.read_text())]
ANYWHERE = "on Range(-999, 999) @ Range(-999, 999), facing Range(0, 360) deg"
MORE = [
    f"v = new Vehicle {ANYWHERE}, in lane of ego",
    f"v = new Vehicle {ANYWHERE}, in lane left of ego",
    f"v = new Vehicle {ANYWHERE}, in lane right of ego",
    f"v = new Vehicle {ANYWHERE}, in oncoming lane of ego",
    f"v = new Object {ANYWHERE}, off lane",
    f"v = new Object {ANYWHERE}, off road",
    f"a = new Vehicle {ANYWHERE}, in lane of ego\nb = new Vehicle behind a by Range(0, 40), facing Range(0, 360) deg, "
    "in lane of a",
    f"a = new Vehicle {ANYWHERE}, in lane right of ego\nb = new Vehicle {ANYWHERE}, in oncoming lane of a",
    # the ego line: ego's own lane facts, and ego in a lane related to a name's
    f"v = new Vehicle {ANYWHERE}\nego in intersection",
    f"v = new Object {ANYWHERE}\nego off lane",
    f"v = new Vehicle {ANYWHERE}\nego in lane of v",
    f"v = new Vehicle {ANYWHERE}\nego in lane left of v",
    f"v = new Vehicle {ANYWHERE}\nego in oncoming lane of v",
    f"v = new Vehicle {ANYWHERE}, in lane of ego\nego moving Range(0, 100) m/s, in lane of v",
]


@functools.cache
def _scenes(frames) -> tuple:
    """Each frame as a scene whose road is its whole map, built once per frames file (every pattern reads the same
    scenes: building them per pattern was most of these tests' time)."""
    maps = {m.map_id: m for m in read_maps(maps_dir(frames))}
    out = []
    for fid, rows in pd.read_parquet(frames).groupby("frame_id", sort=False):
        ego = rows[rows.is_ego].iloc[0]
        out.append((fid, frame_to_scene(rows, maps.get(ego.map_id) if isinstance(ego.map_id, str) else None)))
    return tuple(out)


def brute(frames, pattern) -> list:
    """Every binding of every frame, by the definition, each frame's road its whole map."""
    return sorted((fid, tuple(sorted(b.items()))) for fid, scene in _scenes(str(frames)) for b in matches(pattern, scene))


def engine(frames, pattern) -> list:
    got = query(frames, pattern, all_bindings=True)
    return sorted((r.frame_id, tuple(sorted(r.binding.items()))) for r in got.itertuples())


def _extract(tmp_path_factory, source: str, path) -> str:
    out = tmp_path_factory.mktemp(source) / "frames"
    proc = run_r2s("extract", source, str(path), "--categories", "all", "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    return str(out)



@pytest.fixture(scope="module")
def av2(tmp_path_factory):
    if not AV2_LOG.is_dir():
        pytest.skip("needs ../shared/data/argoverse2 (the av2-api test log with its map)")
    return _extract(tmp_path_factory, "argoverse2", AV2_LOG)


@pytest.mark.parametrize("text", [p.read_text() for p in LANE_PATTERNS] + MORE)
def test_lane_patterns_match_exactly_the_definition_on_the_shipped_excerpt(excerpt_frames, text):
    pattern = parse_pattern(text)
    assert engine(excerpt_frames, pattern) == brute(excerpt_frames, pattern)


def test_lane_patterns_match_exactly_the_definition_on_the_argoverse2_log(av2):
    found = {}
    for text in [p.read_text() for p in LANE_PATTERNS] + MORE:
        pattern = parse_pattern(text)
        got = engine(av2, pattern)
        assert got == brute(av2, pattern), text
        found[text] = len(got)
    # every relation and fact occurs in this log, so the comparison can fail
    assert sum(n > 0 for n in found.values()) >= len(found) - 1, found


def test_lane_patterns_match_exactly_the_definition_on_a_waymo_scenario(tmp_path_factory):
    if not WAYMO.exists():
        pytest.skip("needs ../shared/data/waymo")
    frames = tmp_path_factory.mktemp("waymo") / "frames"
    proc = run_r2s("extract", "scenarionet", str(WAYMO), "--every", "20", "--out", str(frames))
    assert proc.returncode == 0, proc.stderr
    found = {}
    for text in [p.read_text() for p in LANE_PATTERNS] + MORE:
        pattern = parse_pattern(text)
        got = engine(str(frames), pattern)
        assert got == brute(str(frames), pattern), text
        found[text] = len(got)
    # Waymo's maps have no intersection lanes nor intersections: the relations between lanes occur, so the
    # comparison can fail
    assert sum(n > 0 for n in found.values()) >= 5, found


def test_lane_patterns_need_frames_with_a_map(tmp_path):
    frames = ROOT / "data" / "nuscenes-mini-keyframes" / "frames.parquet"
    proc = run_r2s("query", str(frames), str(LANE_PATTERNS[0]), "--out", str(tmp_path / "m.parquet"))
    assert_one_line_error(proc, 2, "no lane columns")
    assert not (tmp_path / "m.parquet").exists()
