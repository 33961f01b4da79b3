"""Temporal patterns (`r2s query` with steps, durations, behaviours): the DuckDB engine against a plain loop over
frames straight from the definition (tests/support/temporal_bruteforce.py) on shipped and real scenes and on random
tracks (hypothesis: tracks with gaps, timestamps on a 100 ms grid so durations fall exactly on their bounds,
speeds that cross the behaviours' thresholds), plus the syntax and its one-line errors."""

from __future__ import annotations

import tempfile
from pathlib import Path

import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from frames.rows import FramesError, read_frames, write_frames
from pipeline.query.mining import query_frames
from synth.dsl import DslError
from synth.patterns.temporal import is_temporal, parse_query_pattern, parse_temporal
from tests.support import ROOT, assert_one_line_error, run_r2s
from tests.support.extract import EXCERPT, frames_of
from tests.support.temporal_bruteforce import brute_temporal
from tests.support.temporal_engine import engine_temporal

SHIPPED = {p.name: p.read_text() for p in sorted((ROOT / "data" / "patterns").glob("*.dsl")) if is_temporal(p.read_text())}
SHARED = Path("/work/shared/data")


def test_shipped_patterns_are_temporal_and_read_back():
    assert set(SHIPPED) >= {"cut-in-from-left.dsl", "cut-in-from-right.dsl", "vehicle-following-ego.dsl",
                            "pedestrian-crossing-ahead.dsl", "vehicle-braking-ahead.dsl",
                            "stopped-vehicle-starts-moving.dsl"}
    for text in SHIPPED.values():
        p = parse_temporal(text)
        assert parse_temporal(str(p)) == p


def _real_inputs():
    """Frames with speeds and timestamps: the shipped excerpts, and /work/shared/data's scenes when present."""
    yield "excerpt", "scenarionet", EXCERPT / "scenarionet"
    yield "av2-excerpt", "argoverse2", ROOT / "tests" / "data" / "argoverse2"
    yield "shared-nuscenes", "scenarionet", SHARED / "nuscenes-mini" / "scenarionet"
    yield "shared-av2", "argoverse2", SHARED / "argoverse2" / "test_data"


@pytest.fixture(scope="module")
def real_frames(tmp_path_factory):
    from extractors.categories import ALL
    from extractors.registry import source as source_of

    out = {"av2-log": ROOT / "data" / "argoverse2-log-excerpt" / "frames.parquet"}  # shipped: 156 frames at 10 Hz
    for name, source, path in _real_inputs():
        if not path.exists():
            continue
        frames = frames_of(source_of(source).extract, path, categories=ALL)
        target = tmp_path_factory.mktemp(name) / "frames.parquet"
        write_frames(frames, target)
        out[name] = target
    return out


@pytest.mark.parametrize("pattern", sorted(SHIPPED))
@pytest.mark.parametrize("data", ["av2-log"] + [n for n, _, _ in _real_inputs()])
def test_shipped_patterns_on_real_scenes_are_the_brute_force(real_frames, pattern, data, tmp_path):
    if data not in real_frames:
        pytest.skip(f"{data}: /work/shared/data is not on this machine")
    path = real_frames[data]
    got = engine_temporal(path, SHIPPED[pattern], tmp_path)
    assert got == brute_temporal(read_frames(path), parse_temporal(SHIPPED[pattern]))


def test_the_shipped_patterns_find_what_they_say_on_real_data(real_frames, tmp_path):
    """Each finds at least one event in the real scenes at hand (the excerpts alone are too short for some)."""
    if "shared-av2" not in real_frames:
        pytest.skip("/work/shared/data is not on this machine")
    found = {}
    for name, text in SHIPPED.items():
        found[name] = 0
        for path in real_frames.values():
            out = tmp_path / f"{name}.parquet"
            found[name] += query_frames(path, parse_temporal(text), out, events=True, log=lambda s: None).events
    assert all(found.values()), found


