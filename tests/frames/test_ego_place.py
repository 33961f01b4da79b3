"""A frame read into a Scene: its ego row's place read once (frames.ego_place) for both its `world` and its
road, and the box rule of each path as docs/formats.md states it (a frames row's null, NaN, infinite, zero or
negative length / width is no box; scene JSON refuses one), all through `r2s` as a user runs it."""

from __future__ import annotations

import json
import math
import shutil

import pyarrow.parquet as pq
import pytest

from frames.ego_place import FramePlace
from frames.maps import FrameRoads, maps_dir
from frames.rows import read_frames, write_frames
from synth.road.roadmap import in_ego_frame
from tests.support import ROOT, assert_one_line_error, run_r2s

AV2 = ROOT / "data" / "argoverse2-log-excerpt" / "frames.parquet"
BAD_BOXES = [0.0, -1.0, math.nan, math.inf, -math.inf, None]


def _frame_with_boxes(tmp_path, lengths):
    """The excerpt's first frame with its first entities' lengths and widths replaced, as a frames file."""
    df = read_frames(AV2)
    fid = df["frame_id"].iloc[0]
    df = df[df["frame_id"] == fid].reset_index(drop=True)
    others = df.index[~df["is_ego"]][: len(lengths)]
    df["length"] = df["length"].astype(object)
    df["width"] = df["width"].astype(object)
    for i, v in zip(others, lengths):
        df.at[i, "length"] = v
        df.at[i, "width"] = v
    out = tmp_path / "frames.parquet"
    write_frames(df, out)
    return out, fid, [df.at[i, "entity_id"] for i in others]


def test_a_frames_row_without_a_positive_finite_box_has_none_in_its_scene(tmp_path):
    lengths = [*BAD_BOXES, 2.5]
    frames, fid, ids = _frame_with_boxes(tmp_path, lengths)
    proc = run_r2s("scene", str(frames), fid)
    assert proc.returncode == 0, proc.stderr
    by_id = {e["id"]: e for e in json.loads(proc.stdout)["entities"]}
    for eid, v in zip(ids, lengths):
        e = by_id[eid]
        if v is not None and math.isfinite(v) and v > 0:
            assert (e["length"], e["width"]) == (v, v)
        else:
            assert "length" not in e and "width" not in e, (v, e)
    # and the scene it writes is scene JSON that reads back as itself: synthesis takes it
    scene = tmp_path / "scene.json"
    scene.write_text(proc.stdout)
    assert run_r2s("synth", str(scene), "--format", "json").returncode == 0


@pytest.mark.parametrize("value", ["0", "-1", "-0.0", "1e400", "-1e400"])
@pytest.mark.parametrize("key", ["length", "width"])
def test_scene_json_refuses_a_box_that_is_not_positive_and_finite(tmp_path, key, value):
    scene = tmp_path / "scene.json"
    scene.write_text('{"frame_id": "f", "entities": [{"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0, '
                     f'"{key}": {value}}}]}}')
    assert_one_line_error(run_r2s("synth", str(scene)), contains=f"ego' {key} must be")


def _frames_of_av2(tmp_path):
    out = tmp_path / "frames.parquet"
    shutil.copy(AV2, out)
    shutil.copytree(maps_dir(AV2), maps_dir(out))
    return out


def test_the_world_and_the_road_come_from_one_reading_of_the_ego_row(tmp_path):
    """Scene JSON's world is the ego row's pose, and the road is the map moved by that same pose (checked against
    in_ego_frame given the row's numbers by hand)."""
    frames = _frames_of_av2(tmp_path)
    df = read_frames(frames)
    fid = df["frame_id"].iloc[3]
    rows = df[df["frame_id"] == fid]
    ego = rows[rows["is_ego"]].iloc[0]
    proc = run_r2s("scene", str(frames), fid)
    assert proc.returncode == 0, proc.stderr
    doc = json.loads(proc.stdout)
    assert (doc["world"]["x"], doc["world"]["y"], doc["world"]["heading"]) == (
        ego["map_x"], ego["map_y"], ego["map_heading"])
    roads = FrameRoads(maps_dir(frames))
    placed = rows[rows["map_x"].notna()]
    want = in_ego_frame(roads.map_named(ego["map_id"]), float(ego["map_x"]), float(ego["map_y"]),
                        float(ego["map_heading"]), 50.0, list(zip(placed["map_x"], placed["map_y"])),
                        {lane for ids in rows["lanes"] if ids is not None for lane in ids})
    got = {f["id"]: f for f in doc["road"]["features"]}
    assert sorted(got) == sorted(f.feature_id for f in want.features) and got
    for f in want.features:
        assert got[f.feature_id].get("polygon", []) == [list(p) for p in f.polygon]


@pytest.mark.parametrize("missing", ["map_x", "map_y", "map_heading"])
def test_an_ego_row_without_a_pose_has_no_world_and_no_road(tmp_path, missing):
    frames = _frames_of_av2(tmp_path)
    table = pq.read_table(frames)
    df = table.to_pandas()
    df.loc[df["is_ego"], missing] = math.nan
    write_frames(df, frames)
    fid = df["frame_id"].iloc[0]
    assert FramePlace.of(df[df["frame_id"] == fid]) == FramePlace(df["map_id"].iloc[0], None)
    proc = run_r2s("scene", str(frames), fid)
    assert proc.returncode == 0, proc.stderr
    doc = json.loads(proc.stdout)
    assert "world" not in doc and "road" not in doc


def test_an_ego_row_without_a_map_has_its_world_and_no_road(tmp_path):
    frames = _frames_of_av2(tmp_path)
    df = read_frames(frames)
    df.loc[df["is_ego"], "map_id"] = None
    write_frames(df, frames)
    fid = df["frame_id"].iloc[0]
    place = FramePlace.of(df[df["frame_id"] == fid])
    assert place.map_id is None and place.road_pose is None and place.world is not None
    proc = run_r2s("scene", str(frames), fid)
    doc = json.loads(proc.stdout)
    assert proc.returncode == 0 and "road" not in doc and "map_id" not in doc["world"]
    assert doc["world"]["x"] == place.world["x"]

