"""Lane clauses in Scenic and in variants (issue 24 item 5): every lane clause is a requirement over the road's
regions that official Scenic (3.1.1) keeps, and `r2s sample` keeps every variant on the lanes its program says,
with either sampler. Each variant's lane facts are decided again here by synth.road.lane_facts.RoadIndex (vectorised,
independent of the sampler's one-pose path and of Scenic's shapely containment), and every lane clause of the
program is asked of them, as the checker asks it of a recording."""

from __future__ import annotations

import random
import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pipeline.variants.sample import SampleOptions, sample_program
from synth.config import SynthConfig
from synth.dsl import parse_program
from synth.road.lane_facts import RoadIndex
from synth.scene import scene_from_dict, scene_from_json
from synth.synthesize import synthesize
from synth.variants.scene_road import SceneRoad
from tests.support import ROOT, overlapping, run_r2s
from tests.support.lanes import BruteLanes, random_lane_scene

LANES = SynthConfig(lanes=True)


def _box(x0, y0, x1, y1):
    return [[x0, y0], [x1, y0], [x1, y1], [x0, y1]]


def _lane(fid, box, line, **links):
    return {"id": fid, "kind": "lane", "polygon": _box(*box), "line": line, "left": links.get("left"),
            "right": links.get("right"), "successors": [], "predecessors": [], "is_intersection": False}


# Ego's frame: +y ahead. Lanes A and B run north side by side (B right of A), C runs south beside A (A's
# oncoming lane); an intersection beyond their ends, a crosswalk across them, a drivable area with a shoulder.
ROAD = {"map_id": "hand-made", "features": [
    _lane("A", (0, -40, 4, 40), [[2, -40], [2, 40]], right="B"),
    _lane("B", (4, -40, 8, 40), [[6, -40], [6, 40]], left="A"),
    _lane("C", (-4, -40, 0, 40), [[-2, 40], [-2, -40]]),
    {"id": "cw", "kind": "crosswalk", "polygon": _box(-4, 20, 8, 23)},
    {"id": "x1", "kind": "intersection", "polygon": _box(-4, 40, 8, 48)},
    {"id": "da", "kind": "drivable_area", "polygon": _box(-7, -40, 10, 48)},
]}
ENTITIES = [
    {"id": "ego", "type": "Car", "x": 2.0, "y": 0.0, "heading": 0.0},
    {"id": "car1", "type": "Car", "x": 2.0, "y": 15.0, "heading": 0.0},
    {"id": "car2", "type": "Car", "x": 6.0, "y": 8.0, "heading": 0.0},
    {"id": "car3", "type": "Car", "x": -2.0, "y": 12.0, "heading": 180.0},
    {"id": "car4", "type": "Car", "x": 2.0, "y": 44.0, "heading": 0.0},
    {"id": "car5", "type": "Car", "x": 6.0, "y": -20.0, "heading": 0.0},
    {"id": "ped1", "type": "Pedestrian", "x": -3.0, "y": 21.5, "heading": 90.0},
    {"id": "ped2", "type": "Pedestrian", "x": -5.5, "y": 5.0, "heading": 0.0},
    {"id": "ped3", "type": "Pedestrian", "x": -9.0, "y": 0.0, "heading": 0.0}]
# Every lane clause kind, each entity free to leave its lane (3 m each side of where it is): the lane clauses
# are what keeps it there.
LANE_OF = {"car1": "in lane of ego", "car2": "in lane right of ego", "car3": "in oncoming lane of ego",
           "car4": "in intersection", "car5": 'in lane "B"', "ped1": "on crosswalk", "ped2": "off lane",
           "ped3": "off road"}


def _program(with_lanes: bool) -> str:
    out = []
    for e in ENTITIES[1:]:
        x, y, h = e["x"] - 2.0, e["y"], e["heading"]
        lane = f", {LANE_OF[e['id']]}" if with_lanes else ""
        out.append(f"{e['id']} = new {e['type']} on Range({x - 3:g}, {x + 3:g}) @ Range({y - 3:g}, {y + 3:g}) "
                   f"relative to ego, facing Range({h - 10:g}, {h + 10:g}) deg{lane}")
    return "\n".join(out) + "\n"


def hand_made():
    scene = scene_from_dict({"frame_id": "lanes", "entities": ENTITIES, "road": ROAD})
    return SceneRoad(scene.road).placed(scene)  # the recording's facts, as extraction would give them


def decided_again(variant):
    """(lanes, lane, in_intersection, on_crosswalk, off_road) of each entity, decided again by RoadIndex on the
    variant's road."""
    ents = variant.entities
    facts = RoadIndex(variant.road).facts(np.array([e.x for e in ents]), np.array([e.y for e in ents]),
                                          np.array([(e.heading + 90) % 360 for e in ents]))
    return {e.id: f for e, f in zip(ents, facts)}


def brute_holds(clause, facts, ref_facts, lanes: BruteLanes) -> bool:
    """A lane clause on decided facts, read from docs/dsl.md with the brute-force lane relations of
    tests/support/lanes (every walk spelled out, GEOS geometry): nothing of synth.parts or synth.road.lane_relations."""
    text = str(clause)
    if clause.ref is not None:
        side = {"in lane of": "same", "in lane left of": "left", "in lane right of": "right",
                "in oncoming lane of": "oncoming"}[text.rsplit(" ", 1)[0]]
        return facts.lane is not None and facts.lane in lanes.related(ref_facts.lane, side)
    if text.startswith('in lane "'):
        return facts.lane == text[len('in lane "'):-1]
    return {"in intersection": facts.in_intersection, "on crosswalk": facts.on_crosswalk,
            "off road": facts.off_road, "off lane": not facts.lanes and not facts.off_road,
            "anywhere": True}[text]


