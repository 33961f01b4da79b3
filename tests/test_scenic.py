"""The emitted Scenic text under the official compiler (scenic 3.1.1): it compiles, and every scene it samples
is inside the DSL program's semantics (synth.semantics.check). Plus `r2s sample` as a user runs it."""

from __future__ import annotations

import itertools
import json
import random

import pytest
from conftest import assert_one_line_error, run_r2s

pytest.importorskip("scenic", reason="scenic (3.1.1) is not importable here: the Scenic tests need the compiler")

from pipeline.render import ego_frame  # noqa: E402
from pipeline.sample import SampleOptions, SamplingFailed, ScenicProgramError, sample_program, sample_scenic  # noqa: E402
from synth.config import SynthConfig  # noqa: E402
from synth.dsl import parse_program  # noqa: E402
from synth.scene import scene_from_dict  # noqa: E402
from synth.semantics import check  # noqa: E402
from synth.synthesize import synthesize  # noqa: E402

# Vehicles-only frames (one with a Trailer, the densest ones) and all-category frames up to the largest (141).
FRAMES = ["scene-0061/0#vehicles", "scene-0061/28#vehicles", "scene-0553/35#vehicles", "scene-0757/0",
          "scene-0061/2", "scene-0061/18"]
# Collision-free samples need a sparse enough scene: in the two crowded frames (barrier rows, groups of
# pedestrians, boxes that touch in the recording) 2000 rejection iterations find none, so they are sampled
# with collisions allowed (their collision failure is tested below).
CROWDED = {"scene-0061/2", "scene-0061/18"}


@pytest.fixture(scope="module")
def synthesized(real_frames):
    by_id = {s.frame_id: s for s in real_frames}
    return {f: (by_id[f], synthesize(by_id[f])) for f in FRAMES}


def _assert_inside(program, recorded, sampled, config=None):
    result = check(program, sampled, config)
    assert result.ok, [str(v) for v in result.violations[:5]]
    assert [e.id for e in sampled.entities] == ["ego"] + [s.id for s in program.statements]
    by_id = recorded.by_id()
    assert all(e.type == by_id[e.id].type for e in sampled.entities)
    assert all(0.0 <= e.heading < 360.0 for e in sampled.entities)
    ego, rec = sampled.ego, recorded.ego
    assert (ego.x, ego.y) == (rec.x, rec.y) and abs(ego.heading - rec.heading) < 1e-9


@pytest.mark.parametrize("frame", FRAMES)
def test_every_sampled_scene_is_inside_the_program(synthesized, frame):
    recorded, result = synthesized[frame]
    assert check(result.program, recorded).ok
    samples = sample_scenic(result.scenic, SampleOptions(n=5, seed=3, allow_collisions=frame in CROWDED))
    assert len(samples.scenes) == 5 and samples.iterations >= 5
    for s in samples.scenes:
        _assert_inside(result.program, recorded, s)
    assert len({s.entities[-1].x for s in samples.scenes}) == 5  # variants, not copies


def _overlap(a, b) -> bool:
    from shapely.geometry import Polygon

    return Polygon(a.corners()).intersection(Polygon(b.corners())).area > 1e-9


@pytest.mark.parametrize("frame", ["scene-0061/28#vehicles", "scene-0757/0"])
def test_default_samples_are_collision_free(synthesized, frame):
    recorded, result = synthesized[frame]
    for s in sample_scenic(result.scenic, SampleOptions(n=5, seed=11)).scenes:
        boxes = list(ego_frame(s).values())
        assert not any(_overlap(a, b) for a, b in itertools.combinations(boxes, 2))


@pytest.fixture
def ranges_at_their_bounds(monkeypatch):
    """Every Range Scenic samples comes out exactly at one of its bounds (Scenic samples with random.uniform)."""
    pick = random.Random(5)
    monkeypatch.setattr(random, "uniform", lambda a, b: a if pick.random() < 0.5 else b)


@pytest.mark.parametrize("frame", ["scene-0061/0#vehicles", "scene-0553/35#vehicles", "scene-0061/2"])
def test_samples_at_the_printed_bounds_are_still_inside(synthesized, frame, ranges_at_their_bounds):
    # The extreme case for float rounding: distances, sector angles, facing tolerances and heading Ranges all
    # at their bounds at once. The checker's 1e-9 slack must absorb whatever Scenic's arithmetic adds.
    recorded, result = synthesized[frame]
    for s in sample_scenic(result.scenic, SampleOptions(n=8, seed=1, allow_collisions=True)).scenes:
        _assert_inside(result.program, recorded, s)


