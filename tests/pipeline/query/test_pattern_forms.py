"""Patterns that say what people mean (docs/dsl.md#patterns): a statement may leave out its position or heading
(any), a position may be a distance alone (`within Range(a, b) of REF`), and an `ego ...` line constrains ego's
motion. The DuckDB engine against the independent brute force (tests/support/query_bruteforce.py) on real frames
and at the boundaries, and the documented equivalences of what a left-out clause means."""

from __future__ import annotations

import math
import random
from pathlib import Path

import pyarrow.parquet as pq
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from frames.rows import iter_scenes, read_frames, scene_to_rows, write_frames
from synth.config import SynthConfig
from synth.dsl import DslError
from synth.patterns.one_frame import matches, parse_pattern
from synth.scene import Entity, Scene
from tests.support import ROOT, assert_one_line_error, run_r2s
from tests.support.query_bruteforce import brute_by_frame

KEYFRAMES = ROOT / "data" / "nuscenes-mini-keyframes" / "frames.parquet"
AV2 = ROOT / "data" / "argoverse2-log-excerpt" / "frames.parquet"  # 10 Hz, with speeds

STATIC = [
    "ped = new Pedestrian within Range(0, 10) of ego\n",
    "ped = new Pedestrian ahead of ego by Range(0, 12)\n",  # no heading: any
    "car = new Vehicle facing toward ego\n",  # no position: anywhere
    "car = new Vehicle, facing away from ego\nped = new Pedestrian within Range(0, 6) of car\n",
    "p = new Pedestrian\nq = new Pedestrian within Range(0, 1.5) of p, facing Range(-30, 30) deg relative to p\n",
    "cone = new TrafficCone\nbar = new Barrier within Range(0.5, 2) of cone\n",
]
MOTION = [
    "car = new Vehicle within Range(0, 25) of ego\nego stationary\n",
    "car = new Vehicle ahead of ego by Range(0, 40)\nego moving like car\n",
    "car = new Vehicle behind ego by Range(0, 40), moving Range(0.5, 20) m/s\nego moving Range(2, 5) m/s\n",
    "thing = new Object within Range(0, 15) of ego, stationary\nego moving Range(1, 3) m/s relative to thing\n",
]


def brute(scenes, text: str, config: SynthConfig | None = None):
    return brute_by_frame(scenes, parse_pattern(text), config)


def engine(frames, text: str, tmp_path: Path, config: SynthConfig | None = None):
    """{frame_id: [binding, ...]} by the engine (`pipeline.query.query`, one row per binding), and how many
    candidates went to the exact check."""
    from pipeline.query.mining import query_frames

    pattern = parse_pattern(text)
    out = tmp_path / "m.parquet"
    summary = query_frames(frames, pattern, out, all_bindings=True, config=config, log=lambda _: None)
    got: dict[str, list[tuple[str, ...]]] = {}
    for row in pq.read_table(out).to_pylist():
        got.setdefault(row["frame_id"], []).append(tuple(row["binding"][n] for n in pattern.names))
    return got, summary


@pytest.fixture(scope="module")
def keyframes():
    return list(iter_scenes(read_frames(KEYFRAMES)))


@pytest.fixture(scope="module")
def av2():
    return list(iter_scenes(read_frames(AV2)))


@pytest.mark.parametrize("text", STATIC)
def test_left_out_clauses_and_within_on_real_frames(text, keyframes, tmp_path):
    got, summary = engine(KEYFRAMES, text, tmp_path)
    want = brute(keyframes, text)
    assert got == want and want, "same frames, same bindings, same order; a pattern matching nothing tests nothing"
    assert summary.bindings == sum(map(len, want.values()))
    pattern = parse_pattern(text)
    for s in keyframes[:60]:  # the definition's own matcher agrees, order included
        assert [tuple(b.values()) for b in matches(pattern, s)] == want.get(s.frame_id, [])


@pytest.mark.parametrize("text", MOTION)
def test_ego_lines_on_real_frames_with_speeds(text, av2, tmp_path):
    got, _ = engine(AV2, text, tmp_path)
    want = brute(av2, text)
    assert got == want and want
    # the ego line is a real constraint: without it, more frames match
    without = "".join(line + "\n" for line in text.splitlines() if not line.startswith("ego "))
    assert len(brute(av2, without)) > len(want)


def test_a_left_out_clause_means_any_as_the_docs_say(keyframes, tmp_path):
    """Leaving out the heading is `facing Range(0, 360) deg`; leaving out the position is anywhere (the frames'
    coordinates are bounded by 1e6 m); the engine's answers are the same."""
    pairs = [("p = new Pedestrian ahead of ego by Range(0, 12)\n",
              "p = new Pedestrian ahead of ego by Range(0, 12), facing Range(0, 360) deg\n"),
             ("c = new Vehicle facing toward ego\n",
              "c = new Vehicle on Range(-1e7, 1e7) @ Range(-1e7, 1e7), facing toward ego\n"),
             ("c = new Car\n", "c = new Car on Range(-1e7, 1e7) @ Range(-1e7, 1e7), facing Range(0, 360) deg\n")]
    for short, spelled in pairs:
        assert engine(KEYFRAMES, short, tmp_path)[0] == engine(KEYFRAMES, spelled, tmp_path)[0]