def assert_on_their_lanes(program, variant):
    facts = decided_again(variant)
    lanes = BruteLanes(variant.road)
    by_id = variant.by_id()
    for statement in program.statements:
        clause, me = statement.lane, statement.id
        ref = facts[clause.ref] if clause.ref is not None else None
        assert brute_holds(clause, facts[me], ref, lanes), (variant.frame_id, me, str(clause), facts[me])
        # the variant carries the facts of where it is (not the recording's)
        e, f = by_id[me], facts[me]
        assert (e.lanes, e.lane, e.in_intersection, e.on_crosswalk, e.off_road) == (
            f.lanes, f.lane, f.in_intersection, f.on_crosswalk, f.off_road)


def test_the_hand_made_recording_is_in_its_program():
    from synth.semantics import check

    assert check(parse_program(_program(True)), hand_made(), LANES).ok


@pytest.mark.parametrize("sampler", ["scenic", "gibbs"])
def test_every_variant_keeps_every_lane_clause(sampler):
    if sampler == "scenic":
        pytest.importorskip("scenic", reason="scenic (3.1.1) is not importable here")
    program = parse_program(_program(True))
    samples = sample_program(program, hand_made(), LANES, SampleOptions(n=12, seed=7, sampler=sampler,
                                                                        max_iterations=5000))
    assert len(samples.scenes) == 12
    for v in samples.scenes:
        assert_on_their_lanes(program, v)
        assert overlapping(v) <= overlapping(hand_made())  # the collision rule stays
    assert len({v.by_id()["car1"].x for v in samples.scenes}) == 12


def test_without_the_lane_clauses_the_same_positions_leave_the_lanes():
    """The control: the program's position Ranges alone let entities leave their lanes, so the tests above see
    the requirements at work."""
    program = parse_program(_program(True))
    free = sample_program(parse_program(_program(False)), hand_made(), SynthConfig(),
                          SampleOptions(n=40, seed=7))
    broken = 0
    for v in free.scenes:
        v = SceneRoad(hand_made().road).placed(v)
        try:
            assert_on_their_lanes(program, v)
        except AssertionError:
            broken += 1
    assert broken >= 10


def test_scenic_text_states_each_lane_clause_as_a_requirement():
    from synth.scenic.emit import render_scenic

    text = render_scenic(parse_program(_program(True)), hand_made(), LANES)
    required = re.findall(r"^require (road__\w+\(.*\)(?: == '.*')?)$", text, flags=re.M)
    assert required == [
        "road__lane_related(car1, ego, 'same')", "road__lane_related(car2, ego, 'right')",
        "road__lane_related(car3, ego, 'oncoming')", "road__in_intersection(car4)", "road__lane_of(car5) == 'B'",
        "road__on_crosswalk(ped1)", "road__off_lane(ped2)", "road__off_road(ped3)"]


EXCERPT = ROOT / "data" / "nuscenes-mini-excerpt"


@pytest.fixture(scope="module")
def real_scenes(tmp_path_factory):
    """Every frame of the shipped nuScenes excerpt through r2s extract and r2s scene (its road within the
    default radius), as a user runs them."""
    out = tmp_path_factory.mktemp("lanes")
    frames = out / "frames"
    assert run_r2s("extract", "scenarionet", str(EXCERPT / "scenarionet"), "--categories", "all", "--out",
                   str(frames)).returncode == 0
    import pandas as pd

    scenes = []
    for fid in pd.read_parquet(frames, columns=["frame_id"]).frame_id.unique()[::3]:
        proc = run_r2s("scene", str(frames), fid)
        assert proc.returncode == 0, proc.stderr
        scenes.append(scene_from_json(proc.stdout))
    return scenes


def test_variants_of_real_frames_with_lanes_stay_on_the_lanes_their_program_says(real_scenes):
    kinds = set()
    for scene in real_scenes:
        result = synthesize(scene, LANES)
        samples = sample_program(result.program, scene, LANES, SampleOptions(n=4, seed=1))
        for v in samples.scenes:
            assert_on_their_lanes(result.program, v)
        kinds |= {type(s.lane).__name__ for s in result.program.statements}
    assert {"LaneRelation", "LaneFact"} <= kinds


def test_official_scenic_keeps_the_lane_clauses_of_real_programs(real_scenes):
    """The first statements of each real program (a prefix is a program: references come first), sampled by
    Scenic's own rejection sampler from the emitted text, on the recorded road."""
    pytest.importorskip("scenic", reason="scenic (3.1.1) is not importable here")
    from synth.dsl import Program

    for scene in real_scenes:
        program = synthesize(scene, LANES).program
        prefix = Program(program.statements[:6])
        samples = sample_program(prefix, scene, LANES, SampleOptions(n=3, seed=2, sampler="scenic",
                                                                    allow_collisions=True))
        for v in samples.scenes:
            assert_on_their_lanes(prefix, v)


@given(st.integers(0, 10**6), st.integers(2, 7))
@settings(max_examples=12, deadline=None)
def test_variants_of_random_roads_stay_on_their_lanes(seed, n):
    """Random roads and scenes (tests/support/lanes: lanes cut into linked segments, neighbours, oncoming lanes,
    a turn, an intersection, a crosswalk): the optimal lane program, then variants from the chain."""
    scene = random_lane_scene(random.Random(seed), n)
    program = synthesize(scene, LANES).program
    for v in sample_program(program, scene, LANES, SampleOptions(n=3, seed=seed)).scenes:
        assert_on_their_lanes(program, v)
        assert overlapping(v) <= overlapping(scene)
