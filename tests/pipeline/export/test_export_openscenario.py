"""`r2s export --to openscenario`: OpenSCENARIO 1.2 files on an OpenDRIVE road built from the recorded lanes.
ASAM's own checkers (asam-qc-openscenarioxml, asam-qc-opendrive) report no issue on any file written for the
shipped scenes; positions, headings, speeds, categories and boxes read back from the .xosc (plain XML parsing)
and brought into the ego frame by the extractors' own transform give back each scene within 1e-6; the road's
reference lines run through the recorded centre lines."""

from __future__ import annotations

import json
import math
import os
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from extractors.base import global_to_ego
from pipeline.export.opendrive import linked, straight_runs
from synth.scene import scene_from_json
from synth.world import road_in_world
from tests.support import assert_one_line_error, run_r2s
from tests.support.opendrive import asam_issues, reference_pose

from .conftest import FRAMES

CATEGORY = {"Car": "car", "Truck": "truck", "Bus": "bus", "Pedestrian": "pedestrian", "Bicycle": "bicycle",
            "Motorcycle": "motorbike", "Barrier": "barrier", "TrafficCone": "obstacle", "Trailer": "trailer",
            "ConstructionVehicle": "truck", "EmergencyVehicle": "van", "Animal": "animal",
            "PushableObject": "obstacle", "Debris": "obstacle", "BicycleRack": "obstacle", "Object": "obstacle"}


def _gap(a: float, b: float) -> float:
    return abs((a - b + 180.0) % 360.0 - 180.0)


def _export(scene: Path, variants: Path | None, out: Path):
    res = run_r2s("export", str(scene), *([str(variants)] if variants else []), "--to", "openscenario",
                  "--out", str(out), "--program", str(scene.with_name("scene.scenic")))
    assert res.returncode == 0, res.stderr
    return res


@pytest.mark.parametrize("fid", FRAMES)
def test_asam_checkers_report_no_issue_on_any_file(fid, recorded, tmp_path):
    scene, variants = recorded[fid]
    _export(scene, variants, tmp_path / "osc")
    files = sorted((tmp_path / "osc").iterdir())
    assert [f.suffix for f in files].count(".xosc") == 6 and [f.suffix for f in files].count(".xodr") == 1
    for f in files:
        assert asam_issues(f) == [], f.name


def road_offset(xodr: Path) -> tuple[float, float]:
    """The recentring offset in an .xodr's header: its coordinates plus this are the world's."""
    o = ET.parse(xodr).getroot().find("header/offset")
    return float(o.get("x")), float(o.get("y"))


def _read_back(xosc: Path) -> dict[str, dict]:
    """Each entity's category, box, speed and place (x, y in the road's frame, yaw), a LanePosition's through
    the road's reference line in the .xodr beside it."""
    root = ET.parse(xosc).getroot()
    roads = {r.get("id"): r for r in ET.parse(next(xosc.parent.glob("*.xodr"))).getroot().findall("road")}
    out: dict[str, dict] = {}
    for obj in root.iter("ScenarioObject"):
        kind = obj[0]
        dims = kind.find("BoundingBox/Dimensions").attrib
        category = kind.get("vehicleCategory") or kind.get("pedestrianCategory") or kind.get("miscObjectCategory")
        out[obj.get("name")] = {"category": category, "length": float(dims["length"]),
                                "width": float(dims["width"])}
    for private in root.iter("Private"):
        e = out[private.get("entityRef")]
        pos = private.find(".//TeleportAction/Position/WorldPosition")
        if pos is not None:
            e.update(x=float(pos.get("x")), y=float(pos.get("y")), h=float(pos.get("h")))
        else:
            pos = private.find(".//TeleportAction/Position/LanePosition")
            base, d = reference_pose(roads[pos.get("roadId")], float(pos.get("s")))
            x, y = base + float(pos.get("offset")) * np.array([-d[1], d[0]])
            e.update(x=x, y=y, h=float(pos.find("Orientation").get("h")), lane=True)
        speed = private.find(".//AbsoluteTargetSpeed")
        e["speed"] = float(speed.get("value")) if speed is not None else None
    return out


