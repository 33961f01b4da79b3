"""Motion (--motion): the third statement part keeps every guarantee of the other two.

Every strategy finds the optimum that the independent subset DP computes from speeds alone; every oracle agrees
and certifies; printed programs parse back and contain their scene (synth.semantics); c(e, E) depends only on the
declared set and only falls as it grows; robust programs contain every scene within the speed error; a frame
without speeds is refused naming the entity; the config hash does not move without motion.
"""

from __future__ import annotations

import json
import random
from dataclasses import replace

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from synth.config import STRATEGIES, ConfigError, SynthConfig, parse_uncertainty
from synth.driver import SpeedMissing
from synth.dsl import AbsoluteSpeed, MovingLike, RelativeSpeed, Stationary, parse_program
from synth.oracle import make_oracle
from synth.parts import MOTION
from synth.parts.motion import LIKE, STATIONARY
from synth.scene import Scene, SceneError, scene_from_dict
from synth.search.costs import CostModel
from synth.semantics import check
from synth.synthesize import synthesize
from synth.tables import NONE
from tests.support import assert_one_line_error, run_r2s, shipped_frames
from tests.support.bruteforce import FREE, motion_witnesses, optimal_cost, random_scene_dict

MOTION_ON = SynthConfig(motion=True)
# Strategies without CPA are O(N!): cross-checked on scenes they finish quickly.
MAX_N = {"bfs": 6, "dfs": 6, "dfs-bnb": 7, "astar": 7, "monolithic": 6}


def with_speeds(scene: Scene, rng: random.Random) -> Scene:
    from tests.support.bruteforce import random_speed

    return Scene(scene.frame_id, tuple(replace(e, speed=random_speed(rng)) for e in scene.entities))


def assert_optimal_contained(result, scene: Scene, expected: int) -> None:
    assert (result.cost, result.status, result.lower_bound) == (expected, "optimal", expected), str(result.program)
    text = str(result.program)
    parsed = parse_program(text)
    assert parsed == result.program and parsed.cost == result.cost
    assert all(s.motion is not None for s in parsed.statements)  # exactly one MOTION clause per statement
    verdict = check(parsed, scene, result.config)
    assert verdict.ok, [str(v) for v in verdict.violations]


# ---------------------------------------------------------------------------------------------- the optimum


@settings(max_examples=30)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 6))
def test_every_strategy_matches_the_brute_force_with_motion(seed, n):
    scene = scene_from_dict(random_scene_dict(random.Random(seed), n, speeds=True))
    expected = optimal_cost(scene, MOTION_ON)
    assert expected >= optimal_cost(scene)  # a motion program without its motion clauses is a static one
    for strategy in STRATEGIES:
        if n > MAX_N.get(strategy, 99):
            continue
        result = synthesize(scene, MOTION_ON.with_(strategy=strategy, oracle="closed-form"))
        assert_optimal_contained(result, scene, expected)


@settings(max_examples=30)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(7, 12))
def test_auto_on_larger_scenes_matches_the_brute_force_with_motion(seed, n):
    scene = scene_from_dict(random_scene_dict(random.Random(seed), n, speeds=True))
    assert_optimal_contained(synthesize(scene, MOTION_ON.with_(oracle="closed-form")), scene,
                             optimal_cost(scene, MOTION_ON))


REAL = [s for s in shipped_frames() if len(s.others) <= 11][:6]


@pytest.mark.parametrize("oracle", ["hybrid", "smt", "closed-form"])
def test_oracles_agree_certify_and_match_the_brute_force(oracle):
    rng = random.Random(16)
    for scene in REAL:
        scene = with_speeds(scene, rng)
        result = synthesize(scene, MOTION_ON.with_(oracle=oracle))
        assert_optimal_contained(result, scene, optimal_cost(scene, MOTION_ON))
        assert result.certified == (oracle != "closed-form")


