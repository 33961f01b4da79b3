"""`r2s export --to scenarionet`: a ScenarioNet database of the recorded frame and its variants. MetaDrive's own
format check accepts every scenario; `r2s extract scenarionet` on the database gives back each scene (world poses
restored and undone: within 1e-6 m / 1e-6 deg), and `r2s scene` on that gives back its road; the database reads
as ScenarioNet's tools read one (plain pickle, our restricted unpickler)."""

from __future__ import annotations

import json
import math
import pickle
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from extractors.safe_pickle import load_pickle
from extractors.scenarionet import TAXONOMY
from pipeline.export.scenarionet import TRACK_TYPES, file_name
from synth.scene import ENTITY_TYPES, scene_from_dict, scene_from_json
from tests.support import assert_one_line_error, run_r2s
from tests.support.extract import EXCERPT

from .conftest import FRAMES


def _gap(a: float, b: float) -> float:
    return abs((a - b + 180.0) % 360.0 - 180.0)


def _export(scene: Path, variants: Path | None, out: Path, *more: str):
    res = run_r2s("export", str(scene), *([str(variants)] if variants else []), "--to", "scenarionet",
                  "--out", str(out), *more)
    assert res.returncode == 0, res.stderr
    return res


def _database(db: Path) -> list[dict]:
    summary = pickle.loads((db / "dataset_summary.pkl").read_bytes())
    mapping = pickle.loads((db / "dataset_mapping.pkl").read_bytes())
    assert list(summary) == list(mapping) and set(mapping.values()) == {""}
    assert sorted(p.name for p in db.iterdir()) == sorted([*summary, "dataset_summary.pkl", "dataset_mapping.pkl"])
    assert load_pickle(db / "dataset_summary.pkl") == summary  # our restricted unpickler reads it too
    return [pickle.loads((db / name).read_bytes()) for name in summary]


def test_every_class_reads_back_as_itself():
    for cls, (_, own) in TRACK_TYPES.items():
        assert TAXONOMY.scenic_class(own) == cls
    assert set(TRACK_TYPES) == set(ENTITY_TYPES)


@pytest.mark.parametrize("fid", FRAMES)
def test_metadrive_s_format_check_accepts_every_scenario(fid, recorded, metadrive_format_check, tmp_path):
    scene, variants = recorded[fid]
    _export(scene, variants, tmp_path / "db", "--program", str(scene.with_name("scene.scenic")))
    scenarios = _database(tmp_path / "db")
    assert len(scenarios) == 6
    for sd in scenarios:
        metadrive_format_check(sd, check_self_type=True, valid_check=True)
        assert sd["map_features"], "a scene with a road exports its map"
        meta = sd["metadata"]["r2sgen"]
        assert meta["frame_id"] == fid and meta["program_file"] == "scene.scenic"
        assert meta["program"] == scene.with_name("scene.scenic").read_text()
    assert [sd["metadata"]["r2sgen"]["variant"] for sd in scenarios] == [None] + [
        f"sample_{k:03d}.json" for k in range(5)]


@pytest.mark.parametrize("fid", FRAMES)
def test_extracting_the_database_gives_back_every_scene(fid, recorded, tmp_path):
    scene_file, variants = recorded[fid]
    _export(scene_file, variants, tmp_path / "db")
    back = tmp_path / "back.parquet"
    res = run_r2s("extract", "scenarionet", str(tmp_path / "db"), "--categories", "all", "--radius", "100000",
                  "--out", str(back))
    assert res.returncode == 0, res.stderr
    df = pd.read_parquet(back)
    recorded_scene = scene_from_json(scene_file.read_text())
    base = fid.replace("/", "_")
    files = [(scene_file, base)] + [(f, f"{base}-{f.stem}") for f in sorted(variants.glob("*.json"))]
    assert df.frame_id.nunique() == len(files) == 6
    for f, name in files:
        scene = scene_from_json(f.read_text())
        rows = df[df.frame_id == f"{name}/0"].set_index("track_id")
        assert sorted(rows.index) == sorted(e.id for e in scene.entities)
        for e in scene.entities:
            r = rows.loc[e.id]
            assert math.hypot(r.x - e.x, r.y - e.y) < 1e-6 and _gap(r.heading, e.heading) < 1e-6
            assert r.type == e.type and r.is_ego == e.is_ego
            assert (r.length, r.width) == pytest.approx(e.dimensions(), rel=1e-6)
            assert r.speed == pytest.approx(e.speed if e.speed is not None else 0.0, abs=1e-9)
        # the world pose came back too: the re-extracted ego sits where the recording put it
        ego = rows.loc["ego"]
        w = recorded_scene.world
        assert math.hypot(ego.map_x - w.x, ego.map_y - w.y) < 1e-9 and _gap(ego.map_heading, w.heading) < 1e-9


