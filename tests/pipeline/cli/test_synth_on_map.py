"""`r2s synth SCENE --format scenic --road F.xodr`: a program's Scenic text that names the scene's road as
OpenDRIVE (`r2s export SCENE --to opendrive --frame ego`), run as a user runs it on a shipped nuScenes frame:
Scenic's driving domain loads the map and samples a scene (`r2s sample --sampler scenic`, a real process), the
recorded ego stands in the Scenic lane of its recorded lane, and a road in another frame, a file that is not
OpenDRIVE or a record naming another kind of map is one line, exit 2."""

from __future__ import annotations

import json
import math
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from synth.road.lane_facts import RoadIndex
from synth.scene import scene_from_dict
from tests.support import assert_one_line_error, run_r2s
from tests.support.extract import EXCERPT

FRAME = "scene-0103/0"  # a shipped nuScenes frame with a road: 9 lanes within r2s scene's radius


@pytest.fixture(scope="module")
def made(tmp_path_factory) -> dict[str, Path]:
    """The frame's scene JSON, its road in its ego frame and in the world, and its program's Scenic text on
    the first, written beside it."""
    root = tmp_path_factory.mktemp("synth-on-map")
    out = {"scene": root / "scene.json", "road": root / "road.xodr", "world": root / "world.xodr",
           "program": root / "p.scenic"}
    assert run_r2s("extract", "scenarionet", str(EXCERPT / "scenarionet"), "--out", str(root / "f.parquet")).returncode == 0
    res = run_r2s("scene", str(root / "f.parquet"), FRAME, "--out", str(out["scene"]))
    assert res.returncode == 0, res.stderr
    for key, frame in (("road", "ego"), ("world", "world")):
        res = run_r2s("export", str(out["scene"]), "--to", "opendrive", "--frame", frame, "--out", str(out[key]))
        assert res.returncode == 0, res.stderr
    res = run_r2s("synth", str(out["scene"]), "--format", "scenic", "--road", str(out["road"]), "--out",
                  str(out["program"]))
    assert res.returncode == 0, res.stderr
    return out


def test_the_text_names_the_map_beside_it_and_the_driving_domain(made):
    text = made["program"].read_text()
    assert "param map = localPath('road.xodr')" in text  # relative to the text: the two move together
    assert "\nmodel scenic.domains.driving.model\n" in text
    assert "class Car(Car):" in text and json.loads(text.splitlines()[-1].split(": ", 1)[1])["map"] == "road.xodr"


def test_the_ego_frame_road_says_where_it_is_in_the_world(made):
    world = json.loads(made["scene"].read_text())["world"]
    offset = ET.parse(made["road"]).getroot().find("header/offset")
    assert float(offset.get("x")) == world["x"] and float(offset.get("y")) == world["y"]
    assert float(offset.get("hdg")) == pytest.approx(math.radians(world["heading"] - 90.0), abs=1e-12)


def test_scenic_samples_the_program_on_the_map(made, tmp_path):
    res = run_r2s("sample", str(made["program"]), "--sampler", "scenic", "--n", "1", "--max-iterations", "2000",
                  "--out", str(tmp_path / "v"), cwd=tmp_path)  # localPath: found from any working directory
    assert res.returncode == 0, res.stderr
    sampled = json.loads((tmp_path / "v" / "sample_000.json").read_text())
    recorded = json.loads(made["scene"].read_text())
    assert {e["id"] for e in sampled["entities"]} <= {e["id"] for e in recorded["entities"]} | {"ego"}
    assert not list(made["road"].parent.glob("*.snet"))  # r2s sample parses the map afresh and caches nothing


def test_the_recorded_ego_is_in_the_scenic_lane_of_its_recorded_lane(made):
    scenic = pytest.importorskip("scenic")
    scene = scene_from_dict(json.loads(made["scene"].read_text()))
    recorded = RoadIndex(scene.road).facts([scene.ego.x], [scene.ego.y], [scene.ego.heading + 90.0])[0].lanes
    assert recorded  # the frame's ego drives in a lane
    scenario = scenic.scenarioFromFile(str(made["program"]), mode2D=True,
                                       params={"map_options": {"useCache": False, "writeCache": False}})
    sampled, _ = scenario.generate(maxIterations=2000)
    network = sampled.workspace.network
    ego = sampled.egoObject
    assert type(ego).__mro__[1].__module__ == "scenic.domains.driving.model"  # the domain's Car
    here = {lane.road.name for lane in network.lanes if lane.containsPoint(ego.position)}
    assert here & set(recorded), (here, recorded)
    assert ego.heading == pytest.approx(math.radians(scene.ego.heading), abs=1e-12)


def test_a_road_in_another_frame_is_refused(made):
    res = run_r2s("synth", str(made["scene"]), "--format", "scenic", "--road", str(made["world"]))
    assert_one_line_error(res, 2, "--frame ego")


@pytest.mark.parametrize("name, body", [("road.txt", "<OpenDRIVE/>"), ("road.xodr", "<html></html>"),
                                        ("road.xodr", "not xml at all")])
def test_a_road_that_is_not_opendrive_is_refused(made, tmp_path, name, body):
    (tmp_path / name).write_text(body)
    res = run_r2s("synth", str(made["scene"]), "--format", "scenic", "--road", str(tmp_path / name))
    assert_one_line_error(res, 2, "OpenDRIVE")


def test_the_road_needs_scenic_text_and_the_ego_frame_needs_a_scene(made, tmp_path):
    res = run_r2s("synth", str(made["scene"]), "--road", str(made["road"]))
    assert_one_line_error(res, 2, "--format scenic")
    maps = Path(__file__).resolve().parents[3] / "data" / "argoverse2-log-excerpt" / "frames.maps"
    res = run_r2s("export", str(maps), "--to", "opendrive", "--frame", "ego", "--out", str(tmp_path / "m.xodr"))
    assert_one_line_error(res, 2, "--frame ego")
    assert not (tmp_path / "m.xodr").exists()


def test_a_record_that_names_another_kind_of_map_is_refused(made, tmp_path):
    # Scenic unpickles a .snet map: a record naming one would run its code, so no text may name one
    text = made["program"].read_text().replace("road.xodr", "road.snet")
    (tmp_path / "p.scenic").write_text(text)
    res = run_r2s("sample", str(tmp_path / "p.scenic"), "--sampler", "scenic", "--out", str(tmp_path / "v"))
    assert_one_line_error(res, 2, "not Scenic text written by r2sgen")