@pytest.mark.parametrize("fid", FRAMES)
def test_positions_read_back_from_the_xosc_give_back_every_scene(fid, recorded, tmp_path):
    scene_file, variants = recorded[fid]
    _export(scene_file, variants, tmp_path / "osc")
    world = json.loads(scene_file.read_text())["world"]
    base = fid.replace("/", "_")
    for f, name in [(scene_file, base)] + [(v, f"{base}-{v.stem}") for v in sorted(variants.glob("*.json"))]:
        scene = scene_from_json(f.read_text())
        back = _read_back(tmp_path / "osc" / f"{name}.xosc")
        assert set(back) == {e.id for e in scene.entities}
        ox, oy = road_offset(tmp_path / "osc" / f"{base}.xodr")  # the road's recentring
        for e in scene.entities:
            b = back[e.id]
            x, y, h = global_to_ego(world["x"], world["y"], math.radians(world["heading"]), [b["x"] + ox],
                                    [b["y"] + oy], [b["h"]])
            assert math.hypot(x[0] - e.x, y[0] - e.y) < 1e-6 and _gap(h[0], e.heading) < 1e-6
            assert b["category"] == CATEGORY[e.type]
            assert (b["length"], b["width"]) == pytest.approx(e.dimensions(), rel=1e-12)
            if b["category"] not in ("barrier", "obstacle"):
                assert b["speed"] == pytest.approx(e.speed or 0.0, abs=1e-12)
        assert any(b.get("lane") for b in back.values())  # some at a LanePosition, read back as exactly


def test_the_road_runs_through_the_recorded_centre_lines(recorded, tmp_path):
    scene_file, _ = recorded["scene-0103/0"]
    _export(scene_file, None, tmp_path / "osc")
    doc = json.loads(scene_file.read_text())
    world = doc["world"]
    lanes = {f["id"]: f for f in doc["road"]["features"] if f["kind"] == "lane"}
    xodr = tmp_path / "osc" / "scene-0103_0.xodr"
    roads = ET.parse(xodr).getroot().findall("road")
    # the file's geometries are what the export's bound counts (test_a_road_of_more_line_geometries_than_the_bound)
    scene = scene_from_json(scene_file.read_text())
    net = linked(road_in_world(scene.world, scene.road), "the scene")
    assert sum(len(r.findall("planView/geometry")) for r in roads) == sum(len(straight_runs(r.points))
                                                                         for r in net.roads)
    ox, oy = road_offset(xodr)
    assert sorted(r.get("name") for r in roads) == sorted(lanes)  # nuScenes' excerpt records no lane links
    for road in roads:
        line = np.array(lanes[road.get("name")]["line"])
        geoms = road.findall("planView/geometry")
        starts = np.array([[float(g.get("x")) + ox, float(g.get("y")) + oy] for g in geoms])
        x, y, _ = global_to_ego(world["x"], world["y"], math.radians(world["heading"]), starts[:, 0], starts[:, 1],
                                np.zeros(len(starts)))
        # every geometry starts on a vertex of the recorded centre line (merged runs skip vertices), the first
        # on its first
        d = np.hypot(x[:, None] - line[None, :, 0], y[:, None] - line[None, :, 1]).min(axis=1)
        assert d.max() < 1e-6 and math.hypot(x[0] - line[0, 0], y[0] - line[0, 1]) < 1e-6
        total = sum(float(g.get("length")) for g in geoms)
        assert total == pytest.approx(np.hypot(*np.diff(line, axis=0).T).sum(), rel=1e-6)
        width = float(road.find("lanes/laneSection/right/lane/width").get("a"))  # the first piece's
        offset = float(road.find("lanes/laneOffset").get("a"))
        assert road.find("lanes/laneSection/right/lane").get("id") == "-1" and offset == pytest.approx(width / 2)


def test_the_same_inputs_give_the_same_bytes(recorded, tmp_path):
    scene_file, variants = recorded["scene-0061/0"]
    _export(scene_file, variants, tmp_path / "a")
    _export(scene_file, variants, tmp_path / "b")
    for f in sorted((tmp_path / "a").iterdir()):
        assert f.read_bytes() == (tmp_path / "b" / f.name).read_bytes(), f.name