# ----------------------------------------------------------------------------------------- random tracks

STEPS = [
    # One step, with and without a least duration (0.2 s: two 100 ms steps, met exactly on the grid).
    "a = new Object ahead of ego by Range(0, 8), facing Range(0, 360) deg\nfor at least 0.2 s\n",
    # Two steps over one variable, with a gap bound met exactly on the grid.
    "a = new Object left of ego by Range(0, 8), facing Range(0, 360) deg\nthen within 0.2 s\n"
    "a = new Object ahead of ego by Range(0, 8), facing Range(0, 360) deg\n",
    # Two variables, the second step with a least duration, plain `then`.
    "a = new Object on Range(-8, 8) @ Range(-8, 8), facing Range(0, 360) deg\n"
    "b = new Object ahead of a by Range(0, 8), facing Range(0, 360) deg\nthen\n"
    "b = new Object on Range(-8, 8) @ Range(-8, 8), facing Range(0, 360) deg\n"
    "a = new Object behind b by Range(0, 8), facing Range(0, 360) deg\nfor at least 0.1 s\n",
    # Behaviours, one per step, and a variable in two of three steps each.
    "a = new Object on Range(-8, 8) @ Range(-8, 8), facing Range(0, 360) deg, braking\nthen within 0.3 s\n"
    "a = new Object on Range(-8, 8) @ Range(-8, 8), facing Range(0, 360) deg, stopping\n"
    "b = new Object on Range(-8, 8) @ Range(-8, 8), facing Range(0, 360) deg\nthen\n"
    "b = new Object on Range(-8, 8) @ Range(-8, 8), facing Range(0, 360) deg, accelerating\n",
    "a = new Object on Range(-8, 8) @ Range(-8, 8), facing Range(0, 360) deg, accelerating, braking\n",
] + [f"a = new Object on Range(-8, 8) @ Range(-8, 8), facing Range(0, 360) deg, {b}\n"
     for b in ("accelerating", "braking", "stopping")]

_box = st.tuples(st.sampled_from("abcd"), st.integers(-8, 8), st.integers(-8, 8),
                 st.sampled_from([None, 0.0, 0.5, 1.0, 2.0]))  # differences of exactly 1 m/s are common
_frame = st.tuples(st.lists(_box, max_size=4, unique_by=lambda b: b[0]), st.integers(1, 2), st.integers(0, 3))


def random_frames(scenes) -> pd.DataFrame:
    """Scenes of random tracks that come and go; frame indices step by 1 or 2, timestamps by 100 ms (sometimes
    another 100 ms or 300 ms on top: uneven gaps)."""
    return track_frames(scenes, lambda extra: 100_000 * (1 + (extra == 3) + 2 * (extra == 2)))


def track_frames(scenes, gap_us, world_heading: bool = False) -> pd.DataFrame:
    """The frames of `scenes` (per frame: boxes (track, x, y, speed[, map_heading]), index step, `extra`), each
    frame `gap_us(extra)` after the one before; with `world_heading`, every row has a map_heading (ego's 0)."""
    rows = []
    for s, frames in enumerate(scenes):
        index, t = 0, 0
        for boxes, step, extra in frames:
            index, t = index + step, t + gap_us(extra)
            ego = dict(frame_id=f"s{s}/{index}", source="test", scene=f"s{s}", frame_index=index, timestamp_us=t,
                       entity_id="ego", track_id="ego", type="Car", category="Car", x=0.0, y=0.0, heading=0.0,
                       length=None, width=None, is_ego=True, speed=3.0, **({"map_heading": 0.0} if world_heading else {}))
            rows.append(ego)
            for k, (track, x, y, v, *h) in enumerate(boxes, start=1):
                rows.append(dict(ego, entity_id=f"car_{track}", track_id=track, x=float(x), y=float(y),
                                 heading=float(30 * k), is_ego=False, speed=v, **({"map_heading": h[0]} if h else {})))
    return pd.DataFrame(rows)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(st.lists(_frame, min_size=1, max_size=9), min_size=1, max_size=2), st.sampled_from(STEPS))
