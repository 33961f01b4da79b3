"""`r2s export F.maps --to opendrive`: road marks from the recorded road lines and crosswalks as objects, read back
from the written file by hand (its planView, lane marks and header offset) and held against the recorded map:
the shipped Argoverse 2 map's crosswalks, the shipped nuScenes maps' road lines (ScenarioNet's types). ASAM's
checker reports no issue on either."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import shapely

from frames.maps import read_maps
from tests.support import run_r2s
from tests.support.extract import EXCERPT
from tests.support.opendrive import reference_pose

from .test_export_openscenario import asam_issues

AV2_MAPS = Path(__file__).resolve().parents[3] / "data" / "argoverse2-log-excerpt" / "frames.maps"
NUSCENES_MAP = "scene-0796"  # 15 broken white, 6 solid white, 2 solid yellow road lines
# what each recorded type must read as in the file: (type, colour, laneChange), written out here by hand
EXPECTED = {"ROAD_LINE_BROKEN_SINGLE_WHITE": ("broken", "white", "both"),
            "ROAD_LINE_SOLID_SINGLE_WHITE": ("solid", "white", "none"),
            "ROAD_LINE_SOLID_SINGLE_YELLOW": ("solid", "yellow", "none")}


def _export(maps: Path, out: Path, *more: str) -> ET.Element:
    res = run_r2s("export", str(maps), *more, "--to", "opendrive", "--out", str(out))
    assert res.returncode == 0, res.stderr
    assert asam_issues(out) == []
    return ET.parse(out).getroot()


@pytest.fixture(scope="module")
def av2(tmp_path_factory) -> ET.Element:
    return _export(AV2_MAPS, tmp_path_factory.mktemp("marks-av2") / "map.xodr")


@pytest.fixture(scope="module")
def nuscenes(tmp_path_factory) -> tuple[ET.Element, object]:
    root = tmp_path_factory.mktemp("marks-nu")
    assert run_r2s("extract", "scenarionet", str(EXCERPT / "scenarionet"), "--out", str(root / "f.parquet")).returncode == 0
    road = next(m for m in read_maps(root / "f.maps") if m.map_id == NUSCENES_MAP)
    return _export(root / "f.maps", root / "map.xodr", "--map", NUSCENES_MAP), road


def test_every_recorded_crosswalk_is_an_object_with_its_outline_where_it_was_recorded(av2):
    road = next(iter(read_maps(AV2_MAPS)))
    recorded = {f.feature_id: f.polygon for f in road.features if f.kind == "crosswalk"}
    o = av2.find("header/offset")
    shift, hdg = np.array([float(o.get("x")), float(o.get("y"))]), float(o.get("hdg"))
    assert hdg == 0.0
    found = {}
    for r in av2.findall("road"):
        for obj in r.findall("objects/object"):
            assert obj.get("type") == "crosswalk"
            base, d = reference_pose(r, float(obj.get("s")))
            n = np.array([-d[1], d[0]])
            origin = base + float(obj.get("t")) * n
            corners = [origin + float(c.get("u")) * d + float(c.get("v")) * n + shift
                       for c in obj.findall("outlines/outline/cornerLocal")]
            found[obj.get("name")] = corners
    assert set(found) == set(recorded) and len(found) == 11
    ids = [obj.get("id") for obj in av2.iter("object")]
    assert len(set(ids)) == len(ids)
    for k, corners in found.items():
        assert np.abs(np.asarray(corners) - np.asarray(recorded[k])).max() < 1e-6, k


def test_road_marks_are_the_recorded_road_lines_along_each_lane_edge(nuscenes):
    root, road = nuscenes
    o = root.find("header/offset")
    shift = np.array([float(o.get("x")), float(o.get("y"))])
    lines = [f for f in road.features if f.kind == "road_line"]
    lanes = {f.feature_id: f for f in road.lanes}
    seen = set()
    for r in root.findall("road"):
        if r.get("junction") != "-1" or " | " in r.get("name"):
            # roads of one lane: a road of several recorded lanes side by side (docs/formats.md "Lanes side by
            # side") takes its marks from its reference lane's edges, which this brute force does not rebuild
            continue
        left = r.find("lanes/laneSection/center/lane/roadMark")
        right = r.find("lanes/laneSection/right/lane/roadMark")
        assert r.get("name") in lanes
        # the lane's centre as the file has it (its reference line, in the world): a recorded lane may be cut
        # into roads where a same-direction neighbour starts or ends beside it
        length = float(r.get("length"))
        centre = shapely.LineString([reference_pose(r, s)[0] + shift for s in np.linspace(0.0, length, 40)])
        half = np.mean([float(w.get("a")) for w in r.findall("lanes/laneSection/right/lane/width")]) / 2
        for side, mark in ((1, left), (-1, right)):
            written = (mark.get("type"), mark.get("color"), mark.get("laneChange"))
            if written[0] == "none":
                continue
            seen.add(written)
            # brute force: a recorded line of a type written so runs along that side of the recorded lane (its
            # centre line moved by half the lane's written width)
            edge = centre.offset_curve(side * half)
            samples = shapely.line_interpolate_point(edge, np.linspace(0, edge.length, 12)[1:-1])
            assert any(EXPECTED.get(f.source_type, (None,))[:2] == written[:2]
                       and EXPECTED[f.source_type] == written
                       and np.mean(shapely.distance(samples, shapely.LineString(f.line)) < 0.8) >= 0.5
                       for f in lines), (r.get("name"), side, written)
    assert {("broken", "white", "both"), ("solid", "white", "none")} <= seen


def test_a_long_lane_takes_the_marks_along_its_edges_and_the_bound_is_checked_before_them():
    """A lane of 20,000 vertices (a 0.01 m zigzag) between a solid line 1.5 m to its left and a broken one 1.5 m
    to its right: its road's marks are those lines (sampled by one pass along each edge); a bound below the line
    geometries it surely writes refuses it with that count (TooManyGeometries, before the marks are sought)."""
    from synth.road.opendrive import END_RUNS, TooManyGeometries, network, straight_runs
    from synth.road.roadmap import MapFeature, RoadMap

    n = 20_000
    length = 0.01 * (n - 1)
    lane = MapFeature("m", "L", "lane", line=tuple((0.01 * i, 0.01 * (i % 2)) for i in range(n)),
                      polygon=((0, -1.5), (length, -1.5), (length, 1.5), (0, 1.5)))
    left = MapFeature("m", "A", "road_line", line=((0, 1.5), (length, 1.5)),
                      source_type="ROAD_LINE_SOLID_SINGLE_WHITE")
    right = MapFeature("m", "B", "road_line", line=((0, -1.5), (length, -1.5)),
                       source_type="ROAD_LINE_BROKEN_SINGLE_WHITE")
    road = RoadMap.of("m", [lane, left, right])
    (r,) = network(road).roads
    assert r.marks == (EXPECTED["ROAD_LINE_SOLID_SINGLE_WHITE"], EXPECTED["ROAD_LINE_BROKEN_SINGLE_WHITE"])
    # the lane has no neighbour: its road is written whatever is grouped, its ends at most END_RUNS runs fewer
    sure = len(straight_runs(r.points)) - END_RUNS
    assert sure > n / 2
    with pytest.raises(TooManyGeometries) as refused:
        network(road, max_geometries=sure - 1)
    assert refused.value.count == sure and not refused.value.exact
    assert network(road, max_geometries=sure).roads == (r,)