def test_every_relation_kind_and_tolerance_config(real_frames):
    # Absolute and relative positions and headings too (a real frame's optimum rarely needs them), under
    # non-default tolerances: the prelude's DELTA1 / DELTA2 follow the config.
    config = SynthConfig(delta1=4.0, delta2=2.0, oracle="closed-form")
    scene = scene_from_dict({"frame_id": "kinds", "entities": [
        {"id": "ego", "type": "Car", "x": 3.5, "y": -2.0, "heading": 200.0},
        {"id": "car1", "type": "Car", "x": 0.0, "y": 12.0, "heading": 359.0},
        {"id": "ped1", "type": "Pedestrian", "x": -12.0, "y": 12.3, "heading": 90.0},
        {"id": "cone1", "type": "TrafficCone", "x": -7.0, "y": -20.0, "heading": 10.0},
        {"id": "bus1", "type": "Bus", "x": 20.0, "y": 30.0, "heading": 330.0, "length": 12.5, "width": 3.0},
    ]})
    program = parse_program(
        "car1 = new Car on Range(-4, 1) @ Range(-17, -12) relative to ego, facing Range(356.5, 361.5) deg\n"
        "ped1 = new Pedestrian left of car1 by Range(9.5, 14.5), facing Range(-271.5, -266.5) deg relative to car1\n"
        "cone1 = new TrafficCone on Range(-9, -4) @ Range(-22, -17), facing toward ped1\n"
        "bus1 = new Bus on Range(18, 23) @ Range(28, 33), facing away from cone1\n"
    )
    assert check(program, scene, config).ok, check(program, scene, config).violations
    samples = sample_program(program, scene, config, SampleOptions(n=10, seed=2, allow_collisions=True))
    for s in samples.scenes:
        _assert_inside(program, scene, s, config)
    bus = samples.scenes[0].by_id()["bus1"]
    assert (bus.length, bus.width) == (12.5, 3.0)  # the recorded box, not the class default


