"""Lanes in programs over a window (synth.window.program with `--lanes`): every lane clause holds in every frame of its
entity per the checker, frame programs are certified, and the cost is the least against an independent brute force
(tests/support/window_bruteforce.py over tests/support/lanes.py's lane relations) on random roads with entities
moving across lanes, on the shipped nuScenes excerpt with its road and, when present, on ../shared/data's
nuScenes-mini and Argoverse 2 log with their maps. Also: a relation the frames agree on that no frame's table
records first (two lanes merging), the window's fallback from every frame's place, and Scenic text."""

from __future__ import annotations

import random
from dataclasses import replace
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from synth import SynthConfig, check_window, synthesize, synthesize_window
from synth.dsl import parse_program
from synth.parts.lane import LANE, Anywhere, InLane, LaneFact, LanesMissing
from synth.road.roadmap import MapFeature, RoadMap
from synth.scene import Scene, make_scene
from tests.support.lanes import placed, random_road
from tests.support.road_windows import road_windows
from tests.support.window_bruteforce import optimal_window_cost


def random_lane_clip(rng: random.Random, n: int, frames: int) -> list[Scene]:
    """A random road (tests.support.lanes) and n entities moving on it from frame to frame: cars along a lane at a
    random pace, some drifting across lanes, pedestrians anywhere; each present in a run of frames or a random
    subset of them. Lane facts are recomputed in every frame from where each entity is."""
    road = random_road(rng)
    lanes = [f for f in road.lanes if not f.is_intersection]
    tracks = []
    for i in range(1, n + 1):
        kind = rng.choice(["Car", "Car", "Car", "Pedestrian"])
        if kind == "Car" and rng.random() < 0.85:
            f = rng.choice(lanes)
            (xa, ya), (xb, yb) = f.line[0], f.line[-1]
            t = rng.random()
            x, y = xa + t * (xb - xa) + rng.uniform(-1, 1), ya + t * (yb - ya)
            way = 1.0 if yb > ya else -1.0
            heading = (0.0 if way > 0 else 180.0) + rng.uniform(-10, 10)
            step = (rng.choice([0.0, 0.0, rng.uniform(-2.5, 2.5)]), way * rng.uniform(0, 12), rng.uniform(-3, 3))
        else:
            x, y, heading = rng.uniform(-12, 12), rng.uniform(-50, 65), rng.uniform(0, 360)
            step = (rng.uniform(-2, 2), rng.uniform(-2, 2), rng.uniform(-20, 20))
        if rng.random() < 0.6:
            a = rng.randrange(frames)
            present = set(range(a, rng.randrange(a, frames) + 1))
        else:
            present = {k for k in range(frames) if rng.random() < 0.7} or {0}
        tracks.append((f"{kind.lower()}{i}", kind, x, y, heading, step, present))
    out = []
    for k in range(frames):
        ents = [{"id": "ego", "type": "Car", "x": 0.0, "y": 0.0, "heading": 0.0}]
        for eid, kind, x, y, h, (dx, dy, dh), present in tracks:
            if k in present:
                ents.append({"id": eid, "type": kind, "x": round(x + dx * k, 2), "y": round(y + dy * k, 2),
                             "heading": round((h + dh * k) % 360, 1)})
        out.append(make_scene(f"lanes/{k}", placed(road, ents), road))
    return out


def assert_optimal_window(scenes: list[Scene], config: SynthConfig) -> None:
    """Every frame's program holds in its frame (r2s check), every statement carries a lane clause, the program
    reads back as printed, it is certified where a solver is at hand, and it costs the brute force's optimum."""
    result = synthesize_window(scenes, config)
    for scene, verdict in zip(scenes, check_window(result.program, scenes, config)):
        assert verdict.ok, (scene.frame_id, [str(v) for v in verdict.violations][:3], str(result.program))
    assert all(s.lane is not None for s in result.program.statements)
    assert parse_program(str(result.program)) == result.program
    assert result.certified == (config.oracle != "closed-form")
    assert result.status == "optimal"
    assert result.cost == result.program.cost == optimal_window_cost(scenes, config), str(result.program)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(0, 7), frames=st.integers(1, 4),
       oracle=st.sampled_from(["hybrid", "closed-form", "smt"]),
       strategy=st.sampled_from(["auto", "astar-cpa", "dfs-bnb-cpa", "bfs-cpa"]))
