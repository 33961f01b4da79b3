"""The recipes of docs/layout.md ("Add a part", "Add a clause kind"), as written there: the toy part's module,
saved where Python finds it and registered, is a part like the others through synthesize (each oracle), the
checker, certification, Scenic emission and the sampler's draws; the clause kind, put in that module as the recipe
says, is parsed, checked, certified, emitted and drawn."""

from __future__ import annotations

import importlib
import random
import re

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from synth import synthesize
from synth.config import SynthConfig
from synth.draws import SPEED
from synth.dsl import parse_program
from synth.parts import all_parts, clause_kinds, register, unregister
from synth.scene import Scene, scene_from_dict
from synth.scenic.emit import render_scenic
from synth.semantics import check
from synth.smt import Z3Backend
from synth.smt.certify import certify
from synth.variants.parameters import parameterise
from tests.support import ROOT

LAYOUT = ROOT / "docs" / "layout.md"


def recipe(section: str) -> str:
    text = LAYOUT.read_text()
    return re.search(r"```python\n(.*?)```", text[text.index(f"### {section}"):], re.S).group(1)


def load(tmp_path, monkeypatch, name: str, code: str):
    (tmp_path / f"{name}.py").write_text(code)
    monkeypatch.syspath_prepend(str(tmp_path))
    return importlib.import_module(name)


@pytest.fixture
def pace(tmp_path, monkeypatch):
    """The toy part's module as the recipe writes it, registered for the test."""
    module = load(tmp_path, monkeypatch, "toy_pace_recipe", recipe("Add a part"))
    register(module.PART)
    yield module
    unregister(module.PART)


@pytest.fixture
def cruising(tmp_path, monkeypatch):
    """The toy part with the recipe's clause kind added: the class before the part, and listed in its clauses."""
    code = recipe("Add a part")
    code = code.replace("\nclass PacePart(Part):", "\n" + recipe("Add a clause kind") + "\n\nclass PacePart(Part):")
    code = code.replace("clauses = (Slow, Pace)", "clauses = (Slow, Pace, Cruising)")
    module = load(tmp_path, monkeypatch, "toy_cruising_recipe", code)
    register(module.PART)
    yield module
    unregister(module.PART)


def scene_of(rows: list[tuple[float, float, float, float]]) -> Scene:
    """ego and cars at (x, y, heading, speed)."""
    entities = [{"id": "ego", "type": "Car", "x": 0.0, "y": 0.0, "heading": 0.0, "speed": 5.0}]
    entities += [{"id": f"car{k}", "type": "Car", "x": x, "y": y, "heading": h, "speed": v}
                 for k, (x, y, h, v) in enumerate(rows, start=1)]
    return scene_from_dict({"frame_id": "toy", "entities": entities})


coords = st.floats(-40, 40, allow_nan=False).map(lambda v: round(v, 2))
rows = st.lists(st.tuples(coords, coords, st.floats(0, 359).map(lambda v: round(v, 1)),
                          st.sampled_from([0.0, 1.0, 2.0, 2.5, 7.25, 12.0])), min_size=1, max_size=5)


def test_a_registered_part_is_one_more_part_everywhere(pace):
    assert all_parts()[-1] is pace.PART
    assert [k.label for k in clause_kinds()[-2:]] == ["slow", "pace"]
    with pytest.raises(ValueError, match="registered already"):
        register(pace.PART)


# The fixture registers the part once for every example: what each example needs.
@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(rows=rows, oracle=st.sampled_from(["hybrid", "smt", "closed-form"]))
def test_the_toy_part_through_synthesize_the_checker_and_certification(pace, rows, oracle):
    scene = scene_of(rows)
    config = SynthConfig(oracle=oracle)
    result = synthesize(scene, config)
    # The part is independent of the others: each entity pays 1 more exactly when it is faster than 2 m/s
    # (counted here from the speeds, not by the part), over the optimum without it.
    unregister(pace.PART)
    try:
        static = synthesize(scene, config)
    finally:
        register(pace.PART)
    assert result.cost == static.cost + sum(e.speed > 2.0 for e in scene.others)
    by_id = scene.by_id()
    for s in result.program.statements:
        assert isinstance(s.pace, pace.Slow if by_id[s.id].speed <= 2.0 else pace.Pace)
    assert check(result.program, scene).ok
    assert certify(Z3Backend(config), result.program, scene) == []
    assert parse_program(str(result.program)) == result.program