def test_random_tracks_are_the_brute_force(tmp_path, scenes, text):
    here = Path(tempfile.mkdtemp(dir=tmp_path))
    path = here / "frames.parquet"
    write_frames(random_frames(scenes), path)
    assert engine_temporal(path, text, here) == brute_temporal(read_frames(path), parse_temporal(text))


def test_boundaries_by_hand(tmp_path):
    """for at least 0.2 s over frames 100 ms apart: the third frame of a run is the first to qualify; a gap in the
    track (a frame without it) starts the run again; `within 0.2 s` admits a gap of exactly 0.2 s, not 0.3 s."""
    near = [("a", 0, 5, 1.0)]
    scenes = [[(near, 1, 0), (near, 1, 0), (near, 1, 0), ([], 1, 0), (near, 1, 0), (near, 1, 0), (near, 1, 0)]]
    path = tmp_path / "f.parquet"
    write_frames(random_frames(scenes), path)
    got = engine_temporal(path, STEPS[0], tmp_path)
    assert got == {"s0/3": {("a",)}, "s0/7": {("a",)}}
    left, ahead = [("a", -5, 0, 1.0)], [("a", 0, 5, 1.0)]
    for extra, expect in ((1, True), (2, False)):  # gap to the next frame: 200 ms, then 300 ms
        scenes = [[(left, 1, 0), (ahead, 1, extra)]]
        path = tmp_path / f"g{extra}.parquet"
        write_frames(random_frames(scenes), path)
        assert bool(engine_temporal(path, STEPS[1], tmp_path)) is expect


def _series(speeds: list[float | None], extra: int = 0) -> pd.DataFrame:
    """One track ahead of ego over frames 100 ms apart (the last one `extra` * 100 ms later still)."""
    frames = [([("a", 0, 5, v)] if v is not None else [], 1, 0) for v in speeds]
    frames[-1] = (frames[-1][0], 1, extra)
    return random_frames([frames])


@pytest.mark.parametrize("behaviour,speeds,extra,expect", [
    ("braking", [2.0] + [1.5] * 9 + [1.0], 0, True),  # 2.0 exactly 1 s before 1.0
    ("braking", [2.0] + [1.5] * 9 + [1.0], 3, False),  # 1.1 s before
    ("braking", [2.0] + [1.5] * 9 + [1.01], 0, False),  # a change of 0.99 m/s
    ("accelerating", [0.0] + [None] * 9 + [1.0], 0, True),  # the track has gaps: only its own frames count
    ("accelerating", [0.0] * 10 + [0.99], 0, False),
    ("stopping", [1.0] + [0.7] * 29 + [0.5], 0, True),  # moving exactly 3 s before, stationary (<= v_stop) now
    ("stopping", [1.0] + [0.7] * 29 + [0.5], 3, False),
    ("stopping", [0.99] + [0.7] * 29 + [0.5], 0, False),
])
def test_behaviour_boundaries_by_hand(tmp_path, behaviour, speeds, extra, expect):
    path = tmp_path / "f.parquet"
    write_frames(_series(speeds, extra), path)
    text = f"a = new Object ahead of ego by Range(0, 8), facing Range(0, 360) deg, {behaviour}\n"
    last = f"s0/{len(speeds)}"
    got = engine_temporal(path, text, tmp_path)
    assert (last in got) is expect
    assert got == brute_temporal(read_frames(path), parse_temporal(text))


# ----------------------------------------------------------------------------------------- syntax and errors

def test_plain_patterns_stay_one_frame_patterns():
    from synth.patterns.one_frame import Pattern

    assert isinstance(parse_query_pattern("p = new Object ahead of ego by Range(0, 5), facing toward ego\n"), Pattern)
    assert not is_temporal("p = new Object ahead of ego by Range(0, 5), facing toward ego, stationary\n")