def test_a_scene_without_road_is_one_line_and_nothing_is_written(tmp_path):
    scene = tmp_path / "scene.json"
    scene.write_text(json.dumps({"frame_id": "log/7", "entities": [
        {"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0}]}))
    res = run_r2s("export", str(scene), "--to", "openscenario", "--out", str(tmp_path / "osc"))
    assert_one_line_error(res, contains="needs a road")
    assert not (tmp_path / "osc").exists()


def test_the_checker_harness_sees_a_broken_file(recorded, tmp_path):
    """asam_issues is not blind: a road without its plan view breaks the OpenDRIVE schema."""
    scene_file, _ = recorded["scene-0103/0"]
    _export(scene_file, None, tmp_path / "osc")
    xodr = tmp_path / "osc" / "scene-0103_0.xodr"
    broken = tmp_path / "broken.xodr"
    tree = ET.parse(xodr)
    road = tree.getroot().find("road")
    road.remove(road.find("planView"))
    tree.write(broken)
    issues = asam_issues(broken)
    assert any(checker == "check_asam_xodr_xml_valid_schema" for checker, _, _ in issues), issues


def test_names_xml_cannot_hold_are_escaped_in_the_notes(recorded, tmp_path):
    """Variant file names and a --program path with a control character, U+FFFE or bytes that are not UTF-8 (a
    lone surrogate in Python) are written as escapes: every file parses as XML and passes ASAM's checkers."""
    scene_file, variants = recorded["scene-0061/0"]
    folder = os.fsencode(tmp_path / "variants")
    os.mkdir(folder)
    names = [b"ctl\x01.json", b"nc\xef\xbf\xbe.json", b"bytes\xff.json"]
    for name, sample in zip(names, sorted(variants.iterdir())):
        with open(os.path.join(folder, name), "wb") as f:
            f.write(sample.read_bytes())
    program = os.path.join(os.fsencode(tmp_path), b"p\x02\xfe.scenic")
    with open(program, "wb") as f:
        f.write(scene_file.with_name("scene.scenic").read_bytes())
    out = tmp_path / "osc"
    res = run_r2s("export", str(scene_file), os.fsdecode(folder), "--to", "openscenario", "--out", str(out),
                  "--program", os.fsdecode(program))
    assert res.returncode == 0, res.stderr
    authors = []
    for f in sorted(out.iterdir()):
        root = ET.parse(f).getroot()  # raises on a character XML 1.0 cannot hold
        if f.suffix == ".xosc":
            authors.append(root.find("FileHeader").get("author"))
        assert asam_issues(f) == [], f.name
    assert len(authors) == 4 and all("program p\\x02\\udcfe.scenic" in a for a in authors)
    assert {"variant ctl\\x01.json", "variant nc\\ufffe.json", "variant bytes\\udcff.json"} <= {
        a.split(" of ")[0].split(": ")[1] for a in authors}


def test_a_road_of_more_line_geometries_than_the_bound_is_one_line(recorded, tmp_path):
    """A lane whose centre line zigzags over MAX_GEOMETRIES + 1 segments (10^6 took 1.6 GB and 54 s for a 186 MB
    .xodr): one line naming the bound, exit 2, nothing written (a real process); one geometry fewer passes the
    bound (the export's own `linked`, in process: writing its 100,000 geometries took 14 s of the suite, and the
    count is the file's, test_the_road_runs_through_the_recorded_centre_lines)."""
    from pipeline.export.opendrive import MAX_GEOMETRIES
    from synth.road.opendrive import network

    scene_file, _ = recorded["scene-0061/0"]
    doc = json.loads(scene_file.read_text())
    lane = next(f for f in doc["road"]["features"] if f["kind"] == "lane" and len(f.get("line") or []) >= 2)
    scene = scene_from_json(scene_file.read_text())
    # the geometries of the other lanes' roads, as the export counts them (the excerpt's lanes are not linked, so
    # each lane is a road on its own)
    others = sum(len(straight_runs(r.points)) for r in network(road_in_world(scene.world, scene.road)).roads
                 if r.lanes != (lane["id"],))
    x0, y0 = lane["line"][0]
    for segments, ok in ((MAX_GEOMETRIES - others, True), (MAX_GEOMETRIES - others + 1, False)):
        lane["line"] = [[x0 + 0.01 * i, y0 + 0.01 * (i % 2)] for i in range(segments + 1)]
        big = tmp_path / "big.json"
        big.write_text(json.dumps(doc))
        if ok:
            big_scene = scene_from_json(big.read_text())
            net = linked(road_in_world(big_scene.world, big_scene.road), "the big scene")
            assert sum(len(straight_runs(r.points)) for r in net.roads) == MAX_GEOMETRIES
        else:
            out = tmp_path / f"osc-{segments}"
            res = run_r2s("export", str(big), "--to", "openscenario", "--out", str(out))
            assert_one_line_error(res, contains=f"{MAX_GEOMETRIES + 1:,} OpenDRIVE line geometries")
            assert not out.exists()
