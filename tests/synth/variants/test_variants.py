"""Variants: the program's parameters (synth.variants.parameters), the collision rule, and the chain of synth.variants.gibbs.

What the chain must give: every variant inside its program (the semantics checker) and no overlap between two
boxes that do not overlap in the recording (shapely, as Scenic tests it), for real frames of every size; the
distribution Scenic's own rejection sampler gives (two-sample Kolmogorov-Smirnov tests on every parameter and
every pairwise distance, with negative controls that show the tests' power); determinism.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

from pipeline.variants.render import Footprint, ego_frame
from synth.config import SynthConfig
from synth.dsl import parse_program
from synth.geometry import angular_difference
from synth.parts.position import SectorDraws
from synth.scene import scene_from_dict
from synth.semantics import check
from synth.synthesize import synthesize
from synth.variants.gibbs import Chain, ChainSettings, NoVariant, autocorrelation_time, sample_variants
from synth.variants.overlap import boxes_overlap, scene_overlaps
from synth.variants.parameters import Pose, inside, parameterise
from tests.support import all_relation_kinds, assert_one_line_error, every_motion_clause, run_r2s
from tests.support.distribution import ALPHA, N_DRAWS, TIGHT, TIGHT_PROGRAM, compare, ks_critical, scenic_draws

shapely = pytest.importorskip("shapely.geometry", reason="shapely (a dependency of scenic) is not installed")


def overlapping(scene) -> set[frozenset[str]]:
    """Pairs of ids whose boxes meet, by shapely: Scenic's `intersects` for planar boxes."""
    boxes = list(ego_frame(scene).values())
    polys = {b.id: shapely.Polygon(b.corners()) for b in boxes}
    return {frozenset((a, b)) for a, b in itertools.combinations(polys, 2) if polys[a].intersects(polys[b])}


# ------------------------------------------------------------------------------------------ boxes

box = st.tuples(st.floats(-6, 6), st.floats(-6, 6), st.floats(0, 360), st.floats(0.2, 8), st.floats(0.2, 3))


@given(box, box)
def test_separating_axes_agree_with_shapely(a, b):
    pa, pb = (shapely.Polygon(Footprint("a", "Car", *v).corners()) for v in (a, b))
    assume(pa.distance(pb) > 1e-7 or pa.intersection(pb).area > 1e-7)  # not a float tie at the boundary
    assert bool(boxes_overlap(*a, *b)) == pa.intersects(pb) == boxes_overlap(*a, *b, xp=math)


def test_touching_boxes_overlap_as_in_scenic():
    # Scenic's `intersects` is shapely's, closed: boxes sharing an edge meet.
    assert boxes_overlap(0, 0, 0, 4, 2, 2, 0, 0, 4, 2) and not boxes_overlap(0, 0, 0, 4, 2, 2.001, 0, 0, 4, 2)


# ------------------------------------------------------------------------------------------ parameters

KINDS, KINDS_PROGRAM, KINDS_CONFIG = all_relation_kinds()


@pytest.fixture(scope="module")
def programs(real_frames):
    """(scene, program, config) for every shipped frame and the all-kinds program."""
    return [(s, synthesize(s).program, SynthConfig()) for s in real_frames] + [(KINDS, KINDS_PROGRAM, KINDS_CONFIG)]


def test_the_kinds_program_contains_its_scene():
    assert check(KINDS_PROGRAM, KINDS, KINDS_CONFIG).ok, check(KINDS_PROGRAM, KINDS, KINDS_CONFIG).violations


def test_the_start_is_the_recorded_scene(programs):
    # The chain starts at the recording: its parameters read back exactly, inside their boxes.
    for scene, program, config in programs:
        p = parameterise(program, scene, config)
        poses, params = p.start(scene)
        by_id = scene.by_id()
        for name, pose, row, parts in zip(p.ids, poses, params, p.draws):
            e = by_id[name]
            assert math.hypot(pose.x - e.x, pose.y - e.y) < 1e-9, (scene.frame_id, name)
            assert angular_difference(pose.heading, e.heading) < 1e-9, (scene.frame_id, name)
            for part, values in zip(parts, row):
                assert all(lo <= v <= hi for lo, v, hi in zip(part.lo, values, part.hi))


