"""The emitted Scenic text under the official compiler (scenic 3.1.1): it compiles, every scene it samples is
inside the DSL program's semantics (synth.semantics.check), and its requirements keep every pair of boxes apart
that is apart in the recording. Plus `r2s sample` as a user runs it. (The default sampler, the chain of
synth.variants.gibbs, and its agreement with Scenic: tests/synth/variants/test_variants.py.)"""

from __future__ import annotations

import ast
import itertools
import json
import random

import pytest

from tests.support import all_relation_kinds, assert_one_line_error, run_r2s

pytest.importorskip("scenic", reason="scenic (3.1.1) is not importable here: the Scenic tests need the compiler")

from pipeline.variants.render import ego_frame  # noqa: E402
from pipeline.variants.sample import SampleOptions, ScenicProgramError, sample_program, sample_scenic  # noqa: E402
from synth.config import SynthConfig  # noqa: E402
from synth.dsl import parse_program  # noqa: E402
from synth.scene import scene_from_dict  # noqa: E402
from synth.semantics import check  # noqa: E402
from synth.synthesize import synthesize  # noqa: E402

# Vehicles-only frames (one with a Trailer, the densest ones) and all-category frames up to the largest (141).
FRAMES = ["scene-0061/0#vehicles", "scene-0061/28#vehicles", "scene-0553/35#vehicles", "scene-0757/0",
          "scene-0061/2", "scene-0061/18"]
# Scenic's whole-scene rejection needs a sparse enough scene: in the two crowded frames (barrier rows, groups of
# pedestrians) 2000 iterations find no scene that keeps the recording's gaps, so Scenic samples them with
# collisions allowed (its failure there is tested below; the chain samples them with the rule).
CROWDED = {"scene-0061/2", "scene-0061/18"}
SCENIC = {"sampler": "scenic"}


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
    samples = sample_scenic(result.scenic, SampleOptions(n=5, seed=3, allow_collisions=frame in CROWDED, **SCENIC))
    assert len(samples.scenes) == 5 and samples.iterations >= 5
    for s in samples.scenes:
        _assert_inside(result.program, recorded, s)
    assert len({s.entities[-1].x for s in samples.scenes}) == 5  # variants, not copies


def overlapping(scene) -> set[frozenset[str]]:
    """Pairs of ids whose boxes meet, by shapely (what Scenic's `intersects` uses for planar boxes)."""
    from shapely.geometry import Polygon

    boxes = list(ego_frame(scene).values())
    return {frozenset((a.id, b.id)) for a, b in itertools.combinations(boxes, 2)
            if Polygon(a.corners()).intersects(Polygon(b.corners()))}


@pytest.mark.parametrize("frame", ["scene-0061/28#vehicles", "scene-0757/0"])
def test_scenic_keeps_apart_what_the_recording_keeps_apart(synthesized, frame):
    recorded, result = synthesized[frame]
    allowed = overlapping(recorded)
    for s in sample_scenic(result.scenic, SampleOptions(n=5, seed=11, **SCENIC)).scenes:
        assert overlapping(s) <= allowed


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
    for s in sample_scenic(result.scenic, SampleOptions(n=8, seed=1, allow_collisions=True, **SCENIC)).scenes:
        _assert_inside(result.program, recorded, s)


@pytest.mark.parametrize("sampler", ["scenic", "gibbs"])
def test_every_relation_kind_and_tolerance_config(sampler):
    # Every relation kind under non-default tolerances: the prelude's DELTA1 / DELTA2 follow the config.
    scene, program, config = all_relation_kinds()
    assert check(program, scene, config).ok, check(program, scene, config).violations
    samples = sample_program(program, scene, config, SampleOptions(n=10, seed=2, allow_collisions=True,
                                                                   sampler=sampler))
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
    samples = sample_scenic(result.scenic, SampleOptions(n=3, seed=0, **SCENIC))
    for s in samples.scenes:
        _assert_inside(result.program, scene, s)