def test_the_checker_and_certification_refute_a_wrong_pace(pace):
    scene = scene_of([(0.0, 10.0, 0.0, 1.0), (5.0, 10.0, 0.0, 7.25)])
    program = synthesize(scene).program
    faster = scene_of([(0.0, 10.0, 0.0, 3.0), (5.0, 10.0, 0.0, 9.5)])
    assert [(v.entity, v.part, v.message) for v in check(program, faster).violations] == [
        ("car1", "pace", "speed 3.000 is not slow"), ("car2", "pace", "speed 9.500 is not pace Range(6.75, 7.75) m/s")]
    assert certify(Z3Backend(SynthConfig()), program, faster) == ["car1", "car2"]


def test_the_toy_part_in_scenic_and_in_the_samplers_draws(pace):
    scene = scene_of([(0.0, 10.0, 0.0, 1.0), (5.0, 10.0, 0.0, 7.25)])
    program = synthesize(scene).program
    text = render_scenic(program, scene, SynthConfig())
    assert "with speed Range(0, 2), with name 'car1'" in text
    assert "with speed Range(6.75, 7.75), with name 'car2'" in text
    from pipeline.variants.render import references

    assert [(m.entity, m.kind) for m in references(program)[1]] == [("car1", "stationary"), ("car2", "absolute_speed")]
    params = parameterise(program, scene, SynthConfig())
    speeds = [row[-1] for row in params.draws[1:]]
    assert [(d.writes, d.lo, d.hi) for d in speeds] == [(SPEED, (0.0,), (2.0,)), (SPEED, (6.75,), (7.75,))]
    poses, values = params.start(scene)
    assert [p.speed for p in poses[1:]] == [1.0, 7.25]  # the recorded scene, read back as parameters
    rng = random.Random(0)
    for _ in range(50):  # every draw in the box evaluates to a speed the clause holds for
        k = rng.randrange(1, 3)
        draw = speeds[k - 1]
        p = [draw.lo[0] + (draw.hi[0] - draw.lo[0]) * rng.random()]
        params.evaluate_into(k, values[k][:-1] + [p], poses)
        moved = scene_of([(0.0, 10.0, 0.0, poses[1].speed), (5.0, 10.0, 0.0, poses[2].speed)])
        assert check(program, moved).ok


def test_the_clause_kind_recipe(cruising):
    text = "car1 = new Car ahead of ego by Range(5, 10), facing away from ego, cruising\n"
    program = parse_program(text)
    clause = program.statements[0].pace
    assert (type(clause).__name__, str(program), clause.kind, clause.cost) == ("Cruising", text, "cruising", 0)
    assert "cruising" in cruising.PART.kinds
    for speed, holds in ((9.99, False), (10.0, True), (12.5, True), (15.0, True), (15.01, False)):
        scene = scene_of([(0.0, 8.0, 0.0, speed)])
        assert check(program, scene).ok is holds
        assert (certify(Z3Backend(SynthConfig()), program, scene) == []) is holds
    scene = scene_of([(0.0, 8.0, 0.0, 12.5)])
    assert "with speed Range(10, 15), with name 'car1'" in render_scenic(program, scene, SynthConfig())
    draw = parameterise(program, scene, SynthConfig()).draws[1][-1]
    assert (draw.writes, draw.lo, draw.hi) == (SPEED, (10.0,), (15.0,))


def test_r2s_query_decides_a_registered_clause_kind_exactly(pace, tmp_path):
    # A clause kind without a SQL condition of its own (pipeline.query.sql) goes to the exact check; the matches
    # are those of the brute force, which asks r2s check's semantics of every tuple.
    from frames.rows import scene_to_rows, write_frames
    from pipeline.query.mining import query_frames
    from synth.patterns.one_frame import parse_pattern
    from tests.support.query_bruteforce import brute_matches

    rng = random.Random(3)
    scenes = [scene_of([(rng.uniform(-30, 30), rng.uniform(-30, 30), rng.uniform(0, 360),
                         rng.choice([0.5, 2.0, 3.0, 9.0])) for _ in range(rng.randrange(1, 6))])
              for _ in range(12)]
    scenes = [Scene(f"toy/{k}", s.entities) for k, s in enumerate(scenes)]
    frames = tmp_path / "frames.parquet"
    write_frames([r for s in scenes for r in scene_to_rows(s, source="test", scene_name="toy")], frames)
    text = "a = new Car on Range(-40, 40) @ Range(-40, 40), facing Range(0, 360) deg, slow\n"
    pattern = parse_pattern(text)
    out = tmp_path / "matches.parquet"
    query_frames(frames, pattern, out, all_bindings=True, log=lambda s: None)
    import pyarrow.parquet as pq

    got = {}
    for row in pq.read_table(out).to_pylist():
        got.setdefault(row["frame_id"], []).append((row["binding"]["a"],))
    expected = {s.frame_id: b for s in scenes if (b := brute_matches(pattern, s))}
    assert got == expected and len(expected) >= 3
