"""`r2s scene` on frames with maps, as a user runs it: the scene carries its road (the map features within the
radius, in the ego frame) and each entity its lane facts; both read back as written; a bad road is one line."""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import shapely

from frames.maps import read_maps
from synth.road.lane_facts import RoadIndex
from synth.scene import scene_from_json
from tests.support import ROOT, assert_one_line_error, run_r2s

EXCERPT = ROOT / "data" / "nuscenes-mini-excerpt"



def test_a_scene_carries_the_map_features_near_ego_in_its_ego_frame_and_the_entities_lane_facts(excerpt_frames):
    frames = pd.read_parquet(excerpt_frames)
    maps = {m.map_id: m for m in read_maps(excerpt_frames / "_maps")}
    for fid in frames.frame_id.unique():
        rows = frames[frames.frame_id == fid]
        proc = run_r2s("scene", str(excerpt_frames), fid, "--radius", "30")
        assert proc.returncode == 0, proc.stderr
        doc = json.loads(proc.stdout)
        ego = rows[rows.is_ego].iloc[0]
        road = maps[ego.map_id]
        # the features kept: exactly those within 30 m of ego in the map's frame (GEOS distance), the lanes the
        # entities' facts name, and those within 1 m of an entity's centre (however far from ego)
        centres = shapely.MultiPoint(list(zip(rows.map_x, rows.map_y)))
        named = {lane for ids in rows.lanes for lane in ids}
        near = {f.feature_id for f in road.features
                if (g := shapely.Polygon(f.polygon) if f.polygon else shapely.LineString(f.line)).distance(
                    shapely.Point(ego.map_x, ego.map_y)) <= 30 or f.feature_id in named or g.distance(centres) <= 1}
        assert doc["road"]["map_id"] == ego.map_id and {f["id"] for f in doc["road"]["features"]} == near
        # every point is its map point seen from ego: rotate back by the ego's heading and add its place
        yaw = math.radians(ego.map_heading)
        for f in doc["road"]["features"]:
            original = road[f["id"]]
            for key, pts in (("polygon", original.polygon), ("line", original.line)):
                got = np.array(f.get(key, []), dtype=float).reshape(-1, 2)
                back_x = ego.map_x + got[:, 0] * math.sin(yaw) + got[:, 1] * math.cos(yaw)
                back_y = ego.map_y - got[:, 0] * math.cos(yaw) + got[:, 1] * math.sin(yaw)
                assert np.allclose(np.stack([back_x, back_y], axis=1), np.array(pts).reshape(-1, 2), atol=1e-9)
        # the entities carry the facts of their frames rows
        for e, r in zip(doc["entities"], rows.itertuples()):
            assert e["id"] == r.entity_id and e["lanes"] == list(r.lanes)
            assert (e.get("lane"), e["in_intersection"], e["on_crosswalk"], e["off_road"]) == (
                r.lane, r.in_intersection, r.on_crosswalk, r.off_road)
        # decided again on the scene's road, in the ego frame, the lanes come out the same (as the float moves
        # of the map may shift a point across an edge only within rounding, none of these is that close)
        scene = scene_from_json(proc.stdout)
        index = RoadIndex(scene.road)
        xs = np.array([e.x for e in scene.entities])
        ys = np.array([e.y for e in scene.entities])
        again = index.facts(xs, ys, np.array([(e.heading + 90) % 360 for e in scene.entities]))
        near_road = [e for e, f in zip(scene.entities, again) if math.hypot(e.x, e.y) < 20]
        assert near_road and all(f.lanes == e.lanes for e, f in zip(scene.entities, again)
                                 if math.hypot(e.x, e.y) < 20)
        # and the scene reads back as written
        assert scene.to_json() == proc.stdout


