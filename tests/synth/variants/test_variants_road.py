"""Variants of a scene with a road (issue 24 item 5): every variant, from either sampler, is on the recorded road
and carries the lane facts of where its entities now are, decided again here by synth.road.lane_facts.RoadIndex
(vectorised, independent of the sampler's one-pose path); a requirement beyond the boxes that reads the road
(synth.draws.Requirement) keeps the chain where it holds, as Scenic's `require` does."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pytest

from pipeline.variants.sample import SampleOptions, sample_program
from synth.config import SynthConfig
from synth.draws import Requirement
from synth.dsl import parse_program
from synth.road.lane_facts import RoadIndex
from synth.scene import scene_from_dict
from synth.variants import gibbs
from synth.variants.gibbs import sample_variants
from synth.variants.parameters import parameterise
from tests.support import overlapping

ROAD = {"map_id": "hand-made", "features": [
    {"id": "north", "kind": "lane", "polygon": [[0, -30], [4, -30], [4, 30], [0, 30]], "line": [[2, -30], [2, 30]]},
    {"id": "south", "kind": "lane", "polygon": [[4, -30], [8, -30], [8, 30], [4, 30]], "line": [[6, 30], [6, -30]]},
    {"id": "cw", "kind": "crosswalk", "polygon": [[-2, 10], [10, 10], [10, 13], [-2, 13]]},
    {"id": "da", "kind": "drivable_area", "polygon": [[-4, -30], [12, -30], [12, 30], [-4, 30]]},
]}
SCENE = {"frame_id": "road", "road": ROAD, "entities": [
    {"id": "ego", "type": "Car", "x": 2.0, "y": 0.0, "heading": 0.0},
    {"id": "car1", "type": "Car", "x": 2.0, "y": 12.0, "heading": 0.0},
    {"id": "car2", "type": "Car", "x": 6.0, "y": 20.0, "heading": 180.0},
    {"id": "ped1", "type": "Pedestrian", "x": 9.0, "y": 11.5, "heading": 90.0}]}
PROGRAM = ("car1 = new Car ahead of ego by Range(8, 16), facing Range(-5, 5) deg relative to ego\n"
           "car2 = new Car on Range(2, 7) @ Range(15, 25) relative to car1, facing Range(175, 185) deg\n"
           "ped1 = new Pedestrian on Range(5, 10) @ Range(-4, 4) relative to car1, facing Range(60, 120) deg\n")


def facts(scene):
    """(lanes, lane, in_intersection, on_crosswalk, off_road) of every entity, decided on the scene's road."""
    ents = scene.entities
    got = RoadIndex(scene.road).facts(np.array([e.x for e in ents]), np.array([e.y for e in ents]),
                                      np.array([(e.heading + 90) % 360 for e in ents]))
    return [(f.lanes, f.lane, f.in_intersection, f.on_crosswalk, f.off_road) for f in got]


def carried(scene):
    return [(e.lanes, e.lane, e.in_intersection, e.on_crosswalk, e.off_road) for e in scene.entities]


@pytest.mark.parametrize("sampler", ["gibbs", "scenic"])
def test_every_variant_is_on_the_recorded_road_with_the_facts_of_where_it_is(sampler):
    if sampler == "scenic":
        pytest.importorskip("scenic", reason="scenic (3.1.1) is not importable here")
    scene = scene_from_dict(SCENE)
    samples = sample_program(parse_program(PROGRAM), scene, SynthConfig(), SampleOptions(n=8, seed=4, sampler=sampler))
    assert len(samples.scenes) == 8
    seen = set()
    for s in samples.scenes:
        assert s.road == scene.road
        assert carried(s) == facts(s)
        seen.add(tuple(f[1] for f in facts(s)))
    assert len(seen) > 1  # the entities move across lanes: the facts are of each variant, not the recording's


@dataclass(frozen=True)
class InLane(Requirement):
    """A test requirement: the entity's lane is `lane` (None: any lane but its reference's)."""

    lane: str | None = None

    def allowed(self, own, ref, road):
        mine = road.facts(own.x, own.y, own.heading).lane
        if self.lane is not None:
            return mine == self.lane
        return mine is not None and mine != road.facts(ref.x, ref.y, ref.heading).lane


@dataclass(frozen=True)
class OnCrosswalk(Requirement):
    def allowed(self, own, ref, road):
        return road.facts(own.x, own.y, own.heading).on_crosswalk


# car1 in lane north; car2 in a lane other than car1's (a requirement that reads its reference, which moves);
# ped1 on the crosswalk. The recording meets all three.
REQUIRED = {"car1": InLane(None, (), (), lane="north"), "car2": InLane("car1", (), ()),
            "ped1": OnCrosswalk(None, (), ())}


def with_requirements(program, scene, config):
    p = parameterise(program, scene, config)
    index = {name: k for k, name in enumerate(p.ids)}
    draws, refs = list(p.draws), list(p.refs)
    for name, req in REQUIRED.items():
        k = index[name]
        draws[k] += (req,)
        refs[k] += (None if req.ref is None else index[req.ref],)
    return replace(p, draws=tuple(draws), refs=tuple(refs))


def meets(scene) -> bool:
    by_id = {e.id: f for e, f in zip(scene.entities, facts(scene))}
    return (by_id["car1"][1] == "north" and by_id["car2"][1] not in (None, by_id["car1"][1])
            and by_id["ped1"][3])


@pytest.mark.parametrize("allow_collisions", [False, True])
def test_the_chain_keeps_every_variant_where_the_requirements_that_read_the_road_hold(monkeypatch, allow_collisions):
    scene, program = scene_from_dict(SCENE), parse_program(PROGRAM)
    free = sample_variants(program, scene, SynthConfig(), 40, seed=2, allow_collisions=allow_collisions)
    assert not all(meets(s) for s in free.scenes)  # the control: the program alone leaves them
    monkeypatch.setattr(gibbs, "parameterise", with_requirements)
    kept = sample_variants(program, scene, SynthConfig(), 40, seed=2, allow_collisions=allow_collisions)
    assert all(meets(s) for s in kept.scenes)
    if not allow_collisions:  # the collision rule stays
        assert all(overlapping(s) <= overlapping(scene) for s in kept.scenes)
    assert len({(s.by_id()["car2"].x, s.by_id()["ped1"].y) for s in kept.scenes}) == 40  # it still moves