def test_every_scenic_keyword_is_a_reserved_id():
    from scenic.syntax.parser import ScenicParser

    from synth.scene import RESERVED_IDS

    keywords = set(ScenicParser.KEYWORDS) | set(ScenicParser.SOFT_KEYWORDS)
    assert sorted(k for k in keywords if k[0].isalpha() and k not in RESERVED_IDS) == []


def test_same_seed_same_scenes_and_sample_k_does_not_depend_on_n(synthesized):
    _, result = synthesized["scene-0061/28#vehicles"]
    a = sample_scenic(result.scenic, SampleOptions(n=4, seed=9, **SCENIC)).scenes
    b = sample_scenic(result.scenic, SampleOptions(n=2, seed=9, **SCENIC)).scenes
    c = sample_scenic(result.scenic, SampleOptions(n=2, seed=10, **SCENIC)).scenes
    assert [s.to_json() for s in a[:2]] == [s.to_json() for s in b]
    assert a[0].to_json() != c[0].to_json()


def test_the_callers_random_state_is_left_alone(synthesized):
    _, result = synthesized["scene-0061/0#vehicles"]
    random.seed(123)
    expected = random.random()
    random.seed(123)
    sample_scenic(result.scenic, SampleOptions(n=1, seed=4, **SCENIC))
    assert random.random() == expected


TWO_CARS = "car1 = new Car ahead of ego by Range(0.5, 7.5), facing Range(-2.5, 2.5) deg\n"


