"""Every source fills `speed` (m/s, the ground velocity's magnitude, null where unknown), each as the data gives it,
checked against values computed here from the files by other means (plain JSON, pickles and Feather tables):
ScenarioNet's state.velocity, nuScenes' centred differences of annotations and ego poses, Argoverse 2 tracks
differenced in the city frame, MCAP / ROS tracks differenced or taken from odometry. And the Done-when: real
ScenarioNet frames synthesized with --motion are certified optimal programs."""

from __future__ import annotations

import json
import math
import random

import numpy as np
import pandas as pd
import pyarrow as pa
import pytest
from hypothesis import given
from hypothesis import strategies as st

from extractors.argoverse2 import extract as extract_av2
from extractors.base import ExtractOptions
from extractors.categories import ALL, VEHICLES
from extractors.mcap import extract as extract_mcap
from extractors.nuscenes import extract as extract_nuscenes
from extractors.rosbag import extract as extract_rosbag
from extractors.scenarionet import extract as extract_scenarionet
from extractors.scenarionet import scenario_frames
from extractors.speed import MAX_GAP_S, track_speeds
from frames.rows import iter_scenes
from synth.config import SynthConfig
from synth.dsl import parse_program
from synth.semantics import check
from synth.synthesize import synthesize
from tests.support import logs as fx
from tests.support.bruteforce import optimal_cost
from tests.support.extract import EXCERPT, frames_of
from tests.support.scenarionet_layouts import as_waymo, load_real

SCENARIONET = EXCERPT / "scenarionet"
TABLES = EXCERPT / "v1.0-mini"
AV2 = __import__("pathlib").Path(__file__).resolve().parents[1] / "data" / "argoverse2"


@given(st.lists(st.floats(0.01, 0.9), min_size=1, max_size=12), st.floats(-20, 20), st.floats(-20, 20))
def test_track_differences_recover_a_constant_velocity_where_a_neighbour_is_close(gaps, vx, vy):
    t = np.concatenate(([0.0], np.cumsum(gaps)))
    got = track_speeds(t, 3.0 + vx * t, -1.0 + vy * t)
    for i in range(len(t)):
        close = (i > 0 and t[i] - t[i - 1] <= MAX_GAP_S) or (i + 1 < len(t) and t[i + 1] - t[i] <= MAX_GAP_S)
        if close:
            assert got[i] == pytest.approx(math.hypot(vx, vy), rel=1e-9, abs=1e-9)
        else:
            assert math.isnan(got[i])


def test_a_turn_is_differenced_across_its_neighbours_not_smoothed():
    t = np.array([0.0, 0.1, 0.2])
    got = track_speeds(t, np.array([0.0, 1.0, 1.0]), np.array([0.0, 0.0, 1.0]))
    assert got.tolist() == pytest.approx([10.0, math.hypot(1, 1) / 0.2, 10.0])


# ---------------------------------------------------------------------------------------------- ScenarioNet


def _velocity_norms(sd: dict, step: int) -> dict[str, float]:
    return {str(k): float(np.hypot(*np.asarray(tr["state"]["velocity"], dtype=float).reshape(-1, 2)[step]))
            for k, tr in sd["tracks"].items()}


@pytest.mark.parametrize("layout", ["nuscenes", "waymo"])
def test_scenarionet_speed_is_the_norm_of_state_velocity(layout, tmp_path):
    path = sorted(SCENARIONET.glob("sd_*.pkl"))[0]
    sd = load_real(path)
    if layout == "waymo":
        sd = as_waymo(sd)
    rows = pd.DataFrame([r for f in scenario_frames(path, sd, ExtractOptions(categories=ALL)) for r in f])
    stride = 5 if layout == "nuscenes" else 1  # nuScenes-derived scenarios: keyframes every 5 steps
    ego_track = str(sd["metadata"]["sdc_id"])
    for fid, frame in rows.groupby("frame_id"):
        norms = _velocity_norms(sd, int(fid.split("/")[1]) * stride)
        expected = frame.track_id.map(norms).where(~frame.is_ego, norms[ego_track])
        assert np.allclose(frame.speed, expected, rtol=1e-6, atol=1e-6), fid
    assert rows.speed.notna().all() and (rows.speed > 1).any()


