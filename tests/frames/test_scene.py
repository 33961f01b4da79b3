"""A frame read into a Scene: its ego row's place read once (frames.scene) for both its `world` and its
road, and the box rule of each path as docs/formats.md states it (a frames row's null, NaN, infinite, zero or
negative length / width is no box; scene JSON refuses one), all through `r2s` as a user runs it."""

from __future__ import annotations

import json
import math
import shutil

import pandas as pd
import pyarrow.parquet as pq
import pytest

from frames.maps import FrameRoads, maps_dir
from frames.rows import FramesError, iter_scenes, read_frames, write_frames
from frames.scene import EgoPlace, FrameColumns, frame_to_scene
from pipeline import scene
from synth.road.roadmap import in_ego_frame
from synth.scene import scene_from_dict
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
    assert EgoPlace.of(FrameColumns.of(df[df["frame_id"] == fid])) == EgoPlace(df["map_id"].iloc[0], None)
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
    place = EgoPlace.of(FrameColumns.of(df[df["frame_id"] == fid]))
    assert place.map_id is None and place.road_pose is None and place.world is not None
    proc = run_r2s("scene", str(frames), fid)
    doc = json.loads(proc.stdout)
    assert proc.returncode == 0 and "road" not in doc and "map_id" not in doc["world"]
    assert doc["world"]["x"] == place.world["x"]



def _by_hand(rows) -> dict:
    """A frame's scene JSON from its DataFrame rows one at a time, each missing value (None, NaN) left out: the
    reading of docs/formats.md, written without frames.scene."""
    def known(v):
        return v is not None and not (isinstance(v, float) and math.isnan(v))

    entities = []
    for r in rows.to_dict("records"):
        d = {k: r[k] for k in ("entity_id", "type", "x", "y", "heading")}
        d["id"] = d.pop("entity_id")
        d.update({k: float(r[k]) for k in ("length", "width") if known(r[k]) and math.isfinite(r[k]) and r[k] > 0})
        d.update({k: r[k] for k in ("speed", "pos_sigma", "heading_sigma", "speed_sigma") if known(r.get(k))})
        if r.get("lanes") is not None:
            d["lanes"] = list(r["lanes"])
            d.update({k: r[k] for k in ("lane", "in_intersection", "on_crosswalk", "off_road") if known(r.get(k))})
        entities.append(d)
    doc = {"frame_id": rows["frame_id"].iloc[0], "entities": entities}
    ego = rows[rows["is_ego"]].iloc[0]
    if all(known(ego.get(k)) for k in ("map_x", "map_y", "map_heading")):
        doc["world"] = {"x": ego["map_x"], "y": ego["map_y"], "heading": ego["map_heading"],
                        "frame_index": int(ego["frame_index"]),
                        **({"timestamp_us": int(ego["timestamp_us"])} if known(ego.get("timestamp_us")) else {}),
                        **{k: ego[k] for k in ("source", "scene", "map_id") if isinstance(ego.get(k), str)}}
    return doc


@pytest.mark.parametrize("frames", [AV2, ROOT / "data" / "nuscenes-mini-keyframes" / "frames.parquet"])
def test_arrow_and_pandas_rows_are_one_scene_the_one_read_by_hand(frames):
    table = pq.read_table(frames)
    df = table.to_pandas()
    starts = df.index[df["frame_id"] != df["frame_id"].shift()].tolist() + [len(df)]
    assert len(starts) > 5
    for a, b in zip(starts[:-1], starts[1:]):
        rows = df.iloc[a:b]
        scene = frame_to_scene(table.slice(a, b - a))
        assert scene == frame_to_scene(rows) == scene_from_dict(_by_hand(rows))
        assert scene.world == scene_from_dict(_by_hand(rows)).world
    assert list(iter_scenes(df)) == [frame_to_scene(table.slice(a, b - a)) for a, b in zip(starts[:-1], starts[1:])]


@pytest.mark.parametrize("as_rows", [pd.DataFrame, list])
@pytest.mark.parametrize("column", ["length", "speed", "map_x"])
def test_rows_in_memory_with_text_for_a_number_are_one_frames_error(as_rows, column):
    rows = [{"frame_id": "f", "source": "s", "scene": "s", "frame_index": 0, "timestamp_us": None, "entity_id": "ego",
             "track_id": "ego", "type": "Car", "category": "Car", "x": 0.0, "y": 0.0, "heading": 0.0, "length": 4.0,
             "width": None, "is_ego": True, "speed": 1.0, "map_x": 1.0, "map_y": 2.0, "map_heading": 3.0}]
    rows[0][column] = "abc"
    with pytest.raises(FramesError, match="abc"):
        scene(as_rows(rows))