@pytest.mark.parametrize("text,says", [
    ("a = new Car ahead of ego by Range(0, 5), facing toward ego\nthen\n"
     "b = new Car ahead of ego by Range(0, 5), facing toward ego\n", "line 1: 'a' is mentioned in one step only"),
    ("a = new Car ahead of ego by Range(0, 5), facing toward ego\nfor at least -1 s\n", "line 2: a duration is"),
    ("a = new Car ahead of ego by Range(0, 5), facing toward ego\nthen within nan s\n"
     "a = new Car ahead of ego by Range(0, 5), facing toward ego\n", "line 2: a duration is"),
    ("ego braking\n", "line 1: a step declares at least one name"),
    ("then\na = new Car ahead of ego by Range(0, 5), facing toward ego\n", "line 1: `then` follows no step"),
    ("a = new Car ahead of ego by Range(0, 5), facing toward ego\nthen\n", "ends with `then`"),
    ("a = new Car ahead of ego by Range(0, 5), facing toward ego\nfor at least 1 s\n"
     "a = new Car ahead of ego by Range(0, 5), facing toward ego\n", "line 3: a statement after `for at least`"),
    ("a = new Car ahead of ego by Range(0, 5), facing toward ego\nthen soon\n"
     "a = new Car ahead of ego by Range(0, 5), facing toward ego\n", "line 2: expected `then`"),
    ("a = new Car ahead of ego by Range(0, 5), facing toward ego, braking\nthen\n"
     "a = new Car ahead of zz by Range(0, 5), facing toward ego\n", "line 3 column"),
])
def test_bad_temporal_patterns_are_one_line(text, says):
    with pytest.raises(DslError, match=None) as err:
        parse_temporal(text)
    assert says in str(err.value), str(err.value)


def test_the_verb_refuses_with_one_line(tmp_path):
    pattern = tmp_path / "p.dsl"
    pattern.write_text("a = new Car ahead of ego by Range(0, 5), facing toward ego\nfor at least -2 s\n")
    out = tmp_path / "m.parquet"
    keyframes = ROOT / "data" / "nuscenes-mini-keyframes" / "frames.parquet"
    assert_one_line_error(run_r2s("query", str(keyframes), str(pattern), "--out", str(out)), 2, "line 2")
    # A behaviour over frames without timestamps (or without speeds) is refused before anything is written.
    frames = read_frames(keyframes)
    frames["timestamp_us"] = None
    frames["speed"] = 1.0
    untimed = tmp_path / "untimed.parquet"
    write_frames(frames, untimed)
    pattern.write_text(SHIPPED["vehicle-braking-ahead.dsl"])
    assert_one_line_error(run_r2s("query", str(untimed), str(pattern), "--out", str(out)), 2, "timestamps")
    assert_one_line_error(run_r2s("query", str(keyframes), str(pattern), "--out", str(out)), 2, "speed")
    assert not out.exists()


# ----------------------------------------------------------------------------------------- turning

TURNS = [f"a = new Object on Range(-60, 60) @ Range(-60, 60) relative to ego, facing Range(0, 360) deg, {b}\n"
         for b in ("turning left", "turning right")] + [
    "a = new Object on Range(-8, 8) @ Range(-8, 8), facing Range(0, 360) deg, turning left\nthen within 1 s\n"
    "a = new Object on Range(-8, 8) @ Range(-8, 8), facing Range(0, 360) deg, turning right, braking\n"]


