"""`r2s extract` keeps each scenario's map (Maps Parquet) and the lane facts of every entity, as a user runs it:
the maps read back as the maps the source gives; the facts equal an independent recomputation (world positions
from the recording itself, containment by shapely / GEOS, and on the Argoverse 2 test log av2's own map API);
a malformed map is one line and exit 2 with nothing written; a source without a map works as before."""

from __future__ import annotations

import pickle
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import shapely

from extractors.safe_pickle import load_pickle
from extractors.scenarionet import scenario_map
from frames.maps import maps_dir, read_maps
from tests.support import SHARED
from tests.support.extract import EXCERPT, assert_refused, r2s

SCENARIONET = EXCERPT / "scenarionet"
AV2_LOG = SHARED / "data" / "argoverse2" / "test_data" / "sensor_dataset_logs" / "adcf7d18-0510-35b0-a2fa-b4cea13a6d76"


def world_facts(frames: pd.DataFrame, maps: pd.DataFrame, places: dict[tuple[str, str], tuple[float, float]]) -> dict:
    """The lanes, intersection and off-road facts of each (frame, entity) placed in `places` (world x, y), by
    GEOS's covers over the polygons of the maps file."""
    polys = {}
    for r in maps.itertuples():
        if len(r.polygon_x):
            polys.setdefault(r.map_id, []).append((r.feature_id, r.kind, r.is_intersection,
                                                   shapely.Polygon(list(zip(r.polygon_x, r.polygon_y)))))
    out = {}
    for r in frames.itertuples():
        if (r.frame_id, r.entity_id) not in places:
            continue
        p = shapely.Point(places[r.frame_id, r.entity_id])
        inside = [(fid, kind, inter) for fid, kind, inter, poly in polys[r.map_id] if poly.covers(p)]
        lanes = sorted(fid for fid, kind, _ in inside if kind == "lane")
        kinds = {kind for _, kind, _ in inside}
        in_intersection = "intersection" in kinds or any(inter for _, kind, inter in inside if kind == "lane")
        out[r.frame_id, r.entity_id] = (lanes, in_intersection, not lanes and "drivable_area" not in kinds,
                                        "crosswalk" in kinds)
    return out


def test_scenarionet_maps_and_lane_facts_match_an_independent_recomputation(tmp_path, capsys):
    out = tmp_path / "frames"
    res = r2s(capsys, "extract", "scenarionet", str(SCENARIONET), "--categories", "all", "--out", str(out))
    assert res.returncode == 0, res.stderr
    frames = pd.read_parquet(out)
    maps = pd.read_parquet(out / "_maps")
    # every frame names its scenario's map, written once
    assert (frames.map_id == frames.scene).all()
    assert sorted(maps.drop_duplicates("map_id").map_id) == sorted(frames.scene.unique())
    assert not maps.duplicated(["map_id", "feature_id"]).any()

    places = {}
    for f in sorted(SCENARIONET.glob("sd_*.pkl")):
        sd = load_pickle(f)
        scene = sd["metadata"]["scenario_id"]
        # the maps read back are the maps of the source
        (back,) = read_maps(out / "_maps", {scene})
        assert back == scenario_map(scene, sd["map_features"], "nuscenes")
        # world positions straight from the recording: keyframe k is step 5k
        mine = frames[frames.scene == scene]
        for r in mine.itertuples():
            track = sd["tracks"][sd["metadata"]["sdc_id"] if r.is_ego else r.track_id]
            x, y = np.asarray(track["state"]["position"])[5 * r.frame_index, :2]
            places[r.frame_id, r.entity_id] = (float(x), float(y))
    want = world_facts(frames, maps, places)
    assert len(want) == len(frames)
    got = {(r.frame_id, r.entity_id): (sorted(r.lanes), r.in_intersection, r.off_road, r.on_crosswalk)
           for r in frames.itertuples()}
    assert got == want
    # the facts are not all alike: entities on lanes, in intersections and off the road all occur
    assert frames.lane.notna().any() and frames.in_intersection.any() and frames.off_road.any()
    # the chosen lane is one of the lanes
    assert all(r.lane in r.lanes if len(r.lanes) else r.lane is None for r in frames.itertuples())