def _draws(chain: Chain, n: int):
    for _ in range(n):
        chain.draw_from_prior()
        yield chain


def test_parts_invert_what_they_evaluate(programs):
    for scene, program, config in programs:
        chain = Chain(program, scene, config, seed=3)
        p = chain.params_of
        for c in _draws(chain, 20):
            poses = [Pose(q.x, q.y, q.heading, q.speed) for q in c.poses]
            for k in range(1, len(p.ids)):
                for part, r, values in zip(p.draws[k], p.refs[k], c.params[k]):
                    back = part.invert(poses[k], None if r is None else poses[r])
                    assert np.allclose(back, values, atol=1e-7), (scene.frame_id, p.ids[k], part)


def _placed(p, params) -> list[Pose]:
    poses = [Pose(p.ego.x, p.ego.y, p.ego.heading, p.ego.speed or 0.0)] + [Pose() for _ in p.ids[1:]]
    for k in range(1, len(p.ids)):
        p.evaluate_into(k, params[k], poses)
    return poses


def test_a_move_re_places_every_entity_it_changes(programs):
    # What the chain re-evaluates after redrawing one part (Parameterisation.moved_by) against a brute force:
    # every entity placed afresh from all parameters, before and after the redraw.
    rng = np.random.default_rng(0)
    for scene, program, config in programs[::4] + programs[-3:]:
        chain = Chain(program, scene, config, seed=1)
        p = chain.params_of
        before = _placed(p, chain.params)
        for k in range(1, len(p.ids)):
            for j, part in enumerate(p.draws[k]):
                params = [list(row) for row in chain.params]
                params[k][j] = tuple(a + (b - a) * t for a, b, t in zip(part.lo, part.hi, rng.random(len(part.lo))))
                after = _placed(p, params)
                changed = {m for m, (u, v) in enumerate(zip(before, after)) if (u.x, u.y, u.heading) != (v.x, v.y, v.heading)}
                assert changed <= set(chain.moves[k][j].tolist()), (scene.frame_id, p.ids[k], j)


def test_every_draw_is_inside_the_program_and_its_reach(programs):
    # The reach bound is sound (the rule leaves out only pairs that can never meet): every drawn centre lies in its
    # disc, every heading in its arc, and every pair that meets in a draw is either recorded or stated apart.
    for scene, program, config in programs:
        chain = Chain(program, scene, config, seed=5)
        reach = chain.params_of.reaches()
        rule = chain.rule
        stated = {frozenset(p) for p in rule.named(rule.apart + rule.recorded)}
        for c in _draws(chain, 40 if len(scene.others) < 50 else 6):  # shapely's pairs are slow at 141 entities
            drawn = c.scene("draw")
            assert check(program, drawn, config).ok, check(program, drawn, config).violations[:3]
            for q, r in zip(c.poses, reach):
                assert math.hypot(q.x - r.x, q.y - r.y) <= r.r
                assert angular_difference(q.heading, r.heading.mid) <= r.heading.half
            assert overlapping(drawn) <= stated


# ------------------------------------------------------------------------------------------ the chain

def _assert_variants(program, recorded, scenes, config=None):
    allowed = overlapping(recorded)
    for s in scenes:
        result = check(program, s, config)
        assert result.ok, [str(v) for v in result.violations[:3]]
        assert overlapping(s) <= allowed, overlapping(s) - allowed
        assert [e.id for e in s.entities] == ["ego"] + [st.id for st in program.statements]
        by_id = recorded.by_id()
        assert all((e.type, e.length, e.width) == (by_id[e.id].type, *by_id[e.id].dimensions()) for e in s.entities)


