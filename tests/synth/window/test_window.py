"""Programs over a window (synth.window.program): consistent in every frame per the checker, certified frame by frame,
optimal against an independent brute force (tests/support/window_bruteforce.py) on random and real small clips,
and how windows tile a scene's timestamps."""

from __future__ import annotations

import random

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from synth import SynthConfig, check_window, frame_program, synthesize, synthesize_window, tile
from synth.config import ConfigError
from synth.parts.heading import RelativeHeading
from synth.parts.position import DirectionPos, LocalXYPos
from synth.scene import Scene, scene_from_dict
from synth.syntax import Range
from synth.window.program import WindowError
from tests.support import ROOT
from tests.support.bruteforce import random_speed
from tests.support.window_bruteforce import optimal_window_cost

KEYFRAMES = ROOT / "data" / "nuscenes-mini-keyframes" / "frames.parquet"
AV2 = ROOT / "data" / "argoverse2-log-excerpt" / "frames.parquet"


def random_clip(rng: random.Random, n: int, frames: int, speeds: bool = False) -> list[Scene]:
    """A street-like clip: entities in lanes moving a little from frame to frame (a heading near the lane axis, or
    anywhere), each present in a run of frames or a random subset of them (an entity leaves and comes back)."""
    ents = []
    for i in range(1, n + 1):
        lane = rng.choice([-7.0, -3.5, 0.0, 3.5, 7.0])
        heading = rng.choice([0.0, 90.0, 180.0, 270.0]) + rng.uniform(-6, 6) if rng.random() < 0.8 else rng.uniform(0, 360)
        if rng.random() < 0.5:
            a = rng.randrange(frames)
            present = set(range(a, rng.randrange(a, frames) + 1))
        else:
            present = {k for k in range(frames) if rng.random() < 0.7} or {0}
        ents.append((f"{rng.choice(['car', 'ped'])}{i}", lane + rng.uniform(-1, 1), rng.uniform(-30, 30), heading,
                     rng.uniform(-1.5, 1.5), rng.uniform(-2, 2), rng.uniform(-4, 4), present))
    out = []
    for k in range(frames):
        entities = [{"id": "ego", "type": "Car", "x": 0.0, "y": 0.0, "heading": 0.0}]
        for eid, x, y, h, dx, dy, dh, present in ents:
            if k in present:
                entities.append({"id": eid, "type": "Car" if eid.startswith("car") else "Pedestrian",
                                 "x": x + dx * k, "y": y + dy * k, "heading": (h + dh * k) % 360})
        if speeds:
            for e in entities:
                e["speed"] = random_speed(rng)
        out.append(scene_from_dict({"frame_id": f"clip/{k}", "entities": entities}))
    return out


def assert_window_program(scenes: list[Scene], config: SynthConfig) -> None:
    """The window program holds in every frame of its window (r2s check's semantics on each frame's program),
    is certified where a solver is at hand, and costs what the brute force says is the least."""
    result = synthesize_window(scenes, config)
    for scene, verdict in zip(scenes, check_window(result.program, scenes, config)):
        assert verdict.ok, (scene.frame_id, [str(v) for v in verdict.violations], str(result.program))
    assert result.certified == (config.oracle != "closed-form")
    assert result.status == "optimal"
    assert result.cost == optimal_window_cost(scenes, config), str(result.program)
    assert result.frame_ids == tuple(s.frame_id for s in scenes)
    assert result.n_entities == len({e.id for s in scenes for e in s.others})


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(0, 8), frames=st.integers(1, 4),
       oracle=st.sampled_from(["hybrid", "closed-form", "smt"]),
       strategy=st.sampled_from(["auto", "astar-cpa", "dfs-bnb-cpa", "bfs-cpa"]))
def test_random_clips_are_consistent_and_optimal(seed, n, frames, oracle, strategy):
    scenes = random_clip(random.Random(seed), n, frames)
    assert_window_program(scenes, SynthConfig(oracle=oracle, strategy=strategy))


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 7), frames=st.integers(2, 4))
def test_random_clips_with_motion(seed, n, frames):
    scenes = random_clip(random.Random(seed), n, frames, speeds=True)
    assert_window_program(scenes, SynthConfig(motion=True))


