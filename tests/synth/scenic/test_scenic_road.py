"""The recorded road in the emitted Scenic text (synth.scenic.road; docs/scenic.md, "The road"), under the official
compiler (scenic 3.1.1, 2D mode): the regions are the scene's features exactly, the text compiles and samples,
and a requirement over the regions samples only scenes whose lane facts, decided again by synth.road.lane_facts (the
exact test, independent of Scenic's shapely one and of the helpers' plain Python), say what it requires."""

from __future__ import annotations

import json
import random

import numpy as np
import pytest

from tests.support import ROOT, run_r2s

pytest.importorskip("scenic", reason="scenic (3.1.1) is not importable here: the Scenic tests need the compiler")

from pipeline.variants.sample import SampleOptions, ScenicProgramError, ensure_generated, sample_scenic  # noqa: E402
from synth.config import SynthConfig  # noqa: E402
from synth.dsl import parse_program  # noqa: E402
from synth.road.lane_facts import RoadIndex  # noqa: E402
from synth.road.roadmap import AREA_KINDS  # noqa: E402
from synth.scene import scene_from_dict, scene_from_json  # noqa: E402
from synth.scenic.emit import SOURCE_PREFIX, render_scenic  # noqa: E402
from synth.scenic.road import CENTRE_LINES, INTERSECTION_LANES, TABLES, road_scenic  # noqa: E402

EXCERPT = ROOT / "data" / "nuscenes-mini-excerpt"


def _box(x0, y0, x1, y1):
    return [[x0, y0], [x1, y0], [x1, y1], [x0, y1]]


# Two lanes of opposite direction that overlap in 2 <= x <= 4 (the tie rule decides there), an intersection lane
# across them that reaches beyond the intersection, a crosswalk, and a drivable area that leaves a margin off road.
ROAD = {"map_id": "hand-made", "features": [
    {"id": "north", "kind": "lane", "polygon": _box(0, -30, 4, 30), "line": [[2, -30], [2, 0.5], [2, 30]],
     "successors": [], "predecessors": [], "left": None, "right": None, "is_intersection": False},
    {"id": "south", "kind": "lane", "polygon": _box(2, -30, 6, 30), "line": [[4, 30], [4, -30]],
     "successors": [], "predecessors": [], "left": None, "right": None, "is_intersection": False},
    {"id": "turn", "kind": "lane", "polygon": _box(-4, 10, 12, 14), "line": [[-4, 12], [12, 12]],
     "successors": [], "predecessors": [], "left": None, "right": None, "is_intersection": True},
    {"id": "cw", "kind": "crosswalk", "polygon": _box(-6, -12, 10, -8)},
    {"id": "x1", "kind": "intersection", "polygon": _box(-6, 8, 4, 16)},
    {"id": "da", "kind": "drivable_area", "polygon": _box(-8, -30, 12, 30)},
    {"id": "edge", "kind": "road_line", "line": [[-8, -30], [-8, 30]]},
]}
SCENE = {"frame_id": "road", "road": ROAD, "entities": [
    {"id": "ego", "type": "Car", "x": 2.0, "y": 0.0, "heading": 0.0},
    {"id": "car1", "type": "Car", "x": 4.5, "y": 5.0, "heading": 180.0}]}
# car1 anywhere over the road and beyond it, facing any way (absolute forms: no reference moves it).
SPREAD = "car1 = new Car on Range(-10, 14) @ Range(-32, 32), facing Range(0, 360) deg\n"


def _text(doc=SCENE, program=SPREAD):
    return render_scenic(parse_program(program), scene_from_dict(doc), SynthConfig())


def _tables(text: str) -> dict:
    """The road section of a text run as plain Python (it is: its helpers use no Scenic syntax), the regions
    standing for their points, to read back what the text defines."""
    lines = text.splitlines()
    start = next(i for i, ln in enumerate(lines) if ln.startswith("# The recorded road"))
    end = next(i for i in range(start, len(lines)) if lines[i].startswith("ego = new"))
    space: dict = {"PolygonalRegion": lambda pts: ("region", pts)}
    exec("\n".join(lines[start:end]), space)  # noqa: S102 - the test's own emitted text
    return space