def test_random_lane_clips_are_consistent_and_optimal(seed, n, frames, oracle, strategy):
    scenes = random_lane_clip(random.Random(seed), n, frames)
    assert_optimal_window(scenes, SynthConfig(lanes=True, oracle=oracle, strategy=strategy))


def test_random_lane_clips_cover_every_kind_of_window_lane_clause():
    """The random clips exercise what the window adds (the test above can fail): lane witnesses over several
    frames, facts held throughout, one lane throughout, and entities that change lanes (anywhere)."""
    kinds = set()
    for seed in range(30):
        scenes = random_lane_clip(random.Random(seed), 6, 3)
        result = synthesize_window(scenes, SynthConfig(lanes=True))
        assert result.cost == optimal_window_cost(scenes, SynthConfig(lanes=True)), seed
        kinds |= {type(s.lane).__name__ if s.lane.ref is None else "relation" for s in result.program.statements}
    assert kinds >= {"relation", "LaneFact", "InLane", "Anywhere"}, kinds


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 6), frames=st.integers(2, 3))
def test_random_lane_clips_with_motion(seed, n, frames):
    rng = random.Random(seed)
    scenes = random_lane_clip(rng, n, frames)
    speeds = {e.id: rng.choice([0.0, 0.3, rng.uniform(0, 15)]) for s in scenes for e in s.entities}
    moving = [Scene(s.frame_id, tuple(replace(e, speed=speeds[e.id] + 0.4 * k) for e in s.entities), s.road)
              for k, s in enumerate(scenes)]
    assert_optimal_window(moving, SynthConfig(lanes=True, motion=True))


def test_robust_lane_windows_are_certified_in_every_frame():
    """With an uncertainty, each frame's lane clause is certified robust on its frame (every violation unsat:
    the clause holds wherever the entity may be), and no window is cheaper than its plain counterpart."""
    config = SynthConfig(lanes=True, pos_uncertainty=0.6, heading_uncertainty=3.0)
    kinds = set()
    for seed in range(8):
        scenes = random_lane_clip(random.Random(300 + seed), 5, 3)
        result = synthesize_window(scenes, config)
        assert result.certified and result.status == "optimal"
        assert all(v.ok for v in check_window(result.program, scenes, config))
        assert result.cost >= synthesize_window(scenes, SynthConfig(lanes=True)).cost
        kinds |= {str(s.lane).split(" ")[0] for s in result.program.statements}
    assert len(kinds) > 1, kinds


# ------------------------------------------------------------------------------------------------ by hand


def _lane(fid: str, x0: float, y0: float, y1: float, **links) -> MapFeature:
    """A northbound lane 3.5 m wide from y0 to y1, centred on x0."""
    return MapFeature("m", fid, "lane", ((x0 - 1.75, y0), (x0 + 1.75, y0), (x0 + 1.75, y1), (x0 - 1.75, y1)),
                      ((x0, y0), (x0, (y0 + y1) / 2), (x0, y1)), **links)