def test_the_road_comes_back_through_extract_and_scene(recorded, tmp_path):
    scene_file, _ = recorded["scene-0103/0"]
    _export(scene_file, None, tmp_path / "db")
    back = tmp_path / "back"
    assert run_r2s("extract", "scenarionet", str(tmp_path / "db"), "--out", str(back)).returncode == 0
    res = run_r2s("scene", str(back), "scene-0103_0/0")
    assert res.returncode == 0, res.stderr
    original = json.loads(scene_file.read_text())["road"]["features"]
    again = {f["id"]: f for f in json.loads(res.stdout)["road"]["features"]}
    kept = [f for f in original if f["kind"] in ("lane", "road_line", "crosswalk")]
    assert kept and {f["id"] for f in kept} <= set(again)
    for f in kept:
        g = again[f["id"]]
        assert g["kind"] == f["kind"]
        for key in ("polygon", "line"):
            if key in f:
                assert np.abs(np.array(g[key]) - np.array(f[key])).max() < 1e-6
        if f["kind"] == "lane":
            assert (g["left"], g["right"], g["is_intersection"]) == (f["left"], f["right"], f["is_intersection"])


def test_a_scene_without_map_or_world_exports_an_empty_map_and_says_so(tmp_path, metadrive_format_check):
    scene = tmp_path / "scene.json"
    scene.write_text(json.dumps({"frame_id": "log/7", "entities": [
        {"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0, "speed": 3.0},
        {"id": "walker1", "type": "Pedestrian", "x": 2.5, "y": 6.0, "heading": 90}]}))
    res = _export(scene, None, tmp_path / "db")
    assert "the scene has no road: the scenarios have an empty map" in res.stdout
    assert "the scene has no world pose" in res.stdout
    [sd] = _database(tmp_path / "db")
    metadrive_format_check(sd, check_self_type=True, valid_check=True)
    assert sd["map_features"] == {} and sd["id"] == "log_7"
    # no world: the ego frame is the world (ego at the origin facing +y)
    walker = sd["tracks"]["walker1"]["state"]
    assert walker["position"][0, :2] == pytest.approx([2.5, 6.0], abs=1e-12)
    assert walker["heading"][0] == pytest.approx(math.pi)  # 90 deg CCW from +y = facing -x
    ego = sd["tracks"]["ego"]["state"]
    assert ego["velocity"][0] == pytest.approx([0.0, 3.0], abs=1e-12)  # speed along the heading


def test_steps_move_every_entity_on_along_its_heading(recorded, tmp_path):
    scene_file, _ = recorded["scene-0103/0"]
    _export(scene_file, None, tmp_path / "db", "--steps", "4")
    [sd] = _database(tmp_path / "db")
    assert sd["length"] == 4 and sd["metadata"]["ts"].tolist() == pytest.approx([0, 0.1, 0.2, 0.3])
    scene = scene_from_json(scene_file.read_text())
    for e in scene.entities:
        s = sd["tracks"][e.id]["state"]
        speed = e.speed or 0.0
        yaw = s["heading"][0]
        for k in range(4):
            assert s["position"][k, :2] == pytest.approx(
                s["position"][0, :2] + speed * 0.1 * k * np.array([math.cos(yaw), math.sin(yaw)]), abs=1e-9)


def test_the_database_is_replaced_whole_and_names_are_metadrive_s(recorded, tmp_path):
    scene_file, variants = recorded["scene-0061/0"]
    db = tmp_path / "db"
    _export(scene_file, variants, db)
    _export(scene_file, None, db)  # fewer scenarios: the old ones are gone
    assert len(_database(db)) == 1
    assert file_name("scene-0061_0").startswith("sd_")  # metadrive's is_scenario_file


@pytest.mark.parametrize("make, says", [
    (lambda d: [str(d / "missing.json")], "does not exist"),
    (lambda d: [str(_write(d / "bad.json", "{"))], "not valid json"),
    (lambda d: [str(_write(d / "nan.json", '{"entities": [{"id": "ego", "type": "Car", "x": NaN, "y": 0, '
                                             '"heading": 0}]}'))], "nan"),
])
def test_bad_variants_are_one_line_and_nothing_is_written(make, says, recorded, tmp_path):
    scene_file, _ = recorded["scene-0061/0"]
    out = tmp_path / "db"
    res = run_r2s("export", str(scene_file), *make(tmp_path), "--to", "scenarionet", "--out", str(out))
    assert_one_line_error(res, contains=says)
    assert not out.exists() and not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_out_may_not_be_an_input(recorded, tmp_path):
    scene_file, variants = recorded["scene-0061/0"]
    assert_one_line_error(run_r2s("export", str(scene_file), str(variants), "--to", "scenarionet",
                                  "--out", str(variants)), contains="--out")


def _write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


_types = sorted(ENTITY_TYPES)


@st.composite
def _scenes(draw):
    n = draw(st.integers(0, 8))
    coord = st.floats(-200, 200, allow_nan=False, allow_subnormal=False)
    entities = [{"id": "ego", "type": "Car", "x": 0.0, "y": 0.0, "heading": 0.0,
                 "speed": draw(st.floats(0, 40))}]
    for k in range(n):
        e = {"id": f"thing{k + 1}", "type": draw(st.sampled_from(_types)), "x": draw(coord), "y": draw(coord),
             "heading": draw(st.floats(0, 360, exclude_max=True)),
             "length": draw(st.floats(0.3, 20)), "width": draw(st.floats(0.3, 5))}
        if draw(st.booleans()):
            e["speed"] = draw(st.floats(0, 40))
        entities.append(e)
    world = {"x": draw(st.floats(-1e6, 1e6)), "y": draw(st.floats(-1e6, 1e6)),
             "heading": draw(st.floats(0, 360, exclude_max=True))}
    return scene_from_dict({"frame_id": "f/0", "entities": entities, "world": world})


@settings(max_examples=60, deadline=None)
@given(_scenes())
def test_random_scenes_come_back_through_the_extractor(tmp_path_factory, scene):
    """Random scenes, world poses and types: the scenario the export builds, read by the ScenarioNet extractor
    itself (scenario_frames), gives back every entity within 1e-6 m / 1e-6 deg, its type, box and speed."""
    from extractors.base import ExtractOptions
    from extractors.categories import ALL
    from extractors.scenarionet import scenario_frames
    from pipeline.export.scenarionet import Provenance, scenario

    sd = scenario(scene, "f_0", scene.world, None, Provenance("f/0"))
    path = tmp_path_factory.mktemp("sd") / "sd_r2sgen_f_0.pkl"
    path.write_bytes(pickle.dumps(sd, protocol=4))
    [rows] = list(scenario_frames(path, load_pickle(path), ExtractOptions(radius=1e6, categories=ALL)))
    back = {r["track_id"]: r for r in rows}
    assert set(back) == {e.id for e in scene.entities}
    for e in scene.entities:
        r = back[e.id]
        assert math.hypot(r["x"] - e.x, r["y"] - e.y) < 1e-6
        assert _gap(r["heading"], e.heading) < 1e-6 and r["type"] == e.type
        assert r["speed"] == pytest.approx(e.speed or 0.0, abs=1e-9)
        if not e.is_ego:
            assert (r["length"], r["width"]) == pytest.approx(e.dimensions())


def test_metadrive_s_check_is_not_blind(recorded, metadrive_format_check, tmp_path):
    """The format check the tests rely on refuses what breaks the format: a state array of the wrong length, a
    track type MetaDrive does not have, metadata without its time steps."""
    scene_file, _ = recorded["scene-0061/0"]
    _export(scene_file, None, tmp_path / "db")
    breaks = [lambda sd: sd["tracks"]["ego"]["state"].update(heading=np.zeros(2)),
              lambda sd: sd["tracks"]["ego"].update(type="CAR"),
              lambda sd: sd["metadata"].pop("ts")]
    for spoil in breaks:
        [sd] = _database(tmp_path / "db")
        metadrive_format_check(sd, check_self_type=True, valid_check=True)
        spoil(sd)
        with pytest.raises((AssertionError, KeyError)):
            metadrive_format_check(sd, check_self_type=True, valid_check=True)


def test_the_map_keeps_the_source_s_own_types(recorded, tmp_path):
    """Every exported road line and lane outside intersections carries the type the source (ScenarioNet's nuScenes
    converter) wrote for it, which scene JSON now keeps (`source_type`): road lines were all written as one type."""
    source = {}
    for pkl in sorted((EXCERPT / "scenarionet").glob("sd_*.pkl")):
        source.update({fid: f["type"] for fid, f in load_pickle(pkl)["map_features"].items()})
    scene_file, _ = recorded[FRAMES[1]]
    road = json.loads(scene_file.read_text())["road"]["features"]
    assert all(f["source_type"] == source[f["id"]] for f in road if f["kind"] in ("lane", "road_line"))
    _export(scene_file, None, tmp_path / "db")
    (sd,) = _database(tmp_path / "db")
    lines = {fid: f["type"] for fid, f in sd["map_features"].items() if f["type"].startswith(("ROAD_LINE", "ROAD_EDGE"))
             and fid in source}
    lanes = {fid: f["type"] for fid, f in sd["map_features"].items() if f["type"].startswith("LANE_") and fid in source}
    assert len({*lines.values()}) >= 2, "the excerpt's road lines are of several types"
    assert all(source[fid] == t for fid, t in lines.items())
    assert all(source[fid] == t for fid, t in lanes.items() if t != "LANE_SURFACE_UNSTRUCTURE")
