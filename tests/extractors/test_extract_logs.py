"""MCAP and ROS bag extractors on files written here from real nuScenes values, in the layouts real tools write:
what comes out equals what went in (the same ego-frame boxes as the ScenarioNet path gives for the same
keyframes). Bad files (truncated, foreign, decompression bombs, unknown topics) exit 2 and write nothing."""

from __future__ import annotations

import struct

import numpy as np
import pandas as pd
import pytest

from extractors.base import ExtractError
from extractors.categories import ALL
from extractors.mcap import extract as extract_mcap
from extractors.messages import LogOptions
from extractors.rosbag import extract as extract_rosbag
from extractors.scenarionet import extract as extract_scenarionet
from tests.support import logs as fx
from tests.support.extract import EXCERPT, assert_refused, frames_of, r2s

SCENE = "scene-0103"  # 4 keyframes, 20-33 boxes within 50 m


@pytest.fixture(scope="module")
def samples():
    return fx.scenes()[SCENE]


@pytest.fixture(scope="module")
def truth():
    df = frames_of(extract_scenarionet, EXCERPT / "scenarionet" / f"sd_nuscenes_v1.0-mini_{SCENE}.pkl",
                   categories=ALL)
    return df


def _same_boxes(got: pd.DataFrame, truth: pd.DataFrame, samples) -> None:
    assert list(dict.fromkeys(got.frame_id)) == list(dict.fromkeys(truth.frame_id))
    key = ["frame_id", "entity_id"]
    g = got[~got.is_ego].sort_values(key).reset_index(drop=True)
    t = truth[~truth.is_ego].sort_values(key).reset_index(drop=True)
    assert len(g) == len(t)
    assert g[["frame_id", "entity_id", "type", "category"]].equals(t[["frame_id", "entity_id", "type", "category"]])
    assert np.abs(g.x - t.x).max() < 1e-6 and np.abs(g.y - t.y).max() < 1e-6
    gap = (g.heading - t.heading) % 360.0
    assert np.minimum(gap, 360.0 - gap).max() < 1e-6
    assert np.abs(g.length - t.length).max() < 1e-5 and np.abs(g.width - t.width).max() < 1e-5
    assert (got.groupby("frame_id").is_ego.sum() == 1).all()
    stamps = sorted(set(got.timestamp_us))
    assert stamps == [s.t_ns // 1000 for s in samples]


WRITERS = {
    "foxglove-protobuf": (lambda p, s: fx.write_foxglove_protobuf(p, s), {}),
    "foxglove-json-zstd": (lambda p, s: fx.write_foxglove_json(p, s, "zstd"), {}),
    "foxglove-json-lz4": (lambda p, s: fx.write_foxglove_json(p, s, "lz4"), {}),
    "ros2-detections-base_link": (fx.write_ros2_mcap, {"topics": ("/detections",)}),
    "ros2-markers-map-tf": (fx.write_ros2_mcap, {"topics": ("/markers",)}),
}


@pytest.mark.parametrize("layout", list(WRITERS))
def test_mcap_layouts_give_back_what_went_in(tmp_path, samples, truth, layout):
    write, opts = WRITERS[layout]
    path = tmp_path / f"{SCENE}.mcap"
    write(path, samples)
    got = frames_of(extract_mcap, path, categories=ALL, **opts)
    _same_boxes(got, truth, samples)


@pytest.mark.parametrize("kind", ["ros2-sqlite3", "ros2-mcap", "ros1", "ros1-bz2", "ros1-lz4"])
def test_bags_give_back_what_went_in(tmp_path, samples, truth, kind):
    if kind.startswith("ros2"):
        path = tmp_path / SCENE
        fx.write_rosbag2(path, samples, kind.split("-")[1])
        opts = {}
    else:
        path = tmp_path / f"{SCENE}.bag"
        fx.write_rosbag1(path, samples, kind.split("-")[1] if "-" in kind else None)
        opts = {"pose_topic": "/odom"}
    got = frames_of(extract_rosbag, path, categories=ALL, **opts)
    _same_boxes(got, truth, samples)


def test_mcap_through_the_cli(tmp_path, capsys, samples):
    path = tmp_path / f"{SCENE}.mcap"
    fx.write_foxglove_protobuf(path, samples)
    out = tmp_path / "frames.parquet"
    res = r2s(capsys, "extract", "mcap", str(path), "--out", str(out), "--every", "2", "--categories", "vehicles")
    assert res.returncode == 0, res.stderr
    df = pd.read_parquet(out)
    assert list(dict.fromkeys(df.frame_id)) == [f"{SCENE}/0", f"{SCENE}/2"]
    assert set(df[~df.is_ego].type) <= {"Car", "Truck", "Bus", "Bicycle", "Motorcycle", "Trailer",
                                        "ConstructionVehicle"}


def _patch_first_chunk(data: bytes, uncompressed_size: int) -> bytes:
    """Rewrite the uncompressed_size field of the first Chunk record of an MCAP file."""
    pos = 8  # magic
    while pos < len(data):
        op, length = data[pos], struct.unpack_from("<Q", data, pos + 1)[0]
        if op == 0x06:
            field = pos + 9 + 16  # after message_start_time and message_end_time
            return data[:field] + struct.pack("<Q", uncompressed_size) + data[field + 8:]
        pos += 9 + length
    raise AssertionError("no chunk")


@pytest.mark.parametrize("case", ["truncated", "foreign", "bomb-claim", "bomb-lie", "limit", "topic", "frame",
                                  "no-pose"])
def test_bad_mcap_exits_2(tmp_path, capsys, samples, case):
    path = tmp_path / f"{SCENE}.mcap"
    fx.write_foxglove_json(path, samples)
    data = path.read_bytes()
    extra: list[str] = []
    expect = "not a readable MCAP"
    if case == "truncated":
        path.write_bytes(data[: len(data) // 2])
    elif case == "foreign":
        path.write_bytes(b"PK\x03\x04" + data[4:])
    elif case == "bomb-claim":
        path.write_bytes(_patch_first_chunk(data, 2**40))
        expect = "claims to decompress"
    elif case == "bomb-lie":
        path.write_bytes(_patch_first_chunk(data, 100))
        expect = "not the 100 it claims"
    elif case == "limit":
        extra = ["--max-chunk-mb", "0.001"]
        expect = "larger than the limit"
    elif case == "topic":
        extra = ["--topics", "/lidar"]
        expect = "no topic '/lidar'"
    elif case == "frame":
        extra = ["--fixed-frame", "world"]
        expect = "neither the fixed frame"
    else:
        extra = ["--pose-topic", "/markers/annotations"]
        expect = "not a pose"
    out = tmp_path / "out" / "frames.parquet"
    assert_refused(r2s(capsys, "extract", "mcap", str(path), "--out", str(out), *extra), out, expect)


@pytest.mark.parametrize("case", ["garbage", "truncated", "topic", "bz2-limit", "no-pose"])
def test_bad_bags_exit_2(tmp_path, capsys, samples, case):
    path = tmp_path / f"{SCENE}.bag"
    fx.write_rosbag1(path, samples, "bz2" if case == "bz2-limit" else None)
    extra = ["--pose-topic", "/odom"]
    expect = "not a readable bag"
    if case == "garbage":
        path.write_bytes(b"#ROSBAG V2.0\n" + bytes(range(256)) * 4)
    elif case == "truncated":
        path.write_bytes(path.read_bytes()[:5000])
        expect = str(path.name)
    elif case == "topic":
        extra += ["--topics", "/nope"]
        expect = "no topic '/nope'"
    elif case == "bz2-limit":
        extra += ["--max-chunk-mb", "0.001"]
        expect = "decompresses to more than"
    else:
        extra = []  # annotations in the map frame, and no /tf: the ego pose is missing
        expect = "no ego pose"
    out = tmp_path / "out" / "frames.parquet"
    assert_refused(r2s(capsys, "extract", "rosbag", str(path), "--out", str(out), *extra), out, expect)


def test_several_annotation_topics_need_a_choice(tmp_path, samples):
    path = tmp_path / "x.mcap"
    fx.write_ros2_mcap(path, samples)
    with pytest.raises(ExtractError, match="several annotation topics"):
        list(extract_mcap(str(path), LogOptions()))