def merge_road() -> RoadMap:
    """Two northbound lanes side by side, `a` (ego's) and `b` on its left, that merge into one lane `m` ahead
    (both have m as successor): m is on a's chain and on b's, so a car in m is `in lane of` a car in a and
    `in lane left of` it at once; a crosswalk and an intersection over m."""
    return RoadMap.of("m", [
        _lane("a", 0.0, -20.0, 20.0, left="b", successors=("m",)),
        _lane("b", -3.5, -20.0, 20.0, right="a", successors=("m",)),
        _lane("m", -1.75, 20.0, 60.0),
        MapFeature("m", "x1", "intersection", ((-6.0, 40.0), (3.0, 40.0), (3.0, 50.0), (-6.0, 50.0))),
        MapFeature("m", "c1", "crosswalk", ((-6.0, 44.0), (3.0, 44.0), (3.0, 56.0), (-6.0, 56.0))),
        MapFeature("m", "d1", "drivable_area", ((-8.0, -25.0), (5.0, -25.0), (5.0, 65.0), (-8.0, 65.0))),
    ])


def merge_clip(*car_places: tuple[float, float]) -> list[Scene]:
    road = merge_road()
    return [make_scene(f"merge/{k}", placed(road, [{"id": "ego", "type": "Car", "x": 0.0, "y": 0.0, "heading": 0.0},
                                                   {"id": "car1", "type": "Car", "x": x, "y": y, "heading": 0.0}]),
                       road) for k, (x, y) in enumerate(car_places)]


def test_a_relation_the_frames_agree_on_that_no_frame_records_first():
    """car1 is in m (on ego's chain and on its left neighbour's: the table records `same lane`), then in b
    (`lane left` only): `in lane left of ego` holds in both frames, cost 0; a table that kept only the recorded
    relation of each frame would find no witness."""
    scenes = merge_clip((-1.75, 30.0), (-3.5, 10.0))
    assert [s.others[0].lane for s in scenes] == ["m", "b"]
    config = SynthConfig(lanes=True)
    assert str(synthesize(scenes[0], config).program.statements[0].lane) == "in lane of ego"
    result = synthesize_window(scenes, config)
    assert str(result.program.statements[0].lane) == "in lane left of ego"
    assert result.cost == optimal_window_cost(scenes, config) == 2  # position and heading: no witness
    assert all(v.ok for v in check_window(result.program, scenes, config))


@pytest.mark.parametrize("oracle", ["hybrid", "smt", "closed-form"])
def test_the_merge_under_uncertainty_with_every_oracle(oracle):
    """The same under a position uncertainty that keeps car1 in its lane in both frames: every oracle finds the
    robust `in lane left of ego` (the closed-form one too: lane questions need no solver)."""
    scenes = merge_clip((-1.75, 30.0), (-3.5, 10.0))
    config = SynthConfig(lanes=True, oracle=oracle, pos_uncertainty=0.3)
    result = synthesize_window(scenes, config)
    assert str(result.program.statements[0].lane) == "in lane left of ego"
    assert result.certified == (oracle != "closed-form")
    assert all(v.ok for v in check_window(result.program, scenes, config))


def test_the_window_fallback_reads_every_frame():
    """In the intersection and on the crosswalk, then on the crosswalk only: `on crosswalk` (each frame alone
    would write `in intersection` first); in one lane throughout: that lane; in two lanes: anywhere."""
    config = SynthConfig(lanes=True)
    both, crosswalk_only = merge_clip((-1.75, 46.0), (-1.75, 53.0))
    assert LANE.fallback(both.others[0], config, robust=False) == LaneFact("intersection")
    assert LANE.window_fallback([both.others[0], crosswalk_only.others[0]], config) == LaneFact("crosswalk")
    still, moved = merge_clip((-3.5, -10.0), (-3.5, 10.0))
    assert LANE.window_fallback([still.others[0], moved.others[0]], config) == InLane("b")
    _, other = merge_clip((-3.5, -10.0), (0.0, 10.0))
    assert LANE.window_fallback([still.others[0], other.others[0]], config) == Anywhere()
    assert LANE.window_fallback_cost([still.others[0], other.others[0]], config) == 2
    assert LANE.window_fallback_cost([both.others[0], crosswalk_only.others[0]], config) == 1
    # a frame's own fallback is the window of that frame alone
    for e in (both.others[0], still.others[0]):
        assert LANE.window_fallback([e], config) == LANE.fallback(e, config, robust=False)