@pytest.mark.parametrize("frame", ["scene-0061/0#vehicles", "scene-0553/35#vehicles", "scene-0757/0",
                                   "scene-0796/31", "scene-0061/2", "scene-0061/18"])
def test_variants_are_inside_the_program_and_keep_the_recordings_gaps(real_frames, frame):
    recorded = next(s for s in real_frames if s.frame_id == frame)
    program = synthesize(recorded).program
    # The two crowded frames (56 and 141 entities, barrier rows and pedestrian groups) with a short chain: every
    # state of the chain must satisfy both, whatever the burn-in (the defaults run on all 242 keyframes in
    # bench/bench_variants.py).
    settings = ChainSettings(burn_in=2, thin=2) if len(recorded.others) > 50 else ChainSettings()
    v = sample_variants(program, recorded, SynthConfig(), 5, seed=0, settings=settings)
    assert len(v.scenes) == 5 and v.stats.start_sweeps == 0
    _assert_variants(program, recorded, v.scenes)
    assert len({s.entities[-1].x for s in v.scenes}) == 5  # variants, not copies
    assert overlapping(recorded) == {frozenset(p) for p in scene_overlaps(recorded)}


def test_the_same_seed_gives_the_same_variants_and_variant_k_does_not_depend_on_n(real_frames):
    recorded = next(s for s in real_frames if s.frame_id == "scene-0757/0")
    program = synthesize(recorded).program
    a = sample_variants(program, recorded, SynthConfig(), 4, seed=9).scenes
    b = sample_variants(program, recorded, SynthConfig(), 2, seed=9).scenes
    c = sample_variants(program, recorded, SynthConfig(), 2, seed=10).scenes
    assert [s.to_json() for s in a[:2]] == [s.to_json() for s in b]
    assert a[0].to_json() != c[0].to_json()
    assert [s.frame_id for s in a] == [f"scene-0757/0#sample{k}" for k in range(4)]


def test_without_the_rule_every_draw_is_accepted():
    v = sample_variants(KINDS_PROGRAM, KINDS, KINDS_CONFIG, 3, seed=1, allow_collisions=True)
    assert v.stats.acceptance == 1.0 and v.stats.proposals == v.stats.sweeps * 2 * len(KINDS.others)
    assert all(check(KINDS_PROGRAM, s, KINDS_CONFIG).ok for s in v.scenes)


