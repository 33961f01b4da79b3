"""`r2s export SCENE --steps T --program P.json`: entities move by their clip program's behaviours. A car recorded
following a lane round a bend (a quarter circle of radius 30 m, then straight on) keeps to its lane at every
step of the export, by the lane fact of each exported pose and by its distance from the bend's centre worked out
here; without the program it goes straight on and leaves the lane (today's behaviour, kept)."""

from __future__ import annotations

import json
import math
import pickle
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from synth.road.lane_facts import RoadIndex
from synth.road.roadmap import LANE, MapFeature, RoadMap
from tests.support import run_r2s

from .test_export_openscenario import asam_issues, road_offset

RADIUS, HALF = 30.0, 1.75  # the bend's centre-line radius, half the lane's width
CENTRE = (5.0 - RADIUS, 0.0)  # the bend turns left from (5, 0), heading +y, round this point
SPEED = 8.0


def _line(offset: float) -> list[list[float]]:
    """The lane's centre line moved `offset` metres to its left: 10 m straight up x = 5, the quarter circle, then
    40 m straight on along -x."""
    r = RADIUS - offset
    pts = [[CENTRE[0] + r, -10.0 + k] for k in range(0, 10, 2)]
    pts += [[CENTRE[0] + r * math.cos(a), CENTRE[1] + r * math.sin(a)] for a in np.linspace(0, math.pi / 2, 31)]
    pts += [[CENTRE[0] - 5.0 * k, CENTRE[1] + r] for k in range(1, 9)]
    return pts


def _place(s: float) -> tuple[float, float, float]:
    """(x, y, heading in degrees CCW from +y) s metres along the centre line from its start."""
    if s <= 10.0:
        return CENTRE[0] + RADIUS, -10.0 + s, 0.0
    a = (s - 10.0) / RADIUS
    return CENTRE[0] + RADIUS * math.cos(a), CENTRE[1] + RADIUS * math.sin(a), math.degrees(a)


def _frame(k: int, s: float) -> dict:
    x, y, h = _place(s)
    road = {"map_id": "bend", "features": [{
        "id": "bend", "kind": "lane", "line": _line(0.0), "polygon": _line(HALF) + _line(-HALF)[::-1],
        "left": None, "right": None, "successors": [], "predecessors": [], "is_intersection": False}]}
    car = {"id": "car1", "type": "Car", "x": x, "y": y, "heading": h, "length": 4.5, "width": 1.9, "speed": SPEED,
           "lanes": ["bend"], "lane": "bend", "in_intersection": False, "on_crosswalk": False, "off_road": False}
    ego = {"id": "ego", "type": "Car", "x": 0.0, "y": 0.0, "heading": 0.0, "speed": 0.0, "lanes": [], "lane": None,
           "in_intersection": False, "on_crosswalk": False, "off_road": True}
    world = {"source": "test", "scene": "bend", "frame_index": k, "timestamp_us": 500_000 * k, "map_id": "bend",
             "x": 0.0, "y": 0.0, "heading": 90.0}  # ego at the world's origin facing +y: the ego frame is the world
    return {"frame_id": f"bend/{k}", "entities": [ego, car], "world": world, "road": road}


@pytest.fixture(scope="module")
def bend(tmp_path_factory) -> tuple[Path, Path]:
    """The bend's first frame and the clip program r2s synth --behaviours writes for 3 frames of it."""
    root = tmp_path_factory.mktemp("bend")
    files = []
    for k in range(3):
        files.append(root / f"f{k}.json")
        files[-1].write_text(json.dumps(_frame(k, 2.0 + SPEED * 0.5 * k)))
    res = run_r2s("synth", *map(str, files), "--behaviours", "--motion", "--lanes", "--format", "json",
                  "--out", str(root / "clip.json"))
    assert res.returncode == 0, res.stderr
    assert "behaviour car1 following lane" in json.loads((root / "clip.json").read_text())["program"]
    return files[0], root / "clip.json"


def _poses(db: Path) -> np.ndarray:
    (f,) = db.glob("sd_*.pkl")
    state = pickle.loads(f.read_bytes())["tracks"]["car1"]["state"]
    return np.column_stack([state["position"][:, :2], np.degrees(state["heading"])])


def _in_lane(poses: np.ndarray) -> list[bool]:
    road = RoadMap.of("bend", [MapFeature("bend", "bend", LANE, tuple(map(tuple, _line(HALF) + _line(-HALF)[::-1])),
                                          tuple(map(tuple, _line(0.0))))])
    facts = RoadIndex(road).facts(poses[:, 0], poses[:, 1], poses[:, 2])
    return [f.lane == "bend" for f in facts]


def _on_the_bend(poses: np.ndarray) -> list[bool]:
    """Within the lane by geometry alone, for the poses on the quarter circle (y >= 0, x >= the circle's centre)."""
    r = np.hypot(poses[:, 0] - CENTRE[0], poses[:, 1] - CENTRE[1])
    return [abs(d - RADIUS) < HALF for d, x, y in zip(r, poses[:, 0], poses[:, 1]) if y >= 0 and x >= CENTRE[0]]


def test_a_car_following_its_lane_round_a_bend_stays_in_it(bend, tmp_path):
    scene, program = bend
    steps = 80  # 8 s at 8 m/s: 64 m, round the whole bend (47 m) and on
    res = run_r2s("export", str(scene), "--to", "scenarionet", "--steps", str(steps), "--program", str(program),
                  "--out", str(tmp_path / "moved"))
    assert res.returncode == 0, res.stderr
    poses = _poses(tmp_path / "moved")
    assert len(poses) == steps and all(_in_lane(poses))
    on_bend = _on_the_bend(poses)
    assert len(on_bend) > 30 and all(on_bend)
    assert poses[-1, 2] % 360 == pytest.approx(180.0, abs=3.0)  # out of the bend heading -x (90 deg left of +y)
    step = np.hypot(*np.diff(poses[:, :2], axis=0).T)
    assert step == pytest.approx(SPEED * 0.1, rel=0.02)  # cruising at its recorded speed

    res = run_r2s("export", str(scene), "--to", "scenarionet", "--steps", str(steps), "--out", str(tmp_path / "straight"))
    assert res.returncode == 0, res.stderr
    assert not all(_in_lane(_poses(tmp_path / "straight")))  # without the program: straight on, off the bend


def test_the_moved_frame_to_openscenario_passes_asam_and_follows_the_bend(bend, tmp_path):
    scene, program = bend
    res = run_r2s("export", str(scene), "--to", "openscenario", "--steps", "80", "--program", str(program),
                  "--out", str(tmp_path / "osc"))
    assert res.returncode == 0, res.stderr
    for f in (tmp_path / "osc").iterdir():
        assert asam_issues(f) == [], f.name
    (xosc,) = (tmp_path / "osc").glob("*.xosc")
    ox, oy = road_offset(next((tmp_path / "osc").glob("*.xodr")))
    root = ET.parse(xosc).getroot()
    (poly,) = root.iter("Polyline")  # car1's path (ego is parked: it has none)
    pts = np.array([[float(v.find("Position/WorldPosition").get(a)) for a in "xy"] for v in poly.findall("Vertex")])
    pts += [ox, oy]
    assert len(pts) == 80 and all(_in_lane(np.column_stack([pts, np.zeros(len(pts))])))