def test_scenarionet_without_velocity_gives_null_speeds():
    path = sorted(SCENARIONET.glob("sd_*.pkl"))[0]
    sd = load_real(path)
    for tr in sd["tracks"].values():
        tr["state"].pop("velocity")
    rows = [r for f in scenario_frames(path, sd, ExtractOptions(categories=ALL)) for r in f]
    assert rows and all(r["speed"] is None for r in rows)


@pytest.fixture(scope="module")
def scenarionet_vehicles() -> list:
    return list(iter_scenes(frames_of(extract_scenarionet, SCENARIONET, categories=VEHICLES)))


def test_real_scenarionet_frames_give_certified_optimal_motion_programs(scenarionet_vehicles):
    config = SynthConfig(motion=True)
    kinds = set()
    for scene in scenarionet_vehicles:
        result = synthesize(scene, config)
        assert result.status == "optimal" and result.certified
        assert result.cost == optimal_cost(scene, config)  # the independent subset DP, with motion
        program = parse_program(str(result.program))
        assert check(program, scene, config).ok
        kinds |= {type(s.motion).__name__ for s in program.statements}
    assert {"Stationary", "MovingLike", "RelativeSpeed"} <= kinds  # real traffic uses all three


# ---------------------------------------------------------------------------------------------- nuScenes


def _tables() -> dict[str, dict[str, dict]]:
    return {n: {r["token"]: r for r in json.loads((TABLES / f"{n}.json").read_text())}
            for n in ("sample", "sample_annotation", "sample_data", "ego_pose", "scene")}


def _centred(first: dict, last: dict, t0: int, t1: int, both: bool) -> float | None:
    """nuScenes' rule (devkit box_velocity), from the JSON: (p_last - p_first) / dt within 1.5 s (3 s centred)."""
    dt = (t1 - t0) * 1e-6
    if dt <= 0 or dt > (3.0 if both else 1.5):
        return None
    return math.hypot(last[0] - first[0], last[1] - first[1]) / dt


def test_nuscenes_speeds_are_centred_differences_of_annotations_and_ego_poses():
    t = _tables()
    lidar = {sd["sample_token"]: sd for sd in t["sample_data"].values()}

    def ego_xy(sample_token):
        return t["ego_pose"][lidar[sample_token]["ego_pose_token"]]["translation"]

    rows = frames_of(extract_nuscenes, EXCERPT, categories=ALL)
    expected = {}
    scene_of = {s["name"]: s["first_sample_token"] for s in t["scene"].values()}
    for name, token in scene_of.items():
        k = 0
        while token:
            s = t["sample"][token]
            a, b = t["sample"].get(s["prev"]) or s, t["sample"].get(s["next"]) or s
            ego = None if a is b else _centred(ego_xy(a["token"]), ego_xy(b["token"]), a["timestamp"], b["timestamp"],
                                               bool(s["prev"] and s["next"]))
            expected[(f"{name}/{k}", "ego")] = ego
            for ann in (x for x in t["sample_annotation"].values() if x["sample_token"] == token):
                p, n = t["sample_annotation"].get(ann["prev"]) or ann, t["sample_annotation"].get(ann["next"]) or ann
                v = None if p is n else _centred(p["translation"], n["translation"],
                                                 t["sample"][p["sample_token"]]["timestamp"],
                                                 t["sample"][n["sample_token"]]["timestamp"],
                                                 bool(ann["prev"] and ann["next"]))
                expected[(f"{name}/{k}", ann["instance_token"])] = v
            token, k = s["next"], k + 1
    got = {(r.frame_id, "ego" if r.is_ego else r.track_id): r.speed for r in rows.itertuples()}
    assert set(got) <= set(expected) and len(got) == len(rows)
    for key, v in got.items():
        if expected[key] is None:
            assert math.isnan(v), key
        else:
            assert v == pytest.approx(expected[key], rel=1e-9), key
    assert rows.speed.isna().sum() < len(rows) // 5