def test_a_frame_without_a_road_is_refused_in_one_line():
    scenes = merge_clip((-3.5, -10.0), (-3.5, 10.0))
    bare = Scene(scenes[1].frame_id, scenes[1].entities, None)
    with pytest.raises(LanesMissing, match="has no road"):
        synthesize_window([scenes[0], bare], SynthConfig(lanes=True))


def test_scenic_of_a_window_program_with_lanes_compiles_on_official_scenic():
    """As a single-frame lane program's does (tests/synth/scenic/test_scenic_road.py): the road's regions and one
    requirement per lane clause, compiled by Scenic 3 itself."""
    scenic = pytest.importorskip("scenic", reason="official Scenic is not installed (pip install scenic)")
    scenes = random_lane_clip(random.Random(5), 6, 3)
    result = synthesize_window(scenes, SynthConfig(lanes=True))
    requirements = [s for s in result.program.statements if not isinstance(s.lane, Anywhere)]
    assert requirements and result.scenic.count("require road__") >= len(requirements)
    scenic.scenarioFromString(result.scenic, mode2D=True)


# ------------------------------------------------------------------------------------------------ real data


def nearest(scenes: list[Scene], k: int) -> list[Scene]:
    """A real clip cut down to the k entities nearest ego in its first frame (the brute force is exponential)."""
    keep = {e.id for e in sorted(scenes[0].others, key=lambda e: (e.x * e.x + e.y * e.y, e.id))[:k]}
    return [Scene(s.frame_id, (s.ego,) + tuple(e for e in s.others if e.id in keep), s.road) for s in scenes]


def assert_real_windows(windows: list[list[Scene]]) -> None:
    """Every window holds in each frame, certified and optimal, no cheaper than its dearest frame alone; its
    nearest entities, as a small clip, cost the brute force's optimum."""
    config = SynthConfig(lanes=True)
    assert windows and any(len(w) > 1 for w in windows)
    for scenes in windows:
        result = synthesize_window(scenes, config)
        assert result.certified and result.status == "optimal"
        for scene, verdict in zip(scenes, check_window(result.program, scenes, config)):
            assert verdict.ok, (scene.frame_id, [str(v) for v in verdict.violations][:3])
        assert result.cost >= max(synthesize(s, config).cost for s in scenes)
        assert_optimal_window(nearest(scenes, 8), config)


@pytest.mark.parametrize("window_s", [1.0, 2.0])
def test_the_shipped_excerpt_with_its_road(excerpt_frames, window_s):
    assert_real_windows(road_windows(excerpt_frames, window_s))


@pytest.fixture(scope="module")
def shared_road_frames(shared_dir, tmp_path_factory) -> dict[str, Path]:
    """../shared/data's nuScenes-mini (ScenarioNet) and Argoverse 2 test log, extracted with their maps."""
    from tests.support import run_r2s

    out = {}
    for name, source, path in (
            ("nuscenes", "scenarionet", shared_dir / "data" / "nuscenes-mini" / "scenarionet"),
            ("av2", "argoverse2", shared_dir / "data" / "argoverse2" / "test_data" / "sensor_dataset_logs"
             / "adcf7d18-0510-35b0-a2fa-b4cea13a6d76")):
        if not path.exists():
            pytest.skip(f"{path} not found in the shared data")
        out[name] = tmp_path_factory.mktemp(name) / "frames"
        proc = run_r2s("extract", source, str(path), "--categories", "all", "--out", str(out[name]))
        assert proc.returncode == 0, proc.stderr
    return out


@pytest.mark.parametrize("name,window_s,limit", [("nuscenes", 2.0, 1), ("av2", 1.0, 2)])
def test_shared_clips_with_their_maps(shared_road_frames, name, window_s, limit):
    assert_real_windows(road_windows(shared_road_frames[name], window_s, limit))
