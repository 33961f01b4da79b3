"""Behaviour programs of a clip (docs/dsl.md, "Behaviour programs"): the dynamic programming's minimum against a
brute force over every boundary set (random tracks with hypothesis; every track of real clips), the checker on
what synthesis writes, printing and parsing, and the clip's refusals."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from pipeline.scenes import scene as frame_scene
from synth.behaviour.check import behaviour_holds, check_clip
from synth.behaviour.program import parse_clip_program
from synth.behaviour.segmentation import segment_track
from synth.behaviour.synthesize import synthesize_behaviours
from synth.behaviour.track import ClipError, Sample, Steps, Track, read_clip
from synth.config import SynthConfig
from synth.syntax import DslError
from tests.support import ROOT, run_r2s
from tests.support.behaviour_bruteforce import brute_cost

AV2 = ROOT / "data" / "argoverse2-log-excerpt" / "frames.parquet"
LOG = "adcf7d18-0510-35b0-a2fa-b4cea13a6d76"
# Speeds on a grid of quarters and thresholds off it: no value lies within the checker's 1e-9 of a bound, where
# the checker (accepting within 1e-9) and synthesis (exact) may read a sample differently by design.
CONFIG = SynthConfig(v_stop=0.6, dv=1.1, c_speed=2.0, c_head=5.0)


@st.composite
def tracks(draw) -> Track:
    n = draw(st.integers(1, 7))
    # Speeds as a walk (steady, rising and falling stretches, as recorded speeds are), on quarters.
    start = draw(st.integers(0, 40)) / 4
    deltas = draw(st.lists(st.sampled_from([-1.5, -1.0, -0.5, -0.25, 0.0, 0.0, 0.5, 1.0, 1.5]), min_size=n, max_size=n))
    speeds = [max(0.0, start + sum(deltas[:k])) for k in range(n)]
    turns = draw(st.lists(st.sampled_from([0.0, 1.5, -1.5, 4.5, 7.5, -7.5, 15.0, -22.5]), min_size=n, max_size=n))
    gaps = draw(st.lists(st.integers(1, 5).map(lambda k: k / 8), min_size=n, max_size=n))
    lanes = draw(st.lists(st.sampled_from([None, "a", "b"]), min_size=n, max_size=n))
    crossing = draw(st.lists(st.booleans(), min_size=n, max_size=n))
    samples, t, h = [], 0.0, draw(st.sampled_from([0.0, 90.0, 357.0]))
    for k in range(n):
        h = (h + turns[k]) % 360.0
        samples.append(Sample(t, speeds[k], h, lanes[k], crossing[k]))
        t += gaps[k]
    # What the lane graph says of each step is a fact of the recording: drawn, only where both samples have lanes.
    laned = [samples[k].lane is not None and samples[k + 1].lane is not None for k in range(n - 1)]
    flags = [draw(st.lists(st.booleans(), min_size=n - 1, max_size=n - 1)) for _ in range(3)]
    steps = Steps(*(tuple(f and ok for f, ok in zip(fs, laned)) for fs in flags))
    return Track("car1", "Car", tuple(samples), steps, True)


@given(tracks())
def test_dynamic_programming_is_minimal_against_the_brute_force(track):
    found = segment_track(track, CONFIG)
    assert found.behaviour.cost == brute_cost(track, CONFIG)
    assert behaviour_holds(found.behaviour, track, CONFIG)
    bounds = found.boundaries
    assert bounds[0] == 0 and bounds[-1] == track.n - 1 and list(bounds) == sorted(bounds)


def test_a_steady_walk_is_one_segment():
    """Equal headings, no lane, a steady speed: one segment, `heading Range(h, h) deg, cruising ...` (cost 4)."""
    samples = tuple(Sample(0.5 * k, 1.25, 61.5, None, False) for k in range(5))
    track = Track("pedestrian1", "Pedestrian", samples, Steps.of(samples, None), True)
    found = segment_track(track, CONFIG)
    assert str(found.behaviour) == ("behaviour pedestrian1 heading Range(61.5, 61.5) deg, cruising Range(1.25, 1.25) m/s "
                                    "for Range(2, 2) s\n")
    assert found.behaviour.cost == brute_cost(track, CONFIG) == 4


def _clip(first: int, n: int):
    return [frame_scene(str(AV2), f"{LOG}/{k}") for k in range(first, first + n)]


@pytest.fixture(scope="module")
def av2_clip():
    return _clip(100, 8)


def test_every_track_of_a_real_clip_is_minimal_and_checked(av2_clip):
    config = SynthConfig(motion=True, lanes=True)
    clip = read_clip(av2_clip)
    moving = [t for t in clip.tracks if any(s.speed > config.v_stop for s in t.samples)]
    assert len(moving) >= 10 and any(t.steps.keep and any(t.steps.keep) for t in moving)
    for track in clip.tracks:
        found = segment_track(track, config)
        assert found.behaviour.cost == brute_cost(track, config), track.id
    result = synthesize_behaviours(clip, config)
    assert check_clip(str(result.program), av2_clip, config).ok
    assert parse_clip_program(str(result.program)) == result.program
    assert result.cost == result.first.cost + sum(b.cost for b in result.program.behaviours)


def _minimal_on_every_track(scenes, config):
    clip = read_clip(scenes)
    for track in clip.tracks:
        assert segment_track(track, config).behaviour.cost == brute_cost(track, config), track.id
    assert check_clip(synthesize_behaviours(clip, config).program, clip, config).ok
    return clip


def test_every_track_of_nuscenes_keyframes_is_minimal(excerpt_frames):
    config = SynthConfig(motion=True, lanes=True)
    clip = _minimal_on_every_track([frame_scene(str(excerpt_frames), f"scene-0103/{k}") for k in range(4)], config)
    assert len(clip.tracks) > 20


def test_every_track_of_a_waymo_second_is_minimal(shared_dir, tmp_path):
    source = tmp_path / "waymo"
    source.mkdir()
    (source / "one.pkl").write_bytes((shared_dir / "data" / "waymo" / "sd_waymo_v1.2_7e21cb7ea347ecaa.pkl").read_bytes())
    frames = tmp_path / "frames"
    assert run_r2s("extract", "scenarionet", str(source), "--categories", "all", "--out", str(frames)).returncode == 0
    scene = "7e21cb7ea347ecaa"
    config = SynthConfig(motion=True, lanes=True)
    clip = _minimal_on_every_track([frame_scene(str(frames), f"{scene}/{k}") for k in range(11)], config)
    assert any(any(t.steps.keep) for t in clip.tracks)


def test_the_checker_refuses_a_behaviour_that_leaves_the_recording(av2_clip):
    config = SynthConfig(motion=True, lanes=True)
    program = synthesize_behaviours(av2_clip, config).program
    text = str(program)
    ego = program.behaviour("ego")
    assert not ego.parked  # ego drives in this stretch of the log
    wrong = text.replace(str(ego), "behaviour ego parked\n")
    verdict = check_clip(wrong, av2_clip, config)
    assert [(v.entity, v.part) for v in verdict.violations] == [("ego", "behaviour")]
    missing = check_clip(text.replace(str(ego), ""), av2_clip, config)
    assert [(v.entity, v.part) for v in missing.violations] == [("ego", "missing")]
    extra = check_clip(text + "behaviour car999 parked\n", av2_clip, config)
    assert [(v.entity, v.part) for v in extra.violations] == [("car999", "extra")]


@pytest.mark.parametrize("text, message", [
    ("behaviour ego cruising Range(1, 2) m/s for Range(0, 1) s\n", "needs a path"),
    ("behaviour ego stopped for Range(0, 1) s\nbehaviour ego parked\n", "has a behaviour already"),
    ("then stopped for Range(0, 1) s\n", "'then' before any behaviour"),
    ("behaviour ego parked\nthen stopped for Range(0, 1) s\n", "parked behaviour"),
    ("behaviour ego following lane, drifting Range(1, 2) m/s for Range(0, 1) s\n", "expected a pace"),
    ("behaviour ego turning up, stopped for Range(0, 1) s\n", "expected left or right"),
    ("behaviour ego stopped for Range(2, 1) s\n", "is empty"),
])
def test_bad_clip_programs_are_one_line(text, message):
    with pytest.raises(DslError, match=message) as info:
        parse_clip_program(text)
    assert "\n" not in str(info.value)


def test_a_clip_without_times_or_out_of_order_is_refused(av2_clip):
    untimed = [s.to_dict() for s in av2_clip[:2]]
    for doc in untimed:
        del doc["world"]["timestamp_us"]
    with pytest.raises(ClipError, match="has no time"):
        read_clip(untimed)
    backwards = [s.to_dict() for s in av2_clip[:2]]
    backwards[1]["world"]["timestamp_us"] = backwards[0]["world"]["timestamp_us"]
    with pytest.raises(ClipError, match="not later"):
        read_clip(backwards)