def test_motion_tables_of_all_oracles_are_equal_and_match_the_definition():
    rng = random.Random(3)
    for scene in REAL[:4]:
        scene = with_speeds(scene, rng)
        tables = [make_oracle(scene, MOTION_ON.with_(oracle=o)).full_table()["motion"]
                  for o in ("hybrid", "smt", "closed-form")]
        assert (tables[0] == tables[1]).all() and (tables[0] == tables[2]).all()
        witnesses = motion_witnesses(scene, MOTION_ON)
        for e in range(len(scene.others)):
            row0 = tables[0][0, e + 1]
            assert (row0 == STATIONARY) == (FREE in witnesses[e])
            assert (row0 == LIKE) == (FREE not in witnesses[e] and -1 in witnesses[e])
            for r in range(len(scene.others)):
                assert (tables[0][r + 1, e + 1] == LIKE) == (r in witnesses[e] and r != e)


@settings(max_examples=40)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(2, 9))
def test_declaring_costs_depend_on_the_set_and_only_fall_as_it_grows(seed, n):
    rng = random.Random(seed)
    scene = scene_from_dict(random_scene_dict(rng, n, speeds=True))
    cost_model = CostModel(make_oracle(scene, MOTION_ON.with_(oracle="closed-form")))
    lazy = CostModel(make_oracle(scene, MOTION_ON.with_(oracle="smt")))  # asks in its own order
    for _ in range(20):
        e = rng.randrange(n)
        small = sum(1 << r for r in range(n) if r != e and rng.random() < 0.4)
        big = small | sum(1 << r for r in range(n) if r != e and rng.random() < 0.5)
        assert cost_model.delta(e, small) >= cost_model.delta(e, big) >= cost_model.floors()[e]
        assert lazy.delta(e, big) == cost_model.delta(e, big) and lazy.delta(e, small) == cost_model.delta(e, small)
        assert 0 <= cost_model.delta(e, small) <= 3


