"""Motion under the official Scenic compiler (scenic 3.1.1): every object carries a speed that satisfies its
clause (never negative), variants carry those speeds into scene JSON, and `r2s check` accepts them."""

from __future__ import annotations

import json
import random
from dataclasses import replace

import pytest

from tests.support import every_motion_clause, run_r2s, shipped_frames

pytest.importorskip("scenic", reason="scenic (3.1.1) is not importable here: the Scenic tests need the compiler")

from pipeline.variants.sample import SampleOptions, sample_program, sample_scenic  # noqa: E402
from synth.config import SynthConfig  # noqa: E402
from synth.scene import Scene  # noqa: E402
from synth.scenic.emit import rebuild_from_source  # noqa: E402
from synth.semantics import check  # noqa: E402
from synth.synthesize import synthesize  # noqa: E402

MOTION_ON = SynthConfig(motion=True)
SCENIC = {"sampler": "scenic", "allow_collisions": True}


def moving(scene: Scene, seed: int) -> Scene:
    """The recorded frame with speeds: a few parked, a few at walking pace, the rest in traffic."""
    rng = random.Random(seed)
    return Scene(scene.frame_id, tuple(
        replace(e, speed=rng.choice([0.0, rng.uniform(0, 0.5), rng.uniform(1, 2), rng.uniform(5, 14)]))
        for e in scene.entities))


@pytest.fixture(scope="module")
def motion_frames():
    frames = [s for s in shipped_frames() if s.frame_id in ("scene-0061/0#vehicles", "scene-0757/0")]
    return [(s, synthesize(s, MOTION_ON)) for s in (moving(f, k) for k, f in enumerate(frames))]


def _speeds_inside(program, recorded, sampled):
    result = check(program, sampled, MOTION_ON)
    assert result.ok, [str(v) for v in result.violations[:5]]
    assert all(e.speed is not None and e.speed >= 0.0 for e in sampled.entities)
    assert sampled.ego.speed == recorded.ego.speed  # ego as recorded


def test_variants_carry_speeds_inside_their_clauses(motion_frames):
    for recorded, result in motion_frames:
        assert rebuild_from_source(result.scenic) == result.scenic
        samples = sample_scenic(result.scenic, SampleOptions(n=6, seed=2, **SCENIC)).scenes
        for s in samples:
            _speeds_inside(result.program, recorded, s)
        assert len({s.entities[-1].speed for s in samples}) == 6  # drawn, not copied


@pytest.fixture
def ranges_at_their_bounds(monkeypatch):
    pick = random.Random(7)
    monkeypatch.setattr(random, "uniform", lambda a, b: a if pick.random() < 0.5 else b)


def test_speeds_at_the_printed_bounds_are_still_inside(motion_frames, ranges_at_their_bounds):
    for recorded, result in motion_frames:
        for s in sample_scenic(result.scenic, SampleOptions(n=6, seed=1, **SCENIC)).scenes:
            _speeds_inside(result.program, recorded, s)


@pytest.mark.parametrize("sampler", ["scenic", "gibbs"])
def test_every_motion_clause_samples_inside_and_never_negative(sampler):
    # Hand-written clauses a synthesized program rarely needs (see conftest.every_motion_clause).
    scene, program = every_motion_clause()
    assert check(program, scene, MOTION_ON).ok
    options = SampleOptions(n=30, seed=3, sampler=sampler, allow_collisions=True)
    samples = sample_program(program, scene, MOTION_ON, options).scenes
    for s in samples:
        _speeds_inside(program, scene, s)
    speeds = {e.id: [s.by_id()[e.id].speed for s in samples] for e in scene.others}
    assert max(speeds["car4"]) <= 0.5 and min(speeds["car5"]) >= 0.0 and min(speeds["car3"]) >= 0.0
    assert max(speeds["car1"]) - min(speeds["car1"]) > 2  # an absolute Range is drawn across its width


@pytest.mark.parametrize("sampler", ["scenic", "gibbs"])
def test_r2s_sample_writes_speeds_and_r2s_check_accepts_them(motion_frames, tmp_path, sampler):
    # Scenic with collisions allowed (its rejection would need many draws here); the chain keeps the recording's gaps.
    recorded, result = motion_frames[1]
    (tmp_path / "p.scenic").write_text(result.scenic)
    (tmp_path / "p.dsl").write_text(str(result.program))
    free = ["--allow-collisions"] if sampler == "scenic" else []
    proc = run_r2s("sample", str(tmp_path / "p.scenic"), "--n", "3", "--seed", "4", "--sampler", sampler, *free,
                   "--out", str(tmp_path / "v"))
    assert proc.returncode == 0, proc.stderr
    config = tmp_path / "motion.toml"
    config.write_text("[synth]\nmotion = true\n")
    for k in range(3):
        doc = json.loads((tmp_path / "v" / f"sample_{k:03d}.json").read_text())
        assert all(isinstance(e["speed"], float) and e["speed"] >= 0 for e in doc["entities"])
        ok = run_r2s("check", str(tmp_path / "v" / f"sample_{k:03d}.json"), str(tmp_path / "p.dsl"),
                     "--config", str(config))
        assert ok.returncode == 0, ok.stdout + ok.stderr


def test_static_programs_write_no_speed(tmp_path):
    scene = next(s for s in shipped_frames() if s.frame_id == "scene-0757/0")
    result = synthesize(moving(scene, 1))  # speeds known, but the program is static
    assert "with speed" not in result.scenic and "r2s_motion" not in result.scenic
    (s,) = sample_scenic(result.scenic, SampleOptions(n=1, seed=1, **SCENIC)).scenes
    assert all(e.speed is None for e in s.entities)