# ---------------------------------------------------------------------------------------------- Argoverse 2


def _write_feather(path, columns: dict) -> None:
    table = pa.table(columns)
    with pa.OSFile(str(path), "wb") as sink, pa.ipc.new_file(sink, table.schema) as w:
        w.write_table(table)


def test_argoverse2_tracks_are_differenced_in_the_city_frame(tmp_path):
    # The ego drives a quarter circle at 8 m/s; a car ahead moves at 5 m/s along the city's +y; a parked truck;
    # a pedestrian seen twice 1.2 s apart (no neighbour within 0.5 s: unknown). Boxes are given in the ego frame,
    # as Argoverse 2 annotates them, and the city poses beside them, as city_SE3_egovehicle.feather holds them.
    log = tmp_path / "0123abcd-log"
    log.mkdir()
    stamps = np.array([0, 100, 200, 300, 1500], dtype=np.int64) * 1_000_000 + 315_966_000_000_000_000
    ts = (stamps - stamps[0]) * 1e-9
    radius, omega = 40.0, 8.0 / 40.0
    ex, ey, eyaw = radius * np.sin(omega * ts), radius * (1 - np.cos(omega * ts)), omega * ts
    world = {"car": (np.full(5, 10.0), 20.0 + 5.0 * ts), "truck": (np.full(5, -6.0), np.full(5, 12.0)),
             "ped": (3.0 + 1.0 * ts, np.full(5, -4.0))}
    rows: dict[str, list] = {c: [] for c in ("timestamp_ns", "track_uuid", "category", "length_m", "width_m",
                                             "qw", "qx", "qy", "qz", "tx_m", "ty_m")}
    for k, stamp in enumerate(stamps):
        for uuid, (wx, wy) in world.items():
            if uuid == "ped" and k not in (0, 4):
                continue
            c, s = math.cos(eyaw[k]), math.sin(eyaw[k])
            dx, dy = wx[k] - ex[k], wy[k] - ey[k]
            for col, v in (("timestamp_ns", stamp), ("track_uuid", uuid), ("category",
                           {"car": "REGULAR_VEHICLE", "truck": "BOX_TRUCK", "ped": "PEDESTRIAN"}[uuid]),
                           ("length_m", 4.0), ("width_m", 2.0), ("qw", 1.0), ("qx", 0.0), ("qy", 0.0), ("qz", 0.0),
                           ("tx_m", c * dx + s * dy), ("ty_m", -s * dx + c * dy)):
                rows[col].append(v)
    _write_feather(log / "annotations.feather", rows)
    _write_feather(log / "city_SE3_egovehicle.feather", {
        "timestamp_ns": stamps, "qw": np.cos(eyaw / 2), "qx": np.zeros(5), "qy": np.zeros(5), "qz": np.sin(eyaw / 2),
        "tx_m": ex, "ty_m": ey, "tz_m": np.zeros(5)})
    df = frames_of(extract_av2, log, categories=ALL)
    by = {(r.frame_id, r.category): r.speed for r in df.itertuples()}
    chord = 2 * radius * math.sin(omega * 0.1) / 0.2  # the centred difference over a 0.2 s arc
    for k in range(4):
        fid = f"{log.name}/{k}"
        assert by[(fid, "REGULAR_VEHICLE")] == pytest.approx(5.0, rel=1e-9)
        assert by[(fid, "BOX_TRUCK")] == pytest.approx(0.0, abs=1e-9)
        one_sided = 2 * radius * math.sin(omega * 0.05) / 0.1
        assert by[(fid, "EGO_VEHICLE")] == pytest.approx(chord if k in (1, 2) else one_sided, rel=1e-9)
    assert math.isnan(by[(f"{log.name}/0", "PEDESTRIAN")]) and math.isnan(by[(f"{log.name}/4", "PEDESTRIAN")])
    assert math.isnan(by[(f"{log.name}/4", "REGULAR_VEHICLE")])  # 1.2 s after its last neighbour
    (log / "city_SE3_egovehicle.feather").unlink()
    assert frames_of(extract_av2, log, categories=ALL).speed.isna().all()  # no city poses: no ground speeds