@pytest.fixture(scope="module")
def mapped_frames(tmp_path_factory):
    """Frames as `r2s extract` writes them, with each entity's place in its map (map_heading): the shipped
    ScenarioNet excerpt, and /work/shared/data's nuScenes mini scenes when present."""
    out = {}
    for name, path in (("excerpt", EXCERPT / "scenarionet"), ("shared-nuscenes", SHARED / "nuscenes-mini" / "scenarionet")):
        if path.exists():
            target = tmp_path_factory.mktemp(name) / "frames.parquet"
            result = run_r2s("extract", "scenarionet", str(path), "--out", str(target))
            assert result.returncode == 0, result.stderr
            out[name] = target
    return out


@pytest.mark.parametrize("data", ["excerpt", "shared-nuscenes"])
@pytest.mark.parametrize("k", range(2))
def test_turning_on_real_scenes_is_the_brute_force(mapped_frames, data, k, tmp_path):
    if data not in mapped_frames:
        pytest.skip(f"{data}: /work/shared/data is not on this machine")
    frames = mapped_frames[data]
    got = engine_temporal(frames, TURNS[k], tmp_path)
    assert got == brute_temporal(read_frames(frames), parse_temporal(TURNS[k]))
    if data == "shared-nuscenes":
        assert len(got) > 20  # vehicles do turn in the six scenes (69 frames left, 57 right)


# Headings in the world that put turns exactly on +-30 degrees and across the wrap (350 -> 20 is +30).
_world = st.sampled_from([None, 0.0, 29.5, 30.0, 60.0, 180.0, 210.0, 330.0, 350.0, 20.0, -30.0, 390.0, 1e-9])
_turn_box = st.tuples(st.sampled_from("ab"), st.integers(-8, 8), st.integers(-8, 8), st.sampled_from([None, 0.0, 1.0, 2.0]),
                      _world)
_turn_frame = st.tuples(st.lists(_turn_box, max_size=3, unique_by=lambda b: b[0]), st.integers(1, 2),
                        st.sampled_from([0, 0, 1, 2, 10, 20]))


def turning_frames(scenes) -> pd.DataFrame:
    """Random tracks with headings in the world; timestamps step by 100 ms, sometimes 1 s or 2 s more (the 3 s
    window met exactly and passed)."""
    return track_frames(scenes, lambda extra: 100_000 * (1 + extra), world_heading=True)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(st.lists(_turn_frame, min_size=1, max_size=9), min_size=1, max_size=2), st.sampled_from(TURNS))
def test_turning_on_random_tracks_is_the_brute_force(tmp_path, scenes, text):
    here = Path(tempfile.mkdtemp(dir=tmp_path))
    path = here / "frames.parquet"
    frames = turning_frames(scenes)
    write_frames(frames, path)
    if not frames[~frames.is_ego].map_heading.notna().any():  # no heading in the world at all: refused
        with pytest.raises(FramesError, match="turning needs"):
            engine_temporal(path, text, here)
        return
    assert engine_temporal(path, text, here) == brute_temporal(read_frames(path), parse_temporal(text))


@pytest.mark.parametrize("behaviour,headings,extra,expect", [
    ("turning left", [0.0, 10.0, 30.0], 0, True),  # exactly 30 degrees
    ("turning left", [0.0, 10.0, 29.999], 0, False),
    ("turning left", [350.0, 20.0], 0, True),  # across the wrap: +30
    ("turning right", [20.0, 350.0], 0, True),
    ("turning left", [20.0, 350.0], 0, False),
    ("turning right", [0.0] + [None] * 29 + [330.0], 0, True),  # 3 s before exactly; the track's own rows count
    ("turning right", [0.0] + [None] * 29 + [330.0], 1, False),  # 3.1 s before
    ("turning right", [0.0, 180.0], 0, True),  # half a turn is -180 (to the right), by the definition
])
def test_turning_boundaries_by_hand(tmp_path, behaviour, headings, extra, expect):
    frames = [([("a", 0, 5, 1.0, h)] if h is not None else [], 1, 0) for h in headings]
    frames[-1] = (frames[-1][0], 1, extra)
    path = tmp_path / "f.parquet"
    write_frames(turning_frames([frames]), path)
    text = f"a = new Object ahead of ego by Range(0, 8), facing Range(0, 360) deg, {behaviour}\n"
    got = engine_temporal(path, text, tmp_path)
    assert (f"s0/{len(headings)}" in got) is expect
    assert got == brute_temporal(read_frames(path), parse_temporal(text))


