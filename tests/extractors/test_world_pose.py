"""Frames keep the ego's world pose per frame (map_x, map_y, map_heading of the ego row), map or no map, and scene
JSON carries it as `world` (r2s scene): checked against the recordings read without our readers (the nuScenes JSON
tables, the ScenarioNet pickles through plain pickle), and the way back from the ego frame (synth.world) against
every entity's own recorded world place."""

from __future__ import annotations

import json
import math
import pickle

import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from extractors.base import global_to_ego
from extractors.categories import ALL
from extractors.nuscenes import extract as extract_nuscenes
from extractors.scenarionet import extract as extract_scenarionet
from frames.rows import frame_to_scene, scene_to_rows
from synth.scene import SceneError, scene_from_dict
from synth.world import WorldPose
from tests.support import run_r2s
from tests.support.extract import EXCERPT
from tests.support.extract import frames_of as _frames


def _angle_gap(a: float, b: float) -> float:
    return abs((a - b + 180.0) % 360.0 - 180.0)


def test_nuscenes_ego_rows_keep_the_lidar_top_ego_pose():
    tables = {n: {r["token"]: r for r in json.loads((EXCERPT / "v1.0-mini" / f"{n}.json").read_text())}
              for n in ("sample", "sample_data", "ego_pose", "scene")}
    lidar = {sd["sample_token"]: sd for sd in tables["sample_data"].values()
             if sd["is_key_frame"] and "LIDAR_TOP" in sd["filename"]}
    df = _frames(extract_nuscenes, EXCERPT, categories=ALL)
    ego = df[df.is_ego]
    assert len(ego) == 9 and ego.map_x.notna().all() and "map_id" not in ego  # no map, a world pose
    samples = {}  # (scene name, 0-based sample index) -> sample token, along each scene's chain
    for scene in tables["scene"].values():
        token, k = scene["first_sample_token"], 0
        while token:
            samples[scene["name"], k] = token
            token, k = tables["sample"][token]["next"], k + 1
    for r in ego.itertuples():
        pose = tables["ego_pose"][lidar[samples[r.scene, r.frame_index]]["ego_pose_token"]]
        w, x, y, z = pose["rotation"]
        yaw = math.degrees(math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)))
        assert (r.map_x, r.map_y) == (pose["translation"][0], pose["translation"][1])
        assert _angle_gap(r.map_heading, yaw) < 1e-9


def test_scenarionet_ego_rows_keep_the_sdc_track_pose():
    df = _frames(extract_scenarionet, EXCERPT / "scenarionet", categories=ALL)
    for path in sorted((EXCERPT / "scenarionet").glob("sd_*.pkl")):
        with path.open("rb") as f:
            sd = pickle.load(f)  # the shipped excerpt: our own file, trusted here
        sdc = sd["tracks"][sd["metadata"]["sdc_id"]]["state"]
        ego = df[df.is_ego & (df.scene == sd["metadata"]["scenario_id"])]
        assert len(ego) > 0
        for r in ego.itertuples():
            step = 5 * r.frame_index
            assert (r.map_x, r.map_y) == tuple(float(v) for v in sdc["position"][step][:2])
            assert _angle_gap(r.map_heading, math.degrees(sdc["heading"][step])) < 1e-9


@pytest.mark.parametrize("extract, where", [(extract_nuscenes, EXCERPT),
                                            (extract_scenarionet, EXCERPT / "scenarionet")])
def test_the_scene_s_world_puts_every_entity_back_on_its_recorded_world_place(extract, where):
    df = _frames(extract, where, categories=ALL)
    for _, rows in df.groupby("frame_id", sort=False):
        scene = frame_to_scene(rows.reset_index(drop=True))
        world = scene.world
        ego = rows[rows.is_ego].iloc[0]
        assert (world.x, world.y, world.heading) == (ego.map_x, ego.map_y, ego.map_heading)
        assert (world.source, world.scene, world.frame_index) == (ego.source, ego.scene, ego.frame_index)
        recorded = rows.set_index("entity_id")
        for e in scene.entities:
            x, y = world.point(e.x, e.y)
            r = recorded.loc[e.id]
            assert math.hypot(x - r.map_x, y - r.map_y) < 1e-6
            assert _angle_gap(math.degrees(world.yaw(e.heading)), r.map_heading) < 1e-6