def test_a_masked_relation_still_counts():
    """Stationary is recorded over `moving like ego` in ego's row; a window whose frames agree only on the latter
    (stationary, then not) still has ego as its witness."""
    frames = [scene_from_dict({"frame_id": f"m/{k}", "entities": [
        {"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0, "speed": 0.8},
        {"id": "car1", "type": "Car", "x": 0, "y": 10 + k, "heading": 0, "speed": v}]}) for k, v in enumerate((0.3, 1.2))]
    result = synthesize_window(frames, SynthConfig(motion=True))
    assert str(result.program.statements[0].motion) == "moving like ego"
    assert result.cost == optimal_window_cost(frames, SynthConfig(motion=True)) == 0


def test_one_frame_is_the_single_frame_program():
    from tests.support import shipped_frames

    for scene in shipped_frames()[:3]:
        assert str(synthesize_window([scene]).program) == str(synthesize(scene).program)


def test_an_entity_in_part_of_the_window_is_declared_for_its_frames():
    """car2 is only in the second frame: declared, described where it is, and absent from the first frame's
    program; car1 may not be its reference's witness in a frame without car1 (it leaves)."""
    a = scene_from_dict({"frame_id": "p/0", "entities": [
        {"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0},
        {"id": "car1", "type": "Car", "x": 0, "y": 10, "heading": 0}]})
    b = scene_from_dict({"frame_id": "p/1", "entities": [
        {"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0},
        {"id": "car2", "type": "Car", "x": 0, "y": 20, "heading": 0}]})
    result = synthesize_window([a, b])
    assert [s.id for s in result.program.statements] == ["car1", "car2"]
    assert [s.id for s in frame_program(result.program, a).statements] == ["car1"]
    assert [s.id for s in frame_program(result.program, b).statements] == ["car2"]
    # car1 is behind car2 in the second frame, but car1 is not there: ego is car2's reference.
    assert result.program.statements[1].position.ref == "ego"
    assert all(v.ok for v in check_window(result.program, [a, b]))


def test_ranges_cover_every_frame():
    """Off every axis of ego, car1 is on a lateral / forward Range relative to ego: each the hull of the frames'
    Ranges; its heading offset, measured as 179 and -179 deg, is one narrow Range (the hull on the circle), not the
    whole circle."""
    frames = [scene_from_dict({"frame_id": f"r/{k}", "entities": [
        {"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0},
        {"id": "car1", "type": "Car", "x": 3, "y": y, "heading": h}]}) for k, (y, h) in enumerate(((10, 179), (14, 181)))]
    statement = synthesize_window(frames).program.statements[0]
    assert statement.position == LocalXYPos(Range(0.5, 5.5), Range(7.5, 16.5), "ego")
    assert statement.heading == RelativeHeading(Range(176.5, 183.5), "ego")
    assert all(v.ok for v in check_window(synthesize_window(frames).program, frames))


def test_widening_on_the_circle():
    mine = RelativeHeading(Range(174.5, 179.5), "ego")
    theirs = RelativeHeading(Range(-179.5, -174.5), "ego")
    assert mine.widened(theirs) == RelativeHeading(Range(174.5, 185.5), "ego")
    assert theirs.widened(mine) == RelativeHeading(Range(-185.5, -174.5), "ego")
    assert mine.widened(RelativeHeading(Range(0, 5), "car1")) is None  # another reference is another clause
    assert DirectionPos("ahead", "ego", Range(1, 2)).widened(DirectionPos("left", "ego", Range(1, 2))) is None


def test_bad_clips_are_one_line_errors():
    a = scene_from_dict({"frame_id": "b/0", "entities": [{"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0},
                                                         {"id": "x1", "type": "Car", "x": 0, "y": 9, "heading": 0}]})
    b = scene_from_dict({"frame_id": "b/1", "entities": [{"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0},
                                                         {"id": "x1", "type": "Truck", "x": 0, "y": 9, "heading": 0}]})
    for scenes, words in (([], "at least one frame"), ([a, a], "twice"), ([a, b], "is a Car in frame")):
        with pytest.raises(WindowError, match=words):
            synthesize_window(scenes)
    with pytest.raises(ConfigError, match="monolithic"):
        synthesize_window([a], {"strategy": "monolithic"})


# ------------------------------------------------------------------------------------------------ real data


def real_windows(path, window_s: float, limit: int | None = None):
    """The windows of every scene of a shipped frames file (tile over its timestamps), as lists of Scenes."""
    pq = pytest.importorskip("pyarrow.parquet")
    from frames.rows import frame_to_scene

    df = pq.read_table(path).to_pandas()
    out = []
    for _, rows in df.groupby("scene", sort=True):
        frames = rows.sort_values("frame_index")
        stamps = frames.drop_duplicates("frame_id")[["frame_id", "timestamp_us"]]
        ids, times = stamps.frame_id.tolist(), [int(t) for t in stamps.timestamp_us]
        by_frame = dict(tuple(frames.groupby("frame_id", sort=False)))
        for first, last in tile(times, int(window_s * 1e6))[:limit]:
            out.append([frame_to_scene(by_frame[f]) for f in ids[first:last + 1]])
    return out


@pytest.mark.parametrize("path,window_s,limit", [(KEYFRAMES, 1.0, 4), (KEYFRAMES, 2.0, 3), (AV2, 1.0, 5)])
def test_real_windows_hold_in_every_frame(path, window_s, limit):
    windows = real_windows(path, window_s, limit)
    assert windows and all(len(w) > 1 for w in windows)
    for scenes in windows:
        result = synthesize_window(scenes)
        assert result.certified and result.status == "optimal"
        for scene, verdict in zip(scenes, check_window(result.program, scenes)):
            assert verdict.ok, (scene.frame_id, [str(v) for v in verdict.violations][:3])
        # No window program is cheaper than its dearest frame's own optimum (each frame's program is a program).
        assert result.cost >= max(synthesize(s).cost for s in scenes)


def nearest(scenes: list[Scene], k: int) -> list[Scene]:
    """A real clip cut down to the k entities nearest ego in its first frame (the brute force is exponential)."""
    first = sorted(scenes[0].others, key=lambda e: (e.x * e.x + e.y * e.y, e.id))[:k]
    keep = {e.id for e in first}
    return [Scene(s.frame_id, (s.ego,) + tuple(e for e in s.others if e.id in keep), s.road) for s in scenes]


@pytest.mark.parametrize("path,window_s", [(KEYFRAMES, 2.0), (AV2, 1.0)])
def test_real_small_clips_are_optimal(path, window_s):
    for scenes in real_windows(path, window_s, 2):
        small = nearest(scenes, 9)
        assert_window_program(small, SynthConfig())


# ------------------------------------------------------------------------------------------------ tiling


@settings(max_examples=200, deadline=None)
@given(steps=st.lists(st.integers(1, 900_000), max_size=30), window=st.integers(1, 3_000_000),
       stride=st.none() | st.integers(1, 3_000_000), gap=st.none() | st.integers(0, 600_000))
def test_tiling(steps, window, stride, gap):
    times = [0]
    for s in steps:
        times.append(times[-1] + s)
    windows = tile(times, window, stride, gap)
    # Cut points: no window crosses a gap; a segment is every frame between two gaps.
    cuts = {i for i in range(1, len(times)) if gap is not None and times[i] - times[i - 1] > gap}
    starts = []
    for first, last in windows:
        assert first <= last
        assert not any(first < i <= last for i in cuts)
        assert times[last] - times[first] < window
        # Maximal: the next frame is beyond the window or across a gap.
        assert last + 1 == len(times) or last + 1 in cuts or times[last + 1] - times[first] >= window
        starts.append(first)
    # Windows start at each segment's first frame, then at the first frame a stride later, in order.
    expected = []
    bounds = [0, *sorted(cuts), len(times)]
    for a, b in zip(bounds, bounds[1:]):
        k = a
        while k < b:
            expected.append(k)
            k = next((j for j in range(k + 1, b) if times[j] - times[k] >= (stride or window)), b)
    assert starts == expected
    if stride is None or stride <= window:  # every frame in some window
        assert {i for first, last in windows for i in range(first, last + 1)} == set(range(len(times)))
    if stride is None:  # consecutive, not overlapping
        assert all(b[0] == a[1] + 1 for a, b in zip(windows, windows[1:]))


def test_tiling_refuses_non_positive_durations():
    for args in ((0,), (1, 0), (1, None, -1)):
        with pytest.raises(ValueError):
            tile([0, 1], *args)


def test_window_scenic_header_says_robust():
    """A window's clauses are its frames' robust ones merged, so its Scenic header says what they are robust to,
    as a frame's does; without uncertainty neither says it."""
    frames = random_clip(random.Random(3), 3, 3, speeds=True)
    robust = SynthConfig(pos_uncertainty=0.5, heading_uncertainty=2.0, motion=True, speed_uncertainty=0.25)
    header = synthesize_window(frames, robust).scenic.splitlines()[0]
    assert "robust to 0.5 m, 2 deg, 0.25 m/s" in header
    assert header.split("; robust")[1] in synthesize(frames[0], robust).scenic.splitlines()[0]
    assert "robust to" not in synthesize_window(frames).scenic