def test_argoverse2_real_excerpt_ego_speed_from_its_poses():
    def read(path):
        with pa.memory_map(str(path)) as src:
            return pa.ipc.open_file(src).read_all().to_pandas()

    df = frames_of(extract_av2, AV2, categories=ALL)
    for log in ("7fab2350-7eaf-3b7e-a39d-6937a4c1bede", "3b3570b4-7b0b-3268-a571-b0889dbf40b6"):
        poses = read(AV2 / log / "city_SE3_egovehicle.feather").sort_values("timestamp_ns")
        t, x, y = poses.timestamp_ns.to_numpy(), poses.tx_m.to_numpy(), poses.ty_m.to_numpy()
        ego = df[(df.scene == log) & df.is_ego].sort_values("frame_index").speed.to_numpy()
        for k in range(len(t)):
            a, b = max(k - 1, 0), min(k + 1, len(t) - 1)
            assert ego[k] == pytest.approx(math.hypot(x[b] - x[a], y[b] - y[a]) / ((t[b] - t[a]) * 1e-9), rel=1e-9)
    assert df.speed.notna().mean() > 0.9


# ---------------------------------------------------------------------------------------------- MCAP / ROS


@pytest.fixture(scope="module")
def nuscenes_truth() -> pd.DataFrame:
    return frames_of(extract_nuscenes, EXCERPT, categories=ALL, scenes=("scene-0103",))


def _agree(got: pd.DataFrame, truth: pd.DataFrame, ego_too: bool = True) -> None:
    """Speeds of the same entities (frame, distance-ranked id) agree wherever both are known; most are."""
    m = got.merge(truth, on=["frame_id", "entity_id"], suffixes=("", "_truth"))
    assert len(m) == len(truth)
    if not ego_too:
        m = m[~m.is_ego]
    both = m.speed.notna() & m.speed_truth.notna()
    assert both.mean() > 0.8
    assert np.allclose(m.speed[both], m.speed_truth[both], rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("layout", ["foxglove_protobuf", "ros2_mcap"])
def test_mcap_tracks_are_differenced_and_agree_with_nuscenes(tmp_path, nuscenes_truth, layout):
    # Keyframes 0.5 s apart: the differences over neighbouring messages are nuScenes' centred differences.
    samples = fx.scenes()["scene-0103"]
    path = tmp_path / "log.mcap"
    getattr(fx, f"write_{layout}")(path, samples)
    topics = ("/detections",) if layout == "ros2_mcap" else ()
    got = frames_of(extract_mcap, path, categories=ALL, topics=topics)
    got["frame_id"] = got.frame_id.str.replace("log/", "scene-0103/")
    _agree(got, nuscenes_truth)


def test_ros1_odometry_gives_the_ego_speed(tmp_path, nuscenes_truth):
    samples = fx.scenes()["scene-0103"]
    rng = random.Random(3)
    twist = [(rng.uniform(-12, 12), rng.uniform(-1, 1)) for _ in samples]
    path = tmp_path / "log.bag"
    fx.write_rosbag1(path, samples, twist=twist)
    got = frames_of(extract_rosbag, path, categories=ALL, pose_topic="/odom")
    ego = got[got.is_ego].sort_values("frame_index").speed.to_numpy()
    assert ego == pytest.approx([math.hypot(*v) for v in twist], rel=1e-12)
    got["frame_id"] = got.frame_id.str.replace("log/", "scene-0103/")
    _agree(got, nuscenes_truth, ego_too=False)  # the markers are differenced in the map frame
