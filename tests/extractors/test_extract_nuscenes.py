"""nuScenes extractor: the shipped 13-table excerpt loads through nuscenes-devkit and gives the same frames as
the ScenarioNet pickles it was built from; filters and bad dataroots."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from extractors.base import ExtractOptions
from extractors.categories import ALL
from extractors.nuscenes import extract as extract_nuscenes
from extractors.scenarionet import extract as extract_scenarionet
from tests.support.extract import EXCERPT, assert_refused, r2s
from tests.support.extract import frames_of as _frames

COMPARED = ["frame_id", "scene", "frame_index", "entity_id", "track_id", "type", "is_ego"]


def test_excerpt_is_a_table_set_nuscenes_devkit_loads():
    from nuscenes.nuscenes import NuScenes

    nusc = NuScenes(version="v1.0-mini", dataroot=str(EXCERPT), verbose=False)
    assert {s["name"] for s in nusc.scene} == {"scene-0061", "scene-0103", "scene-0796"}
    assert len(nusc.sample) == 9


@pytest.mark.parametrize("categories", [ALL, ExtractOptions().categories])
def test_same_frames_as_the_scenarionet_path(categories):
    nus = _frames(extract_nuscenes, EXCERPT, categories=categories)
    sn = _frames(extract_scenarionet, EXCERPT / "scenarionet", categories=categories)
    key = ["frame_id", "entity_id"]
    nus, sn = nus.sort_values(key).reset_index(drop=True), sn.sort_values(key).reset_index(drop=True)
    assert len(nus) == len(sn) and nus.frame_id.nunique() == 9
    assert nus[COMPARED].equals(sn[COMPARED])
    for col in ("x", "y"):
        assert (nus[col] - sn[col]).abs().max() < 1e-6
    gap = (nus.heading - sn.heading) % 360.0
    assert gap.where(gap < 180, 360 - gap).max() < 1e-6
    others = ~nus.is_ego
    assert nus[others].category.equals(sn[others].category)
    assert (nus[others].length - sn[others].length).abs().max() < 1e-6
    assert (nus.timestamp_us == sn.timestamp_us).all()


def _copy_excerpt(tmp_path: Path) -> Path:
    root = tmp_path / "nus"
    shutil.copytree(EXCERPT / "v1.0-mini", root / "v1.0-mini")
    return root  # no maps/ at all: missing map masks must not stop it


def test_missing_map_masks_and_filters(tmp_path):
    root = _copy_excerpt(tmp_path)
    table = root / "v1.0-mini" / "sample_annotation.json"
    anns = json.loads(table.read_text())
    for i, a in enumerate(anns):  # every third annotation barely visible, every fifth without lidar points
        a["visibility_token"] = "1" if i % 3 == 0 else "4"
        a["num_lidar_pts"] = 0 if i % 5 == 0 else 7
    table.write_text(json.dumps(anns))
    base = _frames(extract_nuscenes, root, categories=ALL, radius=1e9)
    vis = _frames(extract_nuscenes, root, categories=ALL, radius=1e9, min_visibility=2)
    pts = _frames(extract_nuscenes, root, categories=ALL, radius=1e9, min_lidar_pts=1)
    n = len(anns)
    assert len(base) - 9 == n
    assert len(vis) - 9 == sum(1 for i in range(n) if i % 3)
    assert len(pts) - 9 == sum(1 for i in range(n) if i % 5)
    kept = {a["instance_token"] for i, a in enumerate(anns) if i % 3}
    assert set(vis[~vis.is_ego].track_id) <= kept


def test_scene_selection(tmp_path):
    one = _frames(extract_nuscenes, EXCERPT, categories=ALL, scenes=("scene-0796",))
    assert set(one.scene) == {"scene-0796"} and one.frame_id.nunique() == 3


@pytest.mark.parametrize("case", ["missing", "version", "corrupt", "scene"])
def test_bad_input_exits_2_and_writes_nothing(tmp_path, capsys, case):
    out = tmp_path / "out" / "frames.parquet"
    args = ["extract", "nuscenes", str(EXCERPT), "--out", str(out)]
    if case == "missing":
        args[2] = str(tmp_path / "nowhere")
    elif case == "version":
        args += ["--version", "v1.0-trainval"]
    elif case == "corrupt":
        root = _copy_excerpt(tmp_path)
        (root / "v1.0-mini" / "sample.json").write_text('[{"token": "x", ')
        args[2] = str(root)
    else:
        args += ["--scenes", "scene-9999"]
    assert_refused(r2s(capsys, *args), out, {"missing": "does not exist", "version": "v1.0-trainval",
                                             "corrupt": "not a loadable", "scene": "scene-9999"}[case])