def test_ids_that_look_like_the_prelude_cannot_shadow_it():
    # Ids may be any identifier without '__'; every name the emitter binds has '__', so none is shadowed.
    names = ["sector_ahead", "in_sector", "DELTA1", "facing_toward", "relative_xy", "bearing", "name",
             "r2s_allow_collisions", "r2s_frame_id"]
    doc = {"frame_id": "shadow", "entities": [{"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0}] + [
        {"id": n, "type": "Pedestrian", "x": 3.0 * (i % 2) - 1.5, "y": 4.0 + 3.0 * i, "heading": 10.0 * i}
        for i, n in enumerate(names)]}
    scene = scene_from_dict(doc)
    result = synthesize(scene, SynthConfig(oracle="closed-form"))
    samples = sample_scenic(result.scenic, SampleOptions(n=3, seed=0))
    for s in samples.scenes:
        _assert_inside(result.program, scene, s)


def test_every_scenic_keyword_is_a_reserved_id():
    from scenic.syntax.parser import ScenicParser

    from synth.scene import RESERVED_IDS

    keywords = set(ScenicParser.KEYWORDS) | set(ScenicParser.SOFT_KEYWORDS)
    assert sorted(k for k in keywords if k[0].isalpha() and k not in RESERVED_IDS) == []


def test_same_seed_same_scenes_and_sample_k_does_not_depend_on_n(synthesized):
    _, result = synthesized["scene-0061/28#vehicles"]
    a = sample_scenic(result.scenic, SampleOptions(n=4, seed=9)).scenes
    b = sample_scenic(result.scenic, SampleOptions(n=2, seed=9)).scenes
    c = sample_scenic(result.scenic, SampleOptions(n=2, seed=10)).scenes
    assert [s.to_json() for s in a[:2]] == [s.to_json() for s in b]
    assert a[0].to_json() != c[0].to_json()


def test_the_callers_random_state_is_left_alone(synthesized):
    _, result = synthesized["scene-0061/0#vehicles"]
    random.seed(123)
    expected = random.random()
    random.seed(123)
    sample_scenic(result.scenic, SampleOptions(n=1, seed=4))
    assert random.random() == expected


def test_collisions_refused_by_default_allowed_with_the_flag():
    # car1's centre is within 1.5 m of ego's: it always overlaps ego.
    scene = scene_from_dict({"frame_id": "overlap", "entities": [
        {"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0},
        {"id": "car1", "type": "Car", "x": 0, "y": 1.0, "heading": 0}]})
    program = parse_program("car1 = new Car ahead of ego by Range(0.5, 1.5), facing Range(-2.5, 2.5) deg\n")
    with pytest.raises(SamplingFailed, match="without collisions found in 50 iterations.*--allow-collisions.*"
                                             "recorded scene itself has 1 overlapping pair of boxes .e.g. ego and car1"):
        sample_program(program, scene, SynthConfig(), SampleOptions(n=1, max_iterations=50))
    samples = sample_program(program, scene, SynthConfig(), SampleOptions(n=3, allow_collisions=True))
    assert all(check(program, s).ok for s in samples.scenes)


# ------------------------------------------------------------------------------------------ r2s sample (CLI)

@pytest.fixture(scope="module")
def files(synthesized, tmp_path_factory):
    d = tmp_path_factory.mktemp("sample")
    out = {}
    for frame in ("scene-0061/28#vehicles", "scene-0061/2"):
        recorded, result = synthesized[frame]
        key = "small" if "vehicles" in frame else "crowded"
        (d / f"{key}.scenic").write_text(result.scenic)
        (d / f"{key}.dsl").write_text(str(result.program))
        (d / f"{key}.json").write_text(recorded.to_json())
        out[key] = (d / f"{key}.scenic", d / f"{key}.dsl", d / f"{key}.json")
    return out


def test_cli_writes_scene_json_byte_identical_for_a_seed(files, tmp_path, monkeypatch):
    scenic_file, dsl, scene = files["small"]
    proc = run_r2s("sample", str(scenic_file), "--n", "3", "--seed", "5", "--out", str(tmp_path / "a"))
    assert proc.returncode == 0, proc.stderr
    assert "wrote 3 scenes" in proc.stdout
    written = sorted(p.name for p in (tmp_path / "a").iterdir())
    assert written == ["sample_000.json", "sample_001.json", "sample_002.json"]
    program = parse_program(dsl.read_text())
    for name in written:
        doc = json.loads((tmp_path / "a" / name).read_text())
        assert doc["frame_id"].startswith("scene-0061/28#vehicles#sample")
        assert check(program, scene_from_dict(doc)).ok
    # Another process, another hash seed, and the DSL route (text regenerated from program + scene): same bytes.
    monkeypatch.setenv("PYTHONHASHSEED", "77")
    proc = run_r2s("sample", "--program", str(dsl), "--scene", str(scene), "--n", "3", "--seed", "5",
                   "--out", str(tmp_path / "b"))
    assert proc.returncode == 0, proc.stderr
    for name in written:
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes()


def test_cli_budget_exhausted_is_one_line_exit_2_nothing_written(files, tmp_path):
    scenic_file, dsl, scene = files["crowded"]
    out = tmp_path / "none"
    proc = run_r2s("sample", str(scenic_file), "--n", "2", "--max-iterations", "3", "--out", str(out))
    assert_one_line_error(proc, 2, contains="no scene without collisions found in 3 iterations")
    assert "--allow-collisions" in proc.stderr and "--max-iterations" in proc.stderr
    assert not out.exists()
    # From the DSL program and its scene, the message also says why: the recording's own boxes overlap.
    proc = run_r2s("sample", "--program", str(dsl), "--scene", str(scene), "--max-iterations", "3", "--out", str(out))
    assert_one_line_error(proc, 2, contains="the recorded scene itself has 8 overlapping pairs of boxes")
    assert not out.exists()
    proc = run_r2s("sample", str(scenic_file), "--n", "2", "--allow-collisions", "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    assert len(list(out.glob("sample_*.json"))) == 2


HANDWRITTEN = "class Car:\n    requireVisible: False\nego = new Car at (0 @ 0), with name 'ego'\n"

BAD_SCENIC = {
    "syntax": (HANDWRITTEN + "car1 = new Car at (0 @ 10\n", "cannot compile"),
    "python error": (HANDWRITTEN + "x = undefined_thing + 1\n", "cannot compile"),
    "no name": (HANDWRITTEN + "car1 = new Car at (0 @ 10)\n", "has no name"),
    "spoofed id": (HANDWRITTEN + "car1 = new Car at (0 @ 10), with name 'os.system(1)'\n", "not an identifier"),
    "reserved id": (HANDWRITTEN + "car1 = new Car at (0 @ 10), with name 'exec'\n", "reserved"),
    "foreign class": ("class Robot:\n    requireVisible: False\nego = new Robot at (0 @ 0), with name 'ego'\n",
                      "unknown type"),
    "no ego": ("class Car:\n    requireVisible: False\nego = new Car at (0 @ 0), with name 'car1'\n", "ego"),
    "duplicate id": (HANDWRITTEN + "c = new Car at (0 @ 10), with name 'ego'\n", "duplicate"),
}


@pytest.mark.parametrize("case", BAD_SCENIC)
def test_bad_scenic_is_a_user_error(case):
    text, message = BAD_SCENIC[case]
    with pytest.raises(ScenicProgramError, match=message):
        sample_scenic(text, SampleOptions(n=1, max_iterations=20), trusted=True)


def test_allow_collisions_on_a_program_that_ignores_it_is_refused():
    with pytest.raises(ScenicProgramError, match="no effect"):
        sample_scenic(HANDWRITTEN, SampleOptions(allow_collisions=True), trusted=True)


@pytest.mark.parametrize("args, message", [
    ((), "either PROGRAM.scenic or --program"),
    (("--program", "P.dsl"), "needs --scene"),
    (("missing.scenic",), "does not exist"),
    (("BROKEN", "--trusted"), "cannot compile"),
    (("BROKEN",), "not Scenic text written by r2sgen"),
    (("SCENIC", "--scene", "S.json"), "belong to the --program route"),
    (("SCENIC", "--n", "0"), "--n"),
    (("SCENIC", "--seed", "-1"), "--seed"),
    (("SCENIC", "--max-iterations", "x"), "--max-iterations"),
])
def test_cli_bad_usage_is_one_line_exit_2(files, tmp_path, args, message):
    broken = tmp_path / "broken.scenic"
    broken.write_text("ego = new\n")
    subst = {"SCENIC": str(files["small"][0]), "BROKEN": str(broken)}
    out = tmp_path / "out"
    proc = run_r2s("sample", *(subst.get(a, a) for a in args), "--out", str(out))
    assert_one_line_error(proc, 2, contains=message)
    assert not out.exists()
