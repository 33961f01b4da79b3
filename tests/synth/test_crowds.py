"""The crowd frames of the synthesis benchmark (tests/support/crowds.py): deterministic, real sizes, laid out as a
recording would be (no overlapping boxes, within the extractors' radius, ids ranked by distance to ego)."""

from __future__ import annotations

import math

import pytest

from synth.variants.overlap import scene_overlaps
from tests.support.crowds import RADIUS, REAL_SIZES, crowd_scene, crowd_scene_dict, crowd_scenes


def test_same_seed_same_frame_other_seed_other_frame():
    assert crowd_scene_dict(7) == crowd_scene_dict(7)
    assert crowd_scene_dict(7)["entities"] != crowd_scene_dict(8)["entities"]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_frame_is_a_recording_like_scene(seed):
    scene = crowd_scene(seed, pedestrians=52, barriers=6, cones=4, cars=2)
    counts = {t: sum(e.type == t for e in scene.others) for t in REAL_SIZES}
    assert counts == {"Pedestrian": 52, "Barrier": 6, "TrafficCone": 4, "Car": 2}
    for e in scene.others:
        lo, hi = REAL_SIZES[e.type][0], REAL_SIZES[e.type][-1]
        assert lo[0] <= e.length <= hi[0] and lo[1] <= e.width <= hi[1], e
        assert 0 <= e.heading < 360
        assert math.hypot(e.x, e.y) <= RADIUS
    assert scene_overlaps(scene) == []
    dist = [math.hypot(e.x, e.y) for e in scene.others]
    assert dist == sorted(dist)
    assert [e.id for e in scene.others] == [f"{e.type.lower()}{i}" for i, e in enumerate(scene.others, start=1)]


def test_the_benchmark_set_is_a_dense_crowd_facing_every_way():
    scenes = crowd_scenes(6)
    for s in scenes:
        peds = [e for e in s.others if e.type == "Pedestrian"]
        assert 50 <= len(peds) <= 60
        assert any(e.type == "Barrier" for e in s.others) and any(e.type == "TrafficCone" for e in s.others)
    octants = {int(e.heading // 45) for s in scenes for e in s.others if e.type == "Pedestrian"}
    assert octants == set(range(8))