@pytest.mark.parametrize("recorded_y, overlap_allowed", [(6.0, False), (1.0, True)])
def test_collisions_follow_the_recording(recorded_y, overlap_allowed):
    # car1 may be 0.5 to 7.5 m ahead of ego: it overlaps ego in about half of the program's scenes. Recorded 6 m
    # ahead (apart), it must stay apart in every sample; recorded 1 m ahead (overlapping), it may overlap.
    scene = scene_from_dict({"frame_id": "overlap", "entities": [
        {"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0},
        {"id": "car1", "type": "Car", "x": 0, "y": recorded_y, "heading": 0}]})
    program = parse_program(TWO_CARS)
    samples = sample_program(program, scene, SynthConfig(), SampleOptions(n=40, seed=1, **SCENIC)).scenes
    meet = sum(bool(overlapping(s)) for s in samples)
    assert (meet > 5) if overlap_allowed else (meet == 0)
    free = sample_program(program, scene, SynthConfig(), SampleOptions(n=40, seed=1, allow_collisions=True, **SCENIC))
    assert sum(bool(overlapping(s)) for s in free.scenes) > 5
    assert all(check(program, s).ok for s in samples + free.scenes)


def test_the_requirements_name_exactly_the_pairs_that_can_meet(synthesized):
    from synth.scenic.emit import read_source
    from synth.variants.collision_rule import collision_rule

    recorded, result = synthesized["scene-0061/2"]
    rule = collision_rule(result.program, recorded, SynthConfig())
    text = result.scenic.split("dsl__objects = [", 1)[1]
    stated = set()
    for req in text.split("require dsl__apart(")[1:]:
        obj, names = req.split(")", 1)[0].split(", ", 1)
        stated |= {frozenset((obj, other)) for other in ast.literal_eval(f"({names})").split()}  # adjacent literals
    assert stated == {frozenset(p) for p in rule.named(rule.apart)} and len(stated) > 100
    assert not stated & {frozenset(p) for p in rule.named(rule.recorded)}
    assert read_source(result.scenic).scene.by_id() == recorded.by_id()  # the rule is re-derived from the record


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


def test_the_header_says_how_to_run_the_file_with_scenic_and_its_headless_command_runs(files, tmp_path):
    """The header's own commands, as written (FILE replaced by the file): the window one names `--2d`; the headless
    one samples the file with Scenic's `scenic` command without a display and exits 0."""
    import os
    import re
    import subprocess
    import sys
    from pathlib import Path

    scenic_file = files["small"][0]
    header = scenic_file.read_text().split("\nparam ", 1)[0]
    assert "# Run: scenic FILE --2d (" in header
    command = re.search(r"headless \(no display\): (scenic FILE --2d [^\n]*?) *\n", header).group(1).split()
    assert "--gather-stats" in command and "r2s sample FILE" in header
    scenic = Path(sys.prefix) / "bin" / "scenic"
    if not scenic.exists():
        pytest.skip(f"no scenic command in {scenic.parent}")
    env = {k: v for k, v in os.environ.items() if k != "DISPLAY"}
    args = [str(scenic_file) if a == "FILE" else a for a in command[1:]]
    proc = subprocess.run([str(scenic), *args, "-s", "1"], cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    n = int(command[command.index("--gather-stats") + 1])
    assert f"Sampled {n} scenes" in proc.stdout, proc.stdout[-1000:]


@pytest.mark.parametrize("sampler", ["gibbs", "scenic"])
def test_cli_writes_scene_json_byte_identical_for_a_seed(files, tmp_path, monkeypatch, sampler):
    scenic_file, dsl, scene = files["small"]
    proc = run_r2s("sample", str(scenic_file), "--n", "3", "--seed", "5", "--sampler", sampler,
                   "--out", str(tmp_path / "a"))
    assert proc.returncode == 0, proc.stderr
    assert "wrote 3 scenes" in proc.stdout and sampler in proc.stdout
    written = sorted(p.name for p in (tmp_path / "a").iterdir())
    assert written == ["sample_000.json", "sample_001.json", "sample_002.json"]
    program = parse_program(dsl.read_text())
    recorded = scene_from_dict(json.loads(scene.read_text()))
    for name in written:
        doc = json.loads((tmp_path / "a" / name).read_text())
        assert doc["frame_id"].startswith("scene-0061/28#vehicles#sample")
        assert all("length" in e and "width" in e for e in doc["entities"])
        assert check(program, scene_from_dict(doc)).ok
        assert overlapping(scene_from_dict(doc)) <= overlapping(recorded)
    # Another process, another hash seed, and the DSL route (program + scene instead of the record): same bytes.
    monkeypatch.setenv("PYTHONHASHSEED", "77")
    proc = run_r2s("sample", "--program", str(dsl), "--scene", str(scene), "--n", "3", "--seed", "5",
                   "--sampler", sampler, "--out", str(tmp_path / "b"))
    assert proc.returncode == 0, proc.stderr
    for name in written:
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes()


def test_cli_scenic_budget_exhausted_is_exit_4_naming_the_pairs_nothing_written(files, tmp_path):
    scenic_file, dsl, scene = files["crowded"]
    out = tmp_path / "none"
    proc = run_r2s("sample", str(scenic_file), "--n", "2", "--sampler", "scenic", "--max-iterations", "3",
                   "--out", str(out))
    assert_one_line_error(proc, 4, contains="Scenic found no scene that satisfies the program and the collision "
                                            "rule in 3 iterations")
    assert "independent draws from the program satisfy the collision rule" in proc.stderr
    assert "most often colliding: " in proc.stderr and "--sampler gibbs" in proc.stderr
    assert not out.exists()
    # The chain (the default) samples it.
    proc = run_r2s("sample", str(scenic_file), "--n", "2", "--burn-in", "2", "--thin", "2", "--out", str(out))
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
    (("SCENIC", "--sampler", "metropolis"), "--sampler"),
    (("SCENIC", "--thin", "0"), "--thin"),
    (("EDITED", "--trusted", "--sampler", "gibbs"), "only --sampler scenic samples it"),
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
    edited = tmp_path / "edited.scenic"
    edited.write_text(files["small"][0].read_text().replace("requireVisible: False", "requireVisible: False  # ", 1))
    subst = {"SCENIC": str(files["small"][0]), "BROKEN": str(broken), "EDITED": str(edited)}
    out = tmp_path / "out"
    proc = run_r2s("sample", *(subst.get(a, a) for a in args), "--out", str(out))
    assert_one_line_error(proc, 2, contains=message)
    assert not out.exists()