TWO_CARS = scene_from_dict({"frame_id": "two", "entities": [
    {"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0},
    {"id": "car1", "type": "Car", "x": 0, "y": 9.0, "heading": 0}]})


def _reexpressed_distance_means(seed: int) -> tuple[float, float]:
    """ped2 stays put while re-anchoring moves ped1 (nothing else moves): the mean of ped2's sector distance as the
    chain draws it, and exactly, by weighting uniform draws of ped1 with the Jacobian the move must respect."""
    scene = scene_from_dict({"frame_id": "anchor", "entities": [
        {"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0},
        {"id": "ped1", "type": "Pedestrian", "x": 0, "y": 7, "heading": 0},
        {"id": "ped2", "type": "Pedestrian", "x": -0.6, "y": 7, "heading": 0}]})
    program = parse_program(
        "ped1 = new Pedestrian ahead of ego by Range(5, 10), facing Range(-5, 5) deg relative to ego\n"
        "ped2 = new Pedestrian left of ped1 by Range(0.1, 3), facing Range(-5, 5) deg relative to ego\n")
    chain = Chain(program, scene, SynthConfig(), seed=seed, allow_collisions=True)
    drawn = []
    for i in range(40000):
        chain._reanchor(1, 0)
        if i % 4 == 0:
            drawn.append(chain.params[2][0][0])
    # Exact: ped1 uniform in its box; the pair is valid where ped2's re-expressed parameters are in their box, and
    # ped2's density at its fixed place is 1 / (its distance) there (polar coordinates).
    p, rng = chain.params_of, np.random.default_rng(seed)
    ped2, sector = chain.poses[2], p.draws[2][0]
    weights, values = [], []
    for d, u in zip(rng.uniform(5, 10, 100000), rng.uniform(-10, 10, 100000)):
        poses = [chain.poses[0], Pose(), ped2]
        p.evaluate_into(1, [(d, u), chain.params[1][1]], poses)
        v = sector.invert(ped2, poses[1])
        if inside(sector, v):
            weights.append(1 / v[0])
            values.append(v[0])
    return float(np.mean(drawn)), float(np.average(values, weights=weights))


def test_re_anchoring_weighs_its_jacobian(monkeypatch):
    drawn, exact = _reexpressed_distance_means(seed=3)
    assert abs(drawn - exact) < 0.05  # seeds 1-5 give -0.03 .. +0.02; without the Jacobian it is ~ +0.26
    monkeypatch.setattr(SectorDraws, "area", lambda self, p, ref: 1.0)  # the bug: a re-expression taken as volume-preserving
    drawn, exact_again = _reexpressed_distance_means(seed=3)
    assert drawn - exact > 0.15


def test_a_program_that_always_collides_is_no_variant_naming_the_pair():
    # The program puts car1 within 2 m of ego (it does not contain the recording, where car1 is 9 m ahead): every
    # scene of it overlaps two boxes that are apart in the recording.
    program = parse_program("car1 = new Car ahead of ego by Range(0.5, 2), facing Range(-2.5, 2.5) deg\n")
    with pytest.raises(NoVariant, match="1 pair of boxes .* always collide .ego and car1.") as info:
        sample_variants(program, TWO_CARS, SynthConfig(), 2, seed=0, settings=ChainSettings(start_sweeps=20))
    assert info.value.pairs == (("ego", "car1"),)


def test_a_start_outside_the_program_is_found_by_descent():
    # car1 recorded 9 m ahead, program says 2 to 12 m: the start is clipped, then the chain finds valid states.
    program = parse_program("car1 = new Car ahead of ego by Range(2, 12), facing Range(30, 35) deg\n")
    v = sample_variants(program, TWO_CARS, SynthConfig(), 3, seed=0)
    assert all(check(program, s).ok for s in v.scenes)
    assert not any(overlapping(s) for s in v.scenes)


def test_cli_no_variant_is_exit_4_one_line_nothing_written(tmp_path):
    scene = tmp_path / "s.json"
    scene.write_text(TWO_CARS.to_json())
    program = tmp_path / "p.dsl"
    program.write_text("car1 = new Car ahead of ego by Range(0.5, 2), facing Range(-2.5, 2.5) deg\n")
    out = tmp_path / "out"
    proc = run_r2s("sample", "--program", str(program), "--scene", str(scene), "--n", "2", "--out", str(out))
    assert_one_line_error(proc, 4, contains="always collide (ego and car1)")
    assert not out.exists()
    proc = run_r2s("render", str(scene), "--program", str(program), "--samples", "2", "--out", str(tmp_path / "a.png"))
    assert_one_line_error(proc, 4, contains="always collide")
    help_text = run_r2s("sample", "--help").stdout
    assert "4 sampling failed" in " ".join(help_text.split())


def test_progress_is_logged_when_not_a_terminal(real_frames, capsys):
    from pipeline.variants.sample import ProgressReport, SampleOptions, sample_scenic

    recorded = next(s for s in real_frames if s.frame_id == "scene-0061/2")
    report = ProgressReport("r2s sample", every_s=0.0)
    samples = sample_scenic(synthesize(recorded).scenic, SampleOptions(n=2, thin=3), progress=report)
    report.close()
    lines = capsys.readouterr().err.splitlines()
    assert len(samples.scenes) == 2 and len(lines) == 20 + 3 + 1  # one line per sweep at every_s = 0
    assert lines[-1].startswith("r2s sample: 24/24 (")


# ------------------------------------------------------------------------------------------ same distribution

def test_autocorrelation_time_of_known_processes():
    rng = np.random.default_rng(0)
    assert autocorrelation_time(rng.random(20000)) == pytest.approx(1.0, abs=0.1)
    x = np.zeros(40000)
    for t, e in enumerate(rng.normal(size=40000)[1:], start=1):
        x[t] = 0.8 * x[t - 1] + e
    assert autocorrelation_time(x) == pytest.approx((1 + 0.8) / (1 - 0.8), rel=0.15)  # AR(1): (1 + phi) / (1 - phi)


# Same distribution: tests/support/distribution.py (shared with bench/bench_variants.py) says how, and with what power.
SMALL_FRAMES = ["scene-0103/1#vehicles", "scene-0061/0#vehicles", "scene-0061/7#vehicles"]  # N = 4, 6, 8


@pytest.fixture(scope="module")
def scenic_installed():
    pytest.importorskip("scenic", reason="scenic (3.1.1) is not importable here: the reference sampler is Scenic")


@pytest.fixture(scope="module")
def tight_reference(scenic_installed):
    return scenic_draws(TIGHT_PROGRAM, TIGHT, SynthConfig())[0]


def test_the_ks_tests_have_the_stated_power():
    m = 3 * 8 + 9 * 8 // 2  # the largest frame compared: 8 entities (24 parameters, 36 distances)
    assert ks_critical(N_DRAWS, ALPHA / m) < 0.16


@pytest.mark.parametrize("frame", SMALL_FRAMES)
def test_the_chain_draws_scenics_distribution_on_real_frames(real_frames, scenic_installed, frame):
    recorded = next(s for s in real_frames if s.frame_id == frame)
    program = synthesize(recorded).program
    result = compare(program, recorded, SynthConfig(), scenic_draws(program, recorded, SynthConfig())[0])
    assert result.same, (result.pvalues.argmin(), result.pvalues.min())


def test_the_chain_draws_scenics_distribution_where_the_rule_binds(tight_reference):
    assert check(TIGHT_PROGRAM, TIGHT).ok and not overlapping(TIGHT)
    chain = Chain(TIGHT_PROGRAM, TIGHT, SynthConfig(), seed=4)
    meets = sum(bool(overlapping(c.scene("draw"))) for c in _draws(chain, 200))
    assert 0.3 < meets / 200 < 0.9  # the rule binds: it turns away this share of the program's own scenes
    result = compare(TIGHT_PROGRAM, TIGHT, SynthConfig(), tight_reference)
    assert result.same, (result.pvalues.argmin(), result.pvalues.min())


def test_the_chain_draws_scenics_speeds(scenic_installed):
    # Every motion clause, a relative speed Range below 0 (Scenic rejects a reference too slow for it) and boxes
    # side by side that the rule keeps apart.
    scene, program = every_motion_clause()
    config = SynthConfig(motion=True)
    reference = scenic_draws(program, scene, config)[0]
    assert all(s.by_id()["car2"].speed >= 7 for s in reference)
    result = compare(program, scene, config, reference)
    assert result.same, (result.pvalues.argmin(), result.pvalues.min())


def test_variants_carry_speeds_inside_their_clauses():
    scene, program = every_motion_clause()
    config = SynthConfig(motion=True)
    v = sample_variants(program, scene, config, 20, seed=1)
    _assert_variants(program, scene, v.scenes, config)
    assert all(s.ego.speed == 2.0 and s.by_id()["car2"].speed >= 7 for s in v.scenes)
    assert len({s.by_id()["car5"].speed for s in v.scenes}) == 20


@pytest.mark.parametrize("bug", ["half the sector width", "rule ignored"])
def test_the_comparison_catches_a_wrong_distribution(tight_reference, bug):
    if bug == "rule ignored":
        result = compare(TIGHT_PROGRAM, TIGHT, SynthConfig(), tight_reference, allow_collisions=True)
    else:
        result = compare(TIGHT_PROGRAM, TIGHT, SynthConfig(), tight_reference, chain_config=SynthConfig(delta1=5.0))
    assert result.pvalues.min() < result.threshold / 100