@pytest.mark.skipif(not AV2_LOG.is_dir(), reason="needs ../shared/data/argoverse2 (the av2-api test log with a map)")
def test_argoverse2_lane_facts_agree_with_av2_s_own_map_api(tmp_path, capsys):
    av2_map = pytest.importorskip("av2.map.map_api", reason="needs av2 (pip install av2 --no-deps: see Makefile)")
    from av2.geometry.geometry import quat_to_mat
    from av2.utils.io import read_feather

    log = tmp_path / AV2_LOG.name
    shutil.copytree(AV2_LOG, log)
    out = tmp_path / "frames.parquet"
    res = r2s(capsys, "extract", "argoverse2", str(log), "--categories", "all", "--out", str(out))
    assert res.returncode == 0, res.stderr
    frames = pd.read_parquet(out)
    assert (frames.map_id == AV2_LOG.name).all() and frames.lanes.notna().all()

    static = av2_map.ArgoverseStaticMap.from_json(next((log / "map").glob("log_map_archive_*.json")))
    lanes = {str(i): shapely.Polygon(s.polygon_boundary[:, :2]) for i, s in static.vector_lane_segments.items()}
    crossings = [shapely.Polygon(c.polygon[:, :2]) for c in static.vector_pedestrian_crossings.values()]
    areas = [shapely.Polygon(a.xyz[:, :2]) for a in static.vector_drivable_areas.values()]
    # box centres in the city by av2's own reading of the poses, on the ground plane (yaw only, as documented)
    poses = read_feather(log / "city_SE3_egovehicle.feather").set_index("timestamp_ns")
    boxes = read_feather(log / "annotations.feather")
    stamps = sorted(boxes.timestamp_ns.unique())
    # each box's centre by (stamp, track) and each stamp's yaw, looked up once (a filter of the whole table per row
    # made this test quadratic in the log's boxes)
    centre = {(t, u): np.array([x, y]) for t, u, x, y in
              zip(boxes.timestamp_ns, boxes.track_uuid, boxes.tx_m, boxes.ty_m)}
    yaws: dict = {}
    points = []
    for r in frames.itertuples():
        stamp = stamps[r.frame_index]
        pose = poses.loc[stamp]
        if stamp not in yaws:
            rot = quat_to_mat(pose[["qw", "qx", "qy", "qz"]].to_numpy(dtype=float))
            yaws[stamp] = np.arctan2(rot[1, 0], rot[0, 0])
        yaw = yaws[stamp]
        local = np.zeros(2) if r.is_ego else centre[(stamp, r.track_id)]
        c, s = np.cos(yaw), np.sin(yaw)
        points.append(shapely.Point(pose.tx_m + c * local[0] - s * local[1], pose.ty_m + s * local[0] + c * local[1]))
    points = np.array(points, dtype=object)
    # shapely's covers, one call per map polygon over every point (the same predicate, vectorised)
    covered = {i: shapely.covers(poly, points) for i, poly in lanes.items()}
    on_crossing = np.any([shapely.covers(c, points) for c in crossings], axis=0)
    on_area = np.any([shapely.covers(a, points) for a in areas], axis=0)
    checked = near_edge = 0
    for k, r in enumerate(frames.itertuples()):
        p = points[k]
        want_lanes = sorted(i for i in lanes if covered[i][k])
        want = (want_lanes, any(static.lane_is_in_intersection(int(i)) for i in want_lanes),
                bool(on_crossing[k]), not want_lanes and not on_area[k])
        got = (sorted(r.lanes), r.in_intersection, r.on_crosswalk, r.off_road)
        checked += 1
        if got != want:
            # two computations of the same pose may differ in the last bits: only a point a micrometre from an
            # edge may come out differently
            edges = [poly.exterior for poly in [*lanes.values(), *crossings, *areas]]
            assert min(e.distance(p) for e in edges) < 1e-6, (r.frame_id, r.entity_id, got, want)
            near_edge += 1
    assert checked == len(frames) and near_edge <= checked // 1000