def _facts(road, entity):
    """The lane facts of a placed entity, by synth.road.lane_facts on the scene's road (the ego frame: headings from +x)."""
    return RoadIndex(road).facts(np.array([entity.x]), np.array([entity.y]), np.array([(entity.heading + 90) % 360]))[0]


def test_the_regions_are_the_scenes_features_exactly():
    scene = scene_from_dict(SCENE)
    space = _tables(_text())
    for kind, table in TABLES:
        want = {f.feature_id: ("region", f.polygon) for f in scene.road.of_kind(kind)}
        assert space[table] == want  # float repr round-trips: every vertex as the scene has it
    assert space[CENTRE_LINES] == {f.feature_id: f.line for f in scene.road.lanes}
    assert space[INTERSECTION_LANES] == {"turn"}
    assert {k for k, _ in TABLES} == set(AREA_KINDS) and "'edge'" not in _text().split(SOURCE_PREFIX)[0]


def test_a_scene_without_a_road_has_no_road_section():
    doc = {k: v for k, v in SCENE.items() if k != "road"}
    assert "road__" not in _text(doc)


# What a requirement over the regions says, and the lane facts that must then hold (LaneFacts -> bool).
REQUIREMENTS = [
    ("road__lane_of(car1) == 'north'", lambda f: f.lane == "north"),
    ("road__lane_of(car1) == 'south'", lambda f: f.lane == "south"),
    ("road__lane_of(car1) == 'turn'", lambda f: f.lane == "turn"),
    # the tie rule where both lanes of opposite direction contain the centre
    ("len(road__in(road__lanes, car1)) == 2 and road__lane_of(car1) == 'north'",
     lambda f: len(f.lanes) == 2 and f.lane == "north"),
    ("len(road__in(road__lanes, car1)) == 2 and road__lane_of(car1) == 'south'",
     lambda f: len(f.lanes) == 2 and f.lane == "south"),
    ("road__lane_of(car1) is None", lambda f: f.lane is None and not f.lanes),
    ("road__in(road__crosswalks, car1) == ['cw']", lambda f: f.on_crosswalk),
    ("not road__in(road__crosswalks, car1)", lambda f: not f.on_crosswalk),
    ("road__in(road__intersections, car1) == ['x1']", lambda f: f.in_intersection),
    ("not road__in(road__lanes, car1) and not road__in(road__drivable_areas, car1)", lambda f: f.off_road),
    # the helpers of the lane facts, each way round (an intersection lane reaches beyond the intersection here)
    ("road__in_intersection(car1) and not road__in(road__intersections, car1)",
     lambda f: f.in_intersection and "turn" in f.lanes),
    ("road__in_intersection(car1)", lambda f: f.in_intersection),
    ("not road__in_intersection(car1)", lambda f: not f.in_intersection),
    ("road__on_crosswalk(car1)", lambda f: f.on_crosswalk),
    ("road__off_road(car1)", lambda f: f.off_road),
    ("not road__off_road(car1)", lambda f: not f.off_road),
]


@pytest.mark.parametrize("requirement, holds", REQUIREMENTS, ids=[r for r, _ in REQUIREMENTS])
def test_scenic_samples_under_a_road_requirement_have_those_lane_facts(requirement, holds):
    import scenic

    scene = scene_from_dict(SCENE)
    text = _text() + f"require {requirement}\n"
    scenario = scenic.scenarioFromString(text, mode2D=True)
    random.seed(5)
    np.random.seed(5)
    scenes, _ = scenario.generateBatch(12, maxIterations=3000)
    placed = set()
    for s in scenes:
        car1 = s.objects[1]
        e = scene_from_dict({"entities": [SCENE["entities"][0], {
            "id": "car1", "type": "Car", "x": float(car1.position.x), "y": float(car1.position.y),
            "heading": float(np.degrees(car1.heading))}]}).by_id()["car1"]
        assert holds(_facts(scene.road, e)), (requirement, e)
        placed.add((e.x, e.y))
    assert len(placed) == 12  # variants, not copies