def test_any_heading_needs_no_exact_check(keyframes, tmp_path):
    """`facing Range(0, 360) deg` holds for every heading (as in the semantics): the engine knows it without the
    exact check in Python, which over 10^6 frames was most of a query's time (a wild entity is still checked:
    test_query's test_wild_magnitudes_are_decided_by_the_checker)."""
    for text in ("c = new Car on Range(-50, 50) @ Range(-50, 50), facing Range(0, 360) deg\n",
                 "c = new Car\nd = new Car ahead of c by Range(1, 10), facing Range(-180, 180) deg relative to c\n"):
        got, summary = engine(KEYFRAMES, text, tmp_path)
        assert got == brute(keyframes, text) and got
        assert summary.checked_exactly == 0


def _write(scenes, path: Path) -> Path:
    write_frames([r for s in scenes for r in scene_to_rows(s, source="test", scene_name=s.frame_id.split("/")[0])],
                 path)
    return path


DELTAS = (-1e-4, -1e-6, -1e-7, -2e-9, -1e-9, -5e-10, 0.0, 5e-10, 1e-9, 2e-9, 1e-7, 1e-6, 1e-4)


@settings(max_examples=8, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), lo=st.sampled_from([0.0, 0.5, 3.0]), hi=st.sampled_from([3.5, 7.25, 40.0]),
       to_ego=st.booleans())
def test_within_at_its_boundaries(seed, lo, hi, to_ego, tmp_path_factory):
    """Distances within 1e-9 .. 1e-4 m of both bounds, either side, to ego or to a name: the engine decides exactly
    as the checker (the band is sent to the exact check)."""
    g = random.Random(seed)
    tmp = tmp_path_factory.mktemp("within")
    ref = "ego" if to_ego else "r"
    text = ("" if to_ego else "r = new Truck\n") + f"a = new Car within Range({lo}, {hi}) of {ref}\n"
    scenes = []
    for i in range(120):
        ego = Entity("ego", "Car", g.uniform(-5, 5), g.uniform(-5, 5), g.uniform(0, 360))
        r = ego if to_ego else Entity("truck1", "Truck", g.uniform(-20, 20), g.uniform(-20, 20), g.uniform(0, 360))
        d = max(0.0, g.choice([lo, hi]) + g.choice(DELTAS))
        b = math.radians(g.uniform(0, 360))
        a = Entity("car1", "Car", r.x - d * math.sin(b), r.y + d * math.cos(b), g.uniform(0, 360))
        other = Entity("car2", "Car", r.x + g.uniform(-9, 9), r.y + g.uniform(-9, 9), 0.0)
        scenes.append(Scene(f"w{seed}/{i}", tuple([ego, *([] if to_ego else [r]), a, other])))
    got, summary = engine(_write(scenes, tmp / "f.parquet"), text, tmp)
    assert got == brute(scenes, text)
    assert summary.checked_exactly > 0


@settings(max_examples=8, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), form=st.sampled_from(["stationary", "moving like a",
                                                              "moving Range(2, 4.5) m/s",
                                                              "moving Range(-1, 1.5) m/s relative to a"]))
def test_the_ego_line_at_its_boundaries(seed, form, tmp_path_factory):
    """Ego's speed within 1e-9 .. 1e-4 m/s of each bound of its clause (v_stop, dv, the Ranges)."""
    g = random.Random(seed)
    tmp = tmp_path_factory.mktemp("ego")
    config = SynthConfig(v_stop=0.5, dv=1.0)
    text = f"a = new Car within Range(0, 30) of ego\nego {form}\n"
    scenes = []
    for i in range(120):
        sa = g.uniform(0, 10)
        bound = {"stationary": [0.5], "moving like a": [sa - 1.0, sa + 1.0], "moving Range(2, 4.5) m/s": [2.0, 4.5],
                 "moving Range(-1, 1.5) m/s relative to a": [sa - 1.0, sa + 1.5]}[form]
        se = max(0.0, g.choice(bound) + g.choice(DELTAS))
        ego = Entity("ego", "Car", 0.0, 0.0, g.uniform(0, 360), speed=se)
        a = Entity("car1", "Car", g.uniform(-20, 20), g.uniform(-20, 20), 0.0, speed=sa)
        scenes.append(Scene(f"e{seed}/{i}", (ego, a)))
    got, _ = engine(_write(scenes, tmp / "f.parquet"), text, tmp, config=config)
    want = brute(scenes, text, config)
    assert got == want and 0 < len(want) < len(scenes)


@pytest.mark.parametrize("text,words", [
    ("ego stationary\n", "declares no name"),
    ("a = new Car\nego = new Car\n", "never declared"),
    ("a = new Car\nego stationary\nego moving like a\n", "constrained twice"),
    ("ego moving like a\na = new Car\n", "neither ego nor declared earlier"),
    ("a = new Car facing toward ego, ahead of ego by Range(0, 1)\n", "in this order"),
    ("a = new Car within Range(5, 1) of ego\n", "is empty"),
    ("a = new Car\nego ahead of a by Range(0, 1)\n", "expected a clause of ego"),
])
def test_bad_pattern_forms_are_one_line_exit_2(text, words, tmp_path):
    with pytest.raises(DslError, match=words):
        parse_pattern(text)
    (tmp_path / "p.dsl").write_text(text)
    proc = run_r2s("query", str(KEYFRAMES), str(tmp_path / "p.dsl"), "--out", str(tmp_path / "m.parquet"))
    assert_one_line_error(proc, contains=words)
    assert not (tmp_path / "m.parquet").exists()


@pytest.mark.parametrize("text", STATIC + MOTION)
def test_patterns_print_back_to_themselves(text):
    pattern = parse_pattern(text)
    assert parse_pattern(str(pattern)) == pattern