def test_r2s_scene_writes_the_world_and_scene_rows_keep_it(tmp_path):
    frames = tmp_path / "frames.parquet"
    res = run_r2s("extract", "nuscenes", str(EXCERPT), "--out", str(frames))
    assert res.returncode == 0, res.stderr
    res = run_r2s("scene", str(frames), "scene-0103/0")
    assert res.returncode == 0, res.stderr
    doc = json.loads(res.stdout)
    assert list(doc) == ["frame_id", "entities", "world"]  # no map: no road, a world
    assert set(doc["world"]) == {"source", "scene", "frame_index", "timestamp_us", "x", "y", "heading"}
    rows = pd.read_parquet(frames)
    assert doc["world"]["timestamp_us"] == int(rows[rows.frame_id == "scene-0103/0"].timestamp_us.iloc[0])
    scene = scene_from_dict(doc)
    back = frame_to_scene(pd.DataFrame(scene_to_rows(scene, source="nuscenes", scene_name="scene-0103")))
    assert back.world == scene.world


def test_the_frames_without_a_world_pose_make_scenes_without_world():
    rows = pd.DataFrame(scene_to_rows(scene_from_dict({"entities": [{"id": "ego", "type": "Car", "x": 0, "y": 0,
                                                                      "heading": 0}]})))
    assert frame_to_scene(rows).world is None


@pytest.mark.parametrize("world, says", [
    ({"x": 1, "y": 2}, "lacks heading"), ({"x": 1, "y": 2, "heading": True}, "must be a number"),
    ({"x": 1e10, "y": 2, "heading": 0}, "within 1e9"), ({"x": 1, "y": 2, "heading": 0, "yaw": 3}, "unknown key 'yaw'"),
    ({"x": 1, "y": 2, "heading": 0, "frame_index": -1}, "frame_index"),
    ({"x": 1, "y": 2, "heading": 0, "timestamp_us": -1}, "timestamp_us"),
    ({"x": 1, "y": 2, "heading": 0, "timestamp_us": 1.5}, "timestamp_us"),
    ({"x": 1, "y": 2, "heading": 0, "timestamp_us": 2**62}, "timestamp_us"),
    ({"x": 1, "y": 2, "heading": 0, "scene": "a\nb"}, "printable"), ([1, 2, 3], "must be an object")])
def test_a_bad_world_is_one_line(world, says):
    with pytest.raises(SceneError, match=says):
        scene_from_dict({"entities": [{"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0}], "world": world})


coord = st.floats(-1e5, 1e5, allow_nan=False)
angle = st.floats(0, 360, exclude_max=True)


@settings(max_examples=300, deadline=None)
@given(coord, coord, angle, coord, coord, angle)
def test_world_point_inverts_the_extractors_global_to_ego(wx, wy, wh, px, py, ph):
    """synth.world's way back and extractors.base.global_to_ego's way in are inverse (within rounding)."""
    pose = WorldPose(wx, wy, wh)
    x, y, h = global_to_ego(wx, wy, math.radians(wh), [px], [py], [math.radians(ph)])
    bx, by = pose.point(float(x[0]), float(y[0]))
    assert math.hypot(bx - px, by - py) <= 1e-9 * (1 + abs(px) + abs(py) + abs(wx) + abs(wy))
    assert _angle_gap(math.degrees(pose.yaw(float(h[0]))), ph) < 1e-9


def test_the_identity_world_keeps_ego_frame_coordinates():
    pose = WorldPose.identity()
    assert pose.point(3.0, 4.0) == pytest.approx((3.0, 4.0), abs=1e-15)
    assert math.degrees(pose.yaw(0.0)) == pytest.approx(90.0)


def test_a_log_s_ego_rows_keep_the_ego_pose_in_the_fixed_frame(tmp_path):
    """MCAP (ROS 2 markers in the map frame, the ego pose from /tf): no map, the ego's pose in `map` per frame."""
    from extractors.mcap import extract as extract_mcap
    from tests.support import logs

    samples = logs.scenes()["scene-0103"]
    path = tmp_path / "log.mcap"
    logs.write_ros2_mcap(path, samples)
    df = _frames(extract_mcap, path, categories=ALL, topics=("/markers",))
    ego = df[df.is_ego].sort_values("frame_index")
    assert len(ego) == len(samples) and "map_id" not in ego
    for r, s in zip(ego.itertuples(), samples):
        w, x, y, z = s.ego_rotation
        yaw = math.degrees(math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)))
        assert math.hypot(r.map_x - s.ego_translation[0], r.map_y - s.ego_translation[1]) < 1e-9
        assert _angle_gap(r.map_heading, yaw) < 1e-6