def test_synthesis_reads_a_scene_with_a_road_and_a_bad_road_is_one_line(excerpt_frames, tmp_path):
    fid = pd.read_parquet(excerpt_frames, columns=["frame_id"]).frame_id.iloc[0]
    scene = tmp_path / "scene.json"
    assert run_r2s("scene", str(excerpt_frames), fid, "--out", str(scene)).returncode == 0
    doc = json.loads(scene.read_text())
    plain = {**doc, "entities": [{k: v for k, v in e.items() if k not in (
        "lanes", "lane", "in_intersection", "on_crosswalk", "off_road")} for e in doc["entities"]]}
    plain.pop("road")
    bare = tmp_path / "bare.json"
    bare.write_text(json.dumps(plain))
    with_road, without = run_r2s("synth", str(scene)), run_r2s("synth", str(bare))
    assert with_road.returncode == without.returncode == 0 and with_road.stdout == without.stdout
    lane = next(f for f in doc["road"]["features"] if f["kind"] == "lane")
    for broken, message in [
        ({**lane, "polygon": [[0, 0], [4, 4], [4, 0], [0, 4]]}, "self-intersecting polygon"),
        ({**lane, "left": "no-such-lane"}, "which is not a lane of the map"),
        ({**lane, "colour": "red"}, "unknown key 'colour'"),
        ({**lane, "source_type": 3}, "source_type must be a printable string"),
        ({**lane, "source_type": "LANE\x00"}, "source_type must be a printable string"),
        ({**lane, "polygon": [[0, 0], [1, "x"], [2, 0]]}, "number pairs"),
        # ids name OpenDRIVE roads (r2s export): printable, as frame ids, so XML can hold them
        *[({**lane, "id": bad_id}, "is not a printable string of 1 to 256")
          for bad_id in ("lane\x01", "lane\ufffe", "lane\ud800", "", "x" * 257)],
    ]:
        bad = {**doc, "road": {**doc["road"], "features": [broken if f is lane else f
                                                           for f in doc["road"]["features"]]}}
        path = tmp_path / "bad.json"
        path.write_text(json.dumps(bad))
        assert_one_line_error(run_r2s("synth", str(path)), 2, message)
    bad_fact = {**plain, "entities": [{**plain["entities"][0], "lanes": ["a"], "lane": "b"}, *plain["entities"][1:]]}
    path.write_text(json.dumps(bad_fact))
    assert_one_line_error(run_r2s("synth", str(path)), 2, "lane must be one of its lanes")


def test_frames_without_a_map_give_a_scene_without_a_road(tmp_path):
    out = tmp_path / "frames.parquet"
    assert run_r2s("extract", "nuscenes", str(EXCERPT), "--out", str(out)).returncode == 0
    fid = pd.read_parquet(out, columns=["frame_id"]).frame_id.iloc[0]
    proc = run_r2s("scene", str(out), fid)
    assert proc.returncode == 0 and "road" not in json.loads(proc.stdout)
    assert all("lanes" not in e for e in json.loads(proc.stdout)["entities"])


def test_a_small_radius_keeps_what_the_entities_stand_on_so_a_lane_program_samples(excerpt_frames, tmp_path):
    # --radius below the extraction's left lanes the entities' facts name out of the road: `in lane "ID"` could
    # never hold and r2s sample found no variant.
    scene = tmp_path / "s.json"
    assert run_r2s("scene", str(excerpt_frames), "scene-0103/0", "--radius", "10", "--out", str(scene)).returncode == 0
    doc = json.loads(scene.read_text())
    assert {lane for e in doc["entities"] for lane in e.get("lanes", [])} <= {f["id"] for f in doc["road"]["features"]}
    program = tmp_path / "p.scenic"
    proc = run_r2s("synth", str(scene), "--lanes", "--format", "scenic")
    assert proc.returncode == 0, proc.stderr
    program.write_text(proc.stdout)
    proc = run_r2s("sample", str(program), "--n", "2", "--out", str(tmp_path / "v"))
    assert proc.returncode == 0, proc.stderr
