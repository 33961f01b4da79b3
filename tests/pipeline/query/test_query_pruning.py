"""The pruning of one-frame joins (pipeline.query.sql, "Pruning the joins"): the box around a name's anchor is a
necessary condition of the clauses' semantics (checked by the checker's own Clause.holds, at and beyond the
boundaries), and random scenes with random Ranges give the brute force's matches with the box and without it."""

from __future__ import annotations

import math
import random

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pipeline.query import sql
from synth.config import SynthConfig
from synth.patterns.one_frame import parse_pattern
from synth.scene import Entity, Scene
from tests.pipeline.query.test_query import _write, brute, engine

CLAUSES = ["ahead of {r} by Range({a}, {b})", "left of {r} by Range({a}, {b})", "within Range({a}, {b}) of {r}",
           "on Range({c}, {d}) @ Range({a}, {b}) relative to {r}"]


def _clause(form: str, a: float, b: float, c: float, d: float):
    text = f"r = new Car on Range(-1e3, 1e3) @ Range(-1e3, 1e3)\ne = new Car {form.format(a=a, b=b, c=c, d=d, r='r')}\n"
    pattern = parse_pattern(text)
    return pattern, next(cl for _, cl in pattern.statements[1].clauses() if cl.ref == "r")


ranges = st.tuples(st.floats(0, 50), st.floats(0, 50)).map(sorted)


@settings(max_examples=400, deadline=None)
@given(form=st.sampled_from(CLAUSES), ab=ranges, cd=ranges, rx=st.floats(-1e6, 1e6), ry=st.floats(-1e6, 1e6),
       rh=st.floats(0, 360), bearing=st.floats(0, 360), nudge=st.sampled_from([0.0, 1e-9, -1e-9, 1e-6]))
def test_every_pair_that_holds_is_within_the_box(form, ab, cd, rx, ry, rh, bearing, nudge):
    """A pair the semantics accept lies within box(reach) of its reference on each axis: entities placed on the
    Range's far boundary (and a hair either side) in a random direction, far from the origin too."""
    (a, b), (c, d) = ab, (cd[0] - 25, cd[1] - 25)
    _, clause = _clause(form, a, b, c, d)
    bound = sql.reach(clause)
    assert bound is not None
    far = math.hypot(max(abs(c), abs(d)), b) if form.startswith("on") else b
    r = Entity("r", "Car", rx, ry, rh)
    t = math.radians(bearing)
    e = Entity("e", "Car", rx + (far + nudge) * math.cos(t), ry + (far + nudge) * math.sin(t), 0.0)
    if clause.holds(e, r, SynthConfig()):
        half = sql.box(bound)
        assert abs(e.x - r.x) <= half and abs(e.y - r.y) <= half


def test_clauses_without_a_distance_have_no_reach():
    pattern = parse_pattern("r = new Car on Range(-5, 5) @ Range(-5, 5)\n"
                            "e = new Car on Range(-5, 5) @ Range(-5, 5), facing toward r\n")
    assert all(sql.reach(cl) is None for _, cl in pattern.statements[1].clauses() if cl.ref == "r")
    assert sql.anchor(pattern.statements[1]) == sql.Anchor("r")  # still paired with r, on the frame alone
    assert sql.reach(_clause(CLAUSES[0], 0, 1e300, 0, 0)[1]) is None  # beyond any two entities that are not wild


def _scenes(g: random.Random, n: int) -> list[Scene]:
    """Frames of 6 to 12 cars in a 40 m square (so Ranges of a few metres keep some pairs and drop others),
    one in eight frames with a wild car (beyond 1e6 m)."""
    scenes = []
    for i in range(n):
        ents = [Entity("ego", "Car", 0.0, 0.0, g.uniform(0, 360))]
        for j in range(g.randint(6, 12)):
            x, y = g.uniform(-20, 20), g.uniform(-20, 20)
            if g.random() < 0.02:
                x *= 1e6
            ents.append(Entity(f"car{j}", g.choice(["Car", "Truck"]), x, y, g.uniform(0, 360)))
        scenes.append(Scene(f"p/{i}", tuple(ents)))
    return scenes


@settings(max_examples=12, deadline=None)
@given(seed=st.integers(0, 10**6), forms=st.lists(st.sampled_from(CLAUSES), min_size=2, max_size=2),
       bounds=st.lists(st.tuples(st.floats(0, 8), st.floats(0, 8)).map(sorted), min_size=4, max_size=4))
def test_random_scenes_and_ranges_match_with_and_without_the_box(seed, forms, bounds, tmp_path_factory):
    g = random.Random(seed)
    (a1, b1), (a2, b2), (c1, d1), (c2, d2) = bounds
    text = ("a = new Vehicle on Range(-30, 30) @ Range(-30, 30), facing Range(0, 360) deg\n"
            f"b = new Vehicle {forms[0].format(r='a', a=a1, b=b1, c=c1 - 4, d=d1 - 4)}\n"
            f"c = new Vehicle {forms[1].format(r='b', a=a2, b=b2 + 2, c=c2 - 4, d=d2 - 4)}\n")
    scenes = _scenes(g, 30)
    tmp = tmp_path_factory.mktemp("p")
    path = _write(scenes, tmp / "f.parquet")
    got, _ = engine(path, text, tmp)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(sql, "reach", lambda clause: None)  # no box: every pair of the frame is a candidate
        unpruned, _ = engine(path, text, tmp)
    assert got == unpruned == brute(scenes, text)