def test_turning_without_headings_in_the_world_is_one_line(tmp_path):
    pattern = tmp_path / "p.dsl"
    pattern.write_text(TURNS[0])
    out = tmp_path / "m.parquet"
    keyframes = ROOT / "data" / "nuscenes-mini-keyframes" / "frames.parquet"  # no map_heading column
    assert_one_line_error(run_r2s("query", str(keyframes), str(pattern), "--out", str(out)), 2,
                          "turning needs each track's heading in the world")
    frames = turning_frames([[([("a", 0, 5, 1.0, None)], 1, 0)] * 3])  # the column, never a value
    path = tmp_path / "f.parquet"
    write_frames(frames, path)
    assert_one_line_error(run_r2s("query", str(path), str(pattern), "--out", str(out)), 2, "map_heading")
    assert not out.exists()


@pytest.mark.parametrize("behaviour,before,now", [("braking", (2.0, None), (1.0, None)),
                                                  ("accelerating", (0.0, None), (1.0, None)),
                                                  ("turning left", (1.0, 0.0), (1.0, 30.0)),
                                                  ("turning right", (1.0, 30.0), (1.0, 0.0))])
def test_behaviours_read_rows_where_the_step_does_not_hold(tmp_path, behaviour, before, now):
    """A behaviour reads every row of the track in its window, also those of frames where the step's statements
    do not hold (the engine reads behaviours only for the tracks a step binds, but all of their rows): here the
    earlier row is 50 m ahead, outside the step's 0..8 m."""
    frames = [([("a", 0, 50, *before)], 1, 0), ([("b", 0, 50, 1.0, 0.0)], 1, 0), ([("a", 0, 5, *now)], 1, 0)]
    path = tmp_path / "f.parquet"
    write_frames(turning_frames([frames]), path)
    text = f"a = new Object ahead of ego by Range(0, 8), facing Range(0, 360) deg, {behaviour}\n"
    got = engine_temporal(path, text, tmp_path)
    assert got == {"s0/3": {("a",)}}
    assert got == brute_temporal(read_frames(path), parse_temporal(text))


@pytest.mark.parametrize("behaviour,column,before,now", [("braking", "speed", 2.0, 1.0),
                                                         ("accelerating", "speed", 0.0, 1.0),
                                                         ("turning left", "map_heading", 0.0, 30.0),
                                                         ("turning right", "map_heading", 30.0, 0.0)])
def test_ego_behaviours_read_rows_where_the_step_does_not_hold(tmp_path, behaviour, column, before, now):
    """Ego's behaviour reads every ego row of the scene in its window, also those of frames where the step's
    statements do not hold (the engine reads ego's rows only in the scenes where such a step holds): here the
    earlier frame has its track 50 m ahead, outside the step's 0..8 m, and a frame between has none."""
    frames = turning_frames([[([("a", 0, 50, 1.0, 0.0)], 1, 0), ([("b", 0, 50, 1.0, 0.0)], 1, 0),
                              ([("a", 0, 5, 1.0, 0.0)], 1, 0)]])
    ego = frames.index[frames.is_ego]
    frames.loc[ego, column] = [before, before, now]
    path = tmp_path / "f.parquet"
    write_frames(frames, path)
    text = f"a = new Object ahead of ego by Range(0, 8), facing Range(0, 360) deg\nego {behaviour}\n"
    got = engine_temporal(path, text, tmp_path)
    assert got == {"s0/3": {("a",)}}
    assert got == brute_temporal(read_frames(path), parse_temporal(text))