def test_the_road_compiles_and_samples_with_the_program_and_is_in_the_provenance_record():
    text = _text()
    record = json.loads(text.splitlines()[-1][len(SOURCE_PREFIX):])
    assert scene_from_dict({"entities": SCENE["entities"], "road": record["road"]}).road == scene_from_dict(SCENE).road
    ensure_generated(text)  # rendered again from its record, byte for byte, road included
    samples = sample_scenic(text, SampleOptions(n=3, seed=1, sampler="scenic"))
    assert len(samples.scenes) == 3
    # a road edited in the text (not in the record) is refused before anything runs
    edited = text.replace("-30.0,", "-31.0,", 1)
    assert edited != text and edited.split(SOURCE_PREFIX)[1] == text.split(SOURCE_PREFIX)[1]
    with pytest.raises(ScenicProgramError, match="differs from what r2sgen writes"):
        ensure_generated(edited)


def test_a_real_road_from_r2s_scene_compiles_and_samples(tmp_path):
    """nuScenes through ScenarioNet (the shipped excerpt): r2s extract, r2s scene --radius, r2s synth --format
    scenic, r2s sample --sampler scenic, as a user runs them; the text holds every area feature of the scene."""
    frames = tmp_path / "frames"
    assert run_r2s("extract", "scenarionet", str(EXCERPT / "scenarionet"), "--categories", "all", "--out",
                   str(frames)).returncode == 0
    scene_file, scenic_file = tmp_path / "scene.json", tmp_path / "p.scenic"
    proc = run_r2s("scene", str(frames), "scene-0103/0", "--radius", "50", "--out", str(scene_file))
    assert proc.returncode == 0, proc.stderr
    scene = scene_from_json(scene_file.read_text())
    assert scene.road is not None and scene.road.lanes
    proc = run_r2s("synth", str(scene_file), "--format", "scenic", "--out", str(scenic_file))
    assert proc.returncode == 0, proc.stderr
    text = scenic_file.read_text()
    space = _tables(text)
    for kind, table in TABLES:
        assert space[table] == {f.feature_id: ("region", f.polygon) for f in scene.road.of_kind(kind)}
    assert "\n".join(road_scenic(scene.road)) in text
    out = tmp_path / "variants"
    proc = run_r2s("sample", str(scenic_file), "--sampler", "scenic", "--n", "2", "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    assert len(list(out.glob("sample_*.json"))) == 2


def test_feature_ids_of_any_characters_are_read_back_as_they_are():
    """Ids are data: quotes (the literal's own ''' among them), backslashes, spaces, non-ASCII. (Ids are printable
    text since they name OpenDRIVE roads: a newline or U+2028 in one is refused, test_scene_road.py.)"""
    import scenic

    odd = ["x'''y", 'a"b', "back\\slash", "line break", "caf\u00e9 \u00e0\u4e2d", "'", "\\"]
    doc = {**SCENE, "road": {"map_id": "m'''\\", "features": [
        {"id": fid, "kind": "crosswalk", "polygon": _box(k, 20, k + 1, 21)} for k, fid in enumerate(odd)]}}
    text = _text(doc)
    assert _tables(text)["road__crosswalks"] == {fid: ("region", scene_from_dict(doc).road[fid].polygon)
                                                 for fid in odd}
    scenario = scenic.scenarioFromString(text + f"require road__in(road__crosswalks, car1) == [{odd[0]!r}]\n",
                                         mode2D=True)
    random.seed(2)
    scene, _ = scenario.generate(maxIterations=20000)
    assert 0 <= scene.objects[1].position.x <= 1 and 20 <= scene.objects[1].position.y <= 21