def _write_scenario(sd: dict, folder: Path) -> Path:
    folder.mkdir()
    path = folder / "sd_broken.pkl"
    with open(path, "wb") as fh:
        pickle.dump(sd, fh, protocol=4)
    return path


def _a_lane(sd: dict) -> tuple[str, dict]:
    return next((k, v) for k, v in sd["map_features"].items() if "polygon" in v)


@pytest.mark.parametrize("break_it, message", [
    (lambda f: f["polygon"].__setitem__((1, 0), np.nan), "polygon point that is not two finite numbers"),
    (lambda f: f.__setitem__("polygon", np.array([[0.0, 0.0], [4.0, 4.0], [4.0, 0.0], [0.0, 4.0]])),
     "self-intersecting polygon"),
    (lambda f: f.__setitem__("left_neighbor", [{"feature_id": "no-such-lane"}]),
     "left neighbour 'no-such-lane', which is not a lane of the map"),
])
def test_a_feature_breaking_a_map_rule_is_dropped_and_counted_or_refused_with_strict_maps(tmp_path, capsys, break_it,
                                                                                          message):
    sd = load_pickle(sorted(SCENARIONET.glob("sd_*.pkl"))[0])
    fid, feature = _a_lane(sd)
    feature = {**feature, "polygon": np.array(feature["polygon"], dtype=float)}
    break_it(feature)
    sd["map_features"][fid] = feature
    path = _write_scenario(sd, tmp_path / "in")
    for out in (tmp_path / "file" / "frames.parquet", tmp_path / "dataset" / "frames"):
        res = r2s(capsys, "extract", "scenarionet", str(path), "--out", str(out), "--strict-maps")
        assert_refused(res, out, message)
        assert f"lane {fid!r}" in res.stderr
        # without --strict-maps: the frames and the rest of the map, the feature (or its link) dropped and counted
        res = r2s(capsys, "extract", "scenarionet", str(path), "--out", str(out))
        assert res.returncode == 0, res.stderr
        kind = "lane links to no lane dropped" if "neighbour" in message else "features breaking a map rule dropped"
        assert f"map repairs: 1 {kind}" in res.stderr.splitlines()[-1]
        maps = pd.read_parquet(maps_dir(out) if out.suffix else out / "_maps")
        lane = maps[maps.feature_id == fid]
        assert lane.left_neighbour.isna().all() if "neighbour" in message else lane.empty
        assert len(pd.read_parquet(out)) > 0


@pytest.mark.parametrize("polygon", [
    [[0.0, 0.0], [10 ** 400, 0.0], [4.0, 4.0]],  # an int beyond a float (was a traceback)
    [[0.0, 0.0], [4.0, 0.0, 1.0], [4.0, 4.0]],  # points of different lengths
    [[0.0, 0.0], ["four", 0.0], [4.0, 4.0]],
])
def test_a_polygon_not_of_numbers_is_one_line_exit_2_with_strict_maps(tmp_path, capsys, polygon):
    sd = load_pickle(sorted(SCENARIONET.glob("sd_*.pkl"))[0])
    fid, feature = _a_lane(sd)
    sd["map_features"][fid] = {**feature, "polygon": polygon}
    path = _write_scenario(sd, tmp_path / "in")
    out = tmp_path / "out" / "frames.parquet"
    res = r2s(capsys, "extract", "scenarionet", str(path), "--out", str(out), "--strict-maps")
    assert_refused(res, out, f"feature {fid!r} has a polygon that is not an array of numbers")


def test_a_source_without_a_map_works_as_before(tmp_path, capsys):
    out = tmp_path / "frames"
    res = r2s(capsys, "extract", "nuscenes", str(EXCERPT), "--out", str(out))
    assert res.returncode == 0, res.stderr
    frames = pd.read_parquet(out)
    assert frames.map_id.isna().all() and frames.lanes.isna().all() and not (out / "_maps").exists()