def test_declaring_a_moving_car_first_lets_others_move_like_it():
    # A platoon at 13 m/s behind a slow ego: no one is like ego, the first of the platoon pays 1 (relative to
    # ego) and every other one rides on it for free; the parked car is stationary.
    ents = [{"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0, "speed": 3.0},
            {"id": "car1", "type": "Car", "x": 3.5, "y": 10, "heading": 0, "speed": 13.0},
            {"id": "car2", "type": "Car", "x": 3.5, "y": 20, "heading": 0, "speed": 13.6},
            {"id": "car3", "type": "Car", "x": 3.5, "y": 30, "heading": 0, "speed": 12.9},
            {"id": "car4", "type": "Car", "x": -3.5, "y": 15, "heading": 0, "speed": 0.1}]
    scene = scene_from_dict({"frame_id": "platoon", "entities": ents})
    result = synthesize(scene, MOTION_ON)
    motions = {s.id: s.motion for s in result.program.statements}
    assert motions["car4"] == Stationary()
    assert sum(isinstance(m, RelativeSpeed) for m in motions.values()) == 1
    assert sum(isinstance(m, MovingLike) for m in motions.values()) == 2
    static = synthesize(scene)
    assert result.cost == static.cost + 1 == optimal_cost(scene, MOTION_ON)


# ---------------------------------------------------------------------------------------------- Ranges


def test_speed_ranges_are_centred_and_rounded_like_the_others():
    scene = scene_from_dict({"frame_id": "r", "entities": [
        {"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0, "speed": 8.0},
        {"id": "car1", "type": "Car", "x": 0, "y": 10, "heading": 0, "speed": 12.337},
        {"id": "car2", "type": "Car", "x": 0, "y": 20, "heading": 0, "speed": 2.004}]})
    by = {s.id: s.motion for s in synthesize(scene, MOTION_ON).program.statements}
    # 4.337 +- 1, lower bound rounded to cents: Range(3.34, 5.34); -5.996 +- 1: Range(-7, -5).
    assert by["car1"] == RelativeSpeed(type(by["car1"].speed)(3.34, 5.34), "ego")
    assert by["car2"] == RelativeSpeed(type(by["car2"].speed)(-7.0, -5.0), "ego")
    for oracle in ("smt", "closed-form"):
        assert {s.id: s.motion for s in synthesize(scene, MOTION_ON.with_(oracle=oracle)).program.statements} == by


def test_stationary_and_like_edges_are_exact():
    base = [{"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0, "speed": 10.0}]
    for speed, expected in ((0.5, Stationary()), (0.5000000000000001, None), (9.0, MovingLike("ego")),
                            (8.999999999999998, None), (11.0, MovingLike("ego"))):
        scene = scene_from_dict({"frame_id": "e", "entities": base + [
            {"id": "car1", "type": "Car", "x": 0, "y": 10, "heading": 0, "speed": speed}]})
        for oracle in ("hybrid", "smt", "closed-form"):
            got = synthesize(scene, MOTION_ON.with_(oracle=oracle)).program.statements[0].motion
            assert (got == expected) if expected else isinstance(got, RelativeSpeed), (speed, oracle, got)


# ---------------------------------------------------------------------------------------------- robust


def perturbed_speeds(scene: Scene, config: SynthConfig, rng: random.Random) -> Scene:
    from synth.perturbation import bounds_of

    out = []
    for e in scene.entities:
        sigma = bounds_of(e, config).speed
        v = rng.choice((e.speed - sigma, e.speed + sigma, rng.uniform(e.speed - sigma, e.speed + sigma)))
        out.append(replace(e, speed=max(0.0, v)))
    return Scene(scene.frame_id, tuple(out))


@settings(max_examples=25)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 6), sigma=st.sampled_from([0.1, 0.25, 0.5, 1.0]))
def test_robust_motion_programs_contain_every_speed_within_the_error(seed, n, sigma):
    rng = random.Random(seed)
    scene = scene_from_dict(random_scene_dict(rng, n, speeds=True))
    config = MOTION_ON.with_(speed_uncertainty=sigma)
    result = synthesize(scene, config)
    assert result.certified and result.cost >= synthesize(scene, MOTION_ON).cost
    assert "0 deg, " in result.scenic.splitlines()[0]  # the header names the speed bound
    for _ in range(40):
        variant = perturbed_speeds(scene, config, rng)
        assert check(result.program, variant, config).ok, str(result.program)


def test_robust_motion_certificate_refutes_a_plain_program():
    rng = random.Random(5)
    scene = with_speeds(REAL[0], rng)
    plain = synthesize(scene, MOTION_ON).program
    from synth.smt import Z3Backend
    from synth.smt.certify import certify

    assert certify(Z3Backend(MOTION_ON.with_(speed_uncertainty=5.0)), plain, scene)


def test_zero_speed_uncertainty_is_byte_identical():
    rng = random.Random(9)
    for scene in REAL[:3]:
        scene = with_speeds(scene, rng)
        a = synthesize(scene, MOTION_ON)
        b = synthesize(scene, MOTION_ON.with_(speed_uncertainty=0.0))
        assert (str(a.program), a.scenic) == (str(b.program), b.scenic)


# ---------------------------------------------------------------------------------------------- semantics


def test_the_checker_reads_motion_literally():
    scene = scene_from_dict({"frame_id": "s", "entities": [
        {"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0, "speed": 5.0},
        {"id": "car1", "type": "Car", "x": 0, "y": 10, "heading": 0, "speed": 0.4},
        {"id": "car2", "type": "Car", "x": 0, "y": 20, "heading": 0, "speed": 6.0}]})
    pos = "ahead of ego by Range(7.5, 12.5), facing Range(-2.5, 2.5) deg"
    pos2 = "ahead of ego by Range(17.5, 22.5), facing Range(-2.5, 2.5) deg"

    def verdict(m1: str, m2: str, config: SynthConfig = MOTION_ON):
        program = parse_program(f"car1 = new Car {pos}, {m1}\ncar2 = new Car {pos2}, {m2}\n")
        return sorted((v.entity, v.part) for v in check(program, scene, config).violations)

    assert verdict("stationary", "moving like ego") == []
    assert verdict("stationary", "moving Range(0.5, 1.5) m/s relative to ego") == []
    assert verdict("moving Range(0, 0.5) m/s", "moving Range(5, 7) m/s") == []
    assert verdict("moving like ego", "moving like car1") == [("car1", "motion"), ("car2", "motion")]
    assert verdict("stationary", "moving Range(1.01, 3) m/s relative to ego") == [("car2", "motion")]
    assert verdict("stationary", "moving like ego", MOTION_ON.with_(v_stop=0.3)) == [("car1", "motion")]
    assert verdict("stationary", "moving like ego", MOTION_ON.with_(dv=0.99)) == [("car2", "motion")]
    # No speed, no motion: a motion clause about an entity whose speed is unknown does not hold.
    blind = Scene(scene.frame_id, tuple(replace(e, speed=None) if e.id == "car1" else e for e in scene.entities))
    program = parse_program(f"car1 = new Car {pos}, stationary\ncar2 = new Car {pos2}\n")
    assert [str(v) for v in check(program, blind, MOTION_ON).violations] == ["car1: motion: no speed is not stationary"]


# ---------------------------------------------------------------------------------------------- inputs


def test_a_scene_without_speeds_is_refused_naming_the_entity(tmp_path):
    scene = REAL[0]
    with pytest.raises(SpeedMissing, match="'ego'"):
        synthesize(scene, MOTION_ON)
    rng = random.Random(1)
    partial = Scene(scene.frame_id, tuple(replace(e, speed=None if e.id == scene.others[2].id else rng.uniform(0, 9))
                                          for e in scene.entities))
    with pytest.raises(SpeedMissing, match=repr(scene.others[2].id)):
        synthesize(partial, MOTION_ON)
    path = tmp_path / "scene.json"
    path.write_text(partial.to_json())
    proc = run_r2s("synth", str(path), "--motion")
    assert_one_line_error(proc, 2, f"entity {scene.others[2].id!r} has no speed")
    assert run_r2s("synth", str(path)).returncode == 0  # static synthesis does not need speeds


@pytest.mark.parametrize("bad", [-0.1, float("inf"), "fast", 1e6])
def test_bad_speeds_are_refused(bad):
    doc = {"frame_id": "b", "entities": [{"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0, "speed": bad}]}
    with pytest.raises(SceneError, match="speed"):
        scene_from_dict(doc)


def test_speed_round_trips_through_scene_json_and_frames(tmp_path):
    from frames.rows import iter_scenes, read_frames, scene_to_rows, write_frames

    scene = with_speeds(REAL[1], random.Random(2))
    scene = Scene(scene.frame_id, tuple(replace(e, speed=None) if e.id == scene.others[0].id else e
                                        for e in scene.entities))
    assert scene_from_dict(json.loads(scene.to_json())) == scene
    assert "speed" not in json.loads(scene.to_json())["entities"][1]  # unknown: no key
    write_frames(scene_to_rows(scene), tmp_path / "f.parquet")
    import pyarrow.parquet as pq

    assert pq.ParquetFile(tmp_path / "f.parquet").schema_arrow.field("speed").type == "double"
    (back,) = list(iter_scenes(read_frames(tmp_path / "f.parquet")))
    assert [(e.id, e.speed) for e in back.entities] == [(e.id, e.speed) for e in scene.entities]


def test_config_keys_hash_and_uncertainty():
    base = SynthConfig().semantic_hash()
    assert base == "c391acc5cc2599fb"  # unchanged: motion off leaves the hash of every earlier run
    assert SynthConfig(v_stop=0.3, dv=2.0, c_speed=4.0).semantic_hash() == base  # irrelevant without motion
    on = MOTION_ON.semantic_hash()
    assert on != base and MOTION_ON.with_(v_stop=0.3).semantic_hash() != on
    assert MOTION_ON.with_(speed_uncertainty=0.0).semantic_hash() == on
    assert parse_uncertainty("0.5,2,0.3") == (0.5, 2.0, 0.3)
    assert parse_uncertainty("0.5,2") == (0.5, 2.0)
    for bad in ("1,2,-1", "1,2,3,4", "1,2,nan", "1,2,100"):
        with pytest.raises(ConfigError):
            parse_uncertainty(bad)
    with pytest.raises(ConfigError, match="motion"):
        SynthConfig(speed_uncertainty=0.5)
    for key, bad in (("v_stop", -1.0), ("dv", float("nan")), ("c_speed", 0.0), ("motion", "yes")):
        with pytest.raises(ConfigError, match=key):
            SynthConfig(**{key: bad})


def test_cli_motion_and_uncertainty(tmp_path):
    scene = with_speeds(REAL[2], random.Random(4))
    path = tmp_path / "scene.json"
    path.write_text(scene.to_json())
    proc = run_r2s("synth", str(path), "--motion", "--format", "json")
    assert proc.returncode == 0, proc.stderr
    doc = json.loads(proc.stdout)
    assert doc["certified"] and doc["cost"] == optimal_cost(scene, MOTION_ON)
    assert all(line.count(", ") >= 2 for line in doc["program"].splitlines())
    robust = run_r2s("synth", str(path), "--motion", "--uncertainty", "0.2,1,0.4", "--format", "json")
    assert robust.returncode == 0 and "0.4 m/s" in json.loads(robust.stdout)["scenic"].splitlines()[0]
    assert_one_line_error(run_r2s("synth", str(path), "--uncertainty", "0.2,1,0.4"), 2, "motion")
    config = tmp_path / "motion.toml"
    config.write_text("[synth]\nmotion = true\nv_stop = 0.3\n")
    proc = run_r2s("synth", str(path), "--config", str(config))
    assert proc.returncode == 0 and proc.stdout == str(synthesize(scene, MOTION_ON.with_(v_stop=0.3)).program)


def test_motion_clause_kinds_print_and_cost():
    p = parse_program(
        "a = new Car ahead of ego by Range(0, 5), facing toward ego, stationary\n"
        "b = new Car behind a by Range(0, 5), facing toward ego, moving like a\n"
        "c = new Car behind b by Range(0, 5), facing toward ego, moving Range(-1, 1) m/s relative to b\n"
        "d = new Car behind c by Range(0, 5), facing toward ego, moving Range(3, 5) m/s\n"
        "e = new Car behind d by Range(0, 5), facing toward ego\n")
    assert [s.cost for s in p.statements] == [0, 0, 1, 2, 0]
    assert [s.motion.kind for s in p.statements[:4]] == list(MOTION.kinds)
    assert isinstance(p.statements[3].motion, AbsoluteSpeed) and p.statements[4].motion is None
    assert str(p) == str(parse_program(str(p)))


def test_table_codes_record_stationary_in_egos_row():
    scene = scene_from_dict({"frame_id": "t", "entities": [
        {"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0, "speed": 0.0},
        {"id": "car1", "type": "Car", "x": 0, "y": 10, "heading": 0, "speed": 0.2},
        {"id": "car2", "type": "Car", "x": 0, "y": 20, "heading": 0, "speed": 0.9}]})
    t = make_oracle(scene, MOTION_ON).full_table()["motion"]
    assert (t[0, 1], t[0, 2]) == (STATIONARY, LIKE)  # car2 is not stationary but moves like (parked) ego
    assert (t[1, 2], t[2, 1], t[1, 1]) == (LIKE, LIKE, NONE)


def test_r2s_run_with_motion_and_a_frame_lacking_a_speed(tmp_path):
    import pandas as pd

    from frames.rows import scene_to_rows, write_frames

    rng = random.Random(12)
    scenes = [with_speeds(s, rng) for s in REAL[:3]]
    blind = scenes[1].others[1].id
    scenes[1] = Scene(scenes[1].frame_id, tuple(replace(e, speed=None) if e.id == blind else e
                                                for e in scenes[1].entities))
    rows = [r for k, s in enumerate(scenes) for r in scene_to_rows(s, frame_index=k)]
    write_frames(pd.DataFrame(rows), tmp_path / "frames.parquet")
    out = tmp_path / "programs.parquet"
    proc = run_r2s("run", str(tmp_path / "frames.parquet"), "--out", str(out), "--motion", "--jobs", "1")
    assert proc.returncode == 0, proc.stderr
    df = pd.read_parquet(out).set_index("frame_id")
    bad = df.loc[scenes[1].frame_id]
    assert bad["status"] == "error" and f"entity {blind!r} has no speed" in bad["error"]
    for s in (scenes[0], scenes[2]):
        row = df.loc[s.frame_id]
        assert row["status"] == "optimal" and row["certified"] and row["cost"] == optimal_cost(s, MOTION_ON)
        assert check(parse_program(row["program"]), s, MOTION_ON).ok
        assert row["config_hash"] == MOTION_ON.semantic_hash()
