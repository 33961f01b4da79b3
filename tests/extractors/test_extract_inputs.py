"""What `r2s extract` says about its inputs (issue 13): an unknown --categories value, for every source, exits 2
with the known names and the closest one, before anything is read or written; an input of one source given to
another gets a line naming what it looks like and the `r2s extract SOURCE` that reads it; the end-of-extract
line counts scenarios, frames and rows."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from extractors.registry import SOURCES
from extractors.registry import source as source_of
from extractors.sniff import looks_like
from frames.rows import read_frames
from synth.scene import ENTITY_TYPES
from tests.support import logs as fx
from tests.support.extract import EXCERPT, assert_refused, r2s

AV2 = Path(__file__).resolve().parents[1] / "data" / "argoverse2"
SCENE = "scene-0103"


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    """A real input of every source: the shipped excerpts, and logs written from the same nuScenes keyframes."""
    d = tmp_path_factory.mktemp("inputs")
    samples = fx.scenes()[SCENE]
    fx.write_foxglove_protobuf(d / f"{SCENE}.mcap", samples)
    fx.write_rosbag1(d / f"{SCENE}.bag", samples)
    fx.write_rosbag2(d / "ros2bag", samples, "sqlite3")
    nus = d / "nuscenes"  # a nuScenes dataroot alone (the excerpt folder also holds the ScenarioNet pickles)
    shutil.copytree(EXCERPT / "v1.0-mini", nus / "v1.0-mini")
    shutil.copytree(EXCERPT / "maps", nus / "maps")
    return {"nuscenes": nus, "scenarionet": EXCERPT / "scenarionet", "argoverse2": AV2,
            "mcap": d / f"{SCENE}.mcap", "rosbag": d / f"{SCENE}.bag", "rosbag2": d / "ros2bag"}


def test_every_source_declares_the_taxonomy_its_categories_are_checked_against():
    for name in SOURCES:
        taxonomy = source_of(name).taxonomy
        assert source_of(name).name == name
        assert taxonomy.classes and set(taxonomy.classes.values()) <= set(ENTITY_TYPES)


@pytest.mark.parametrize("source", list(SOURCES))
@pytest.mark.parametrize("value, closest", [("vehicle.carr", "vehicle.car"), ("Cars", "Car"),
                                            ("Pedestrian,trafic_cone", None), ("foo", None)])
def test_unknown_categories_value_exits_2_with_known_names_and_closest(tmp_path, capsys, inputs, source, value,
                                                                       closest):
    out = tmp_path / "out" / "frames.parquet"
    res = r2s(capsys, "extract", source, str(inputs[source]), "--out", str(out), "--categories", value)
    bad = value.split(",")[-1]
    assert_refused(res, out, f"unknown category {bad!r} in --categories")
    line = res.stderr
    # the known names: every class and every raw category of the source's taxonomy
    raw = source_of(source).taxonomy.classes
    assert all(c in line for c in ENTITY_TYPES) and all(r in line for r in raw)
    assert "closest: '" in line
    if closest in set(ENTITY_TYPES) | set(raw):
        assert f"closest: {closest!r}" in line


@pytest.mark.parametrize("source", list(SOURCES))
def test_known_names_and_their_prefixes_are_accepted(tmp_path, capsys, inputs, source):
    # a class, a raw name of the source's own taxonomy and a dotted prefix where it has dotted names
    raw = {"nuscenes": "human.pedestrian", "scenarionet": "VEHICLE,human", "argoverse2": "REGULAR_VEHICLE",
           "mcap": "vehicle,CYCLIST", "rosbag": "vehicle.car"}[source]
    out = tmp_path / "frames.parquet"
    opts = ["--pose-topic", "/odom"] if source == "rosbag" else []
    res = r2s(capsys, "extract", source, str(inputs[source]), "--out", str(out), "--categories", f"Truck,{raw}",
              *opts)
    assert res.returncode == 0, res.stderr
    assert set(read_frames(out).type) <= {"Car", "Truck", "Pedestrian", "Bicycle"}


def test_vehicles_inside_a_list_means_the_vehicle_classes(tmp_path, capsys, inputs):
    out = tmp_path / "frames.parquet"
    res = r2s(capsys, "extract", "scenarionet", str(inputs["scenarionet"]), "--out", str(out),
              "--categories", "vehicles,Pedestrian")
    assert res.returncode == 0, res.stderr
    types = set(read_frames(out).type)
    assert "Pedestrian" in types and "Car" in types and not types & {"Barrier", "TrafficCone"}


WRONG = [  # (source asked for, input of, the source the line must name)
    ("nuscenes", "scenarionet", "scenarionet"),
    ("scenarionet", "nuscenes", "nuscenes"),
    ("scenarionet", "argoverse2", "argoverse2"),
    ("argoverse2", "scenarionet", "scenarionet"),
    ("rosbag", "mcap", "mcap"),
    ("mcap", "rosbag", "rosbag"),
    ("mcap", "rosbag2", "rosbag"),
    ("argoverse2", "rosbag2", "rosbag"),
    ("nuscenes", "mcap", "mcap"),
]


@pytest.mark.parametrize("asked, given, named", WRONG)
def test_wrong_source_names_what_the_input_looks_like_and_the_source_to_use(tmp_path, capsys, inputs, asked, given,
                                                                           named):
    out = tmp_path / "out" / "frames.parquet"
    path = inputs[given]
    res = r2s(capsys, "extract", asked, str(path), "--out", str(out))
    assert_refused(res, out, f"use `r2s extract {named} {path}`")
    assert f"{path} looks like " in res.stderr and f"not input of the {asked} source" in res.stderr
    if given == "scenarionet":
        assert "looks like a ScenarioNet database (dataset_summary.pkl)" in res.stderr
    # and the source it names does read it
    opts = ["--pose-topic", "/odom"] if given == "rosbag" else []
    assert r2s(capsys, "extract", named, str(path), "--out", str(out), *opts).returncode == 0


def test_the_version_folder_itself_points_to_its_dataroot(inputs):
    looks = looks_like(str(inputs["nuscenes"] / "v1.0-mini" / "sample.json"))
    assert [(x.source, x.path) for x in looks] == [("nuscenes", str(inputs["nuscenes"]))]


def test_an_input_that_looks_like_nothing_keeps_the_sources_own_message(tmp_path, capsys):
    empty = tmp_path / "empty"
    empty.mkdir()
    out = tmp_path / "out" / "frames.parquet"
    assert_refused(r2s(capsys, "extract", "scenarionet", str(empty), "--out", str(out)), out,
                   "holds no ScenarioNet .pkl files")


def test_a_folder_holding_inputs_of_the_asked_source_is_not_second_guessed(tmp_path, capsys):
    # the shipped excerpt holds a nuScenes dataroot and a ScenarioNet database: both sources read it
    out = tmp_path / "frames.parquet"
    for source in ("nuscenes", "scenarionet"):
        assert {x.source for x in looks_like(str(EXCERPT))} >= {source}
        res = r2s(capsys, "extract", source, str(EXCERPT), "--out", str(out))
        assert res.returncode == 0, res.stderr


def test_summary_line_counts_scenarios_frames_and_rows(tmp_path, capsys):
    out = tmp_path / "frames.parquet"
    res = r2s(capsys, "extract", "scenarionet", str(EXCERPT / "scenarionet"), "--out", str(out),
              "--categories", "all")
    df = read_frames(out)
    assert res.stderr == (f"r2s extract: {df.scene.nunique()} scenarios, {df.frame_id.nunique()} frames, "
                          f"{len(df)} rows -> {out}\n")
    assert df.scene.nunique() == 3


@pytest.mark.parametrize("source,path", [("scenarionet", EXCERPT / "scenarionet"), ("nuscenes", EXCERPT)])
@pytest.mark.parametrize("categories", ["vehicles", "Pedestrian", "Car,Barrier", "human.pedestrian"])
def test_the_summary_says_what_categories_left_out_by_type(tmp_path, capsys, source, path, categories):
    """Nothing filtered silently: the boxes --categories left out, counted by type, are exactly those that an
    extraction of every type has and this one lacks (the same frames, radius and ids)."""
    every = tmp_path / "all.parquet"
    assert r2s(capsys, "extract", source, str(path), "--out", str(every)).returncode == 0
    chosen = tmp_path / "chosen.parquet"
    res = r2s(capsys, "extract", source, str(path), "--categories", categories, "--out", str(chosen))
    assert res.returncode == 0, res.stderr
    a, c = read_frames(every), read_frames(chosen)
    a, c = a[~a.is_ego], c[~c.is_ego]
    dropped = a[~a.set_index(["frame_id", "entity_id"]).index.isin(c.set_index(["frame_id", "entity_id"]).index)]
    want = dropped.type.value_counts()
    assert len(want), "the selection should leave something out"
    listing = ", ".join(f"{t} x{n}" for t, n in sorted(want.items(), key=lambda kv: (-kv[1], kv[0])))
    assert f"--categories left out {len(dropped)} boxes within --radius ({listing})" in res.stderr, res.stderr
    # every type kept is named nowhere in the listing
    assert not set(c.type) & set(want.index)


def test_all_categories_leave_nothing_out_and_say_nothing(tmp_path, capsys):
    res = r2s(capsys, "extract", "scenarionet", str(EXCERPT / "scenarionet"), "--out", str(tmp_path / "f.parquet"))
    assert res.returncode == 0 and "left out" not in res.stderr
