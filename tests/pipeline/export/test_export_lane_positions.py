"""`r2s export SCENE --to openscenario`: an entity in a lane is placed by a LanePosition on the road of its
recorded lane (its `lane` fact), read back from the .xosc and the .xodr by hand on shipped nuScenes frames: the
road's name is the lane fact, and (s, offset) on that road's reference line is the entity's recorded world
position."""

from __future__ import annotations

import json
import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from synth.road.lane_facts import RoadIndex
from synth.scene import scene_from_dict
from synth.world import in_world
from tests.support import run_r2s
from tests.support.extract import EXCERPT
from tests.support.opendrive import LANE_SEP, SEP, reference_pose

FRAMES = ("scene-0103/0", "scene-0796/1")


@pytest.fixture(scope="module")
def frames(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("lane-positions")
    assert run_r2s("extract", "scenarionet", str(EXCERPT / "scenarionet"), "--out", str(root / "f.parquet")).returncode == 0
    return root


@pytest.mark.parametrize("fid", FRAMES)
def test_an_entity_in_a_lane_is_at_a_lane_position_of_its_recorded_lane(frames, fid, tmp_path):
    scene_file = tmp_path / "s.json"
    assert run_r2s("scene", str(frames / "f.parquet"), fid, "--out", str(scene_file)).returncode == 0
    res = run_r2s("export", str(scene_file), "--to", "openscenario", "--out", str(tmp_path / "x"))
    assert res.returncode == 0, res.stderr
    scene = scene_from_dict(json.loads(scene_file.read_text()))
    xodr = ET.parse(next((tmp_path / "x").glob("*.xodr"))).getroot()
    xosc = ET.parse(next((tmp_path / "x").glob("*.xosc"))).getroot()
    roads = {r.get("id"): r for r in xodr.findall("road")}
    o = xodr.find("header/offset")
    shift = np.array([float(o.get("x")), float(o.get("y"))])
    placed = {a.get("entityRef"): a.find(".//Position")[0] for a in xosc.iter("Private")}
    es = scene.entities
    facts = RoadIndex(scene.road).facts([e.x for e in es], [e.y for e in es], [e.heading + 90.0 for e in es])
    in_lane = 0
    for e, fact in zip(es, facts):
        where = placed[e.id]
        if fact.lane is None or where.tag == "WorldPosition":  # the latter: beyond a bend's outer corner
            assert fact.lane is not None or where.tag == "WorldPosition", e.id
            continue
        in_lane += 1
        assert where.tag == "LanePosition" and where.get("laneId") == "-1", e.id
        road = roads[where.get("roadId")]
        # lane -1's recorded lanes: a road's name joins its lanes' left to right (lanes side by side)
        assert fact.lane in road.get("name").split(LANE_SEP)[0].split(SEP), (e.id, fact.lane, road.get("name"))
        base, d = reference_pose(road, float(where.get("s")))
        at = base + float(where.get("offset")) * np.array([-d[1], d[0]]) + shift
        w = in_world(scene.world, e)
        assert np.hypot(*(at - (w.x, w.y))) < 1e-6, (e.id, at, (w.x, w.y))
        assert math.isclose(float(where.find("Orientation").get("h")), w.yaw, abs_tol=1e-9)
    assert in_lane >= 3
