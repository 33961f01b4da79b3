"""The road of a window (synth.window.road; docs/dsl.md, "Programs over a window"): a window program's Scenic text
stands on every frame's road brought into its first frame's ego frame, so an `in lane "ID"` of an entity first seen
in a later frame names a region of the text. Checked on a hand-made clip that the first frame's road alone fails
(a lane beyond its radius), under official Scenic 3.1.1 (compiles and samples it); against an independent brute
force from the map itself on random clips (hypothesis), over every window of the shipped nuScenes excerpt, and,
when present, over ../shared/data's nuScenes-mini 2 s windows."""

from __future__ import annotations

import json
import math
import random
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from synth import SynthConfig, check_window, synthesize_window
from synth.parts.lane import InLane
from synth.road.lane_facts import RoadIndex
from synth.road.lane_relations import LaneGraph
from synth.road.roadmap import LANE, MapFeature, RoadMap, in_ego_frame
from synth.scene import Scene, make_scene
from synth.scenic.road import DATA
from synth.window.road import WindowRoadError, window_road
from synth.world import WorldPose
from tests.support import assert_one_line_error, run_r2s
from tests.support.lanes import placed, random_road
from tests.support.road_windows import road_windows

# ------------------------------------------------------------------------------------------------ a clip by hand

ANGLE, ORIGIN = 35.0, (400.0, -250.0)  # where the road's own frame (lanes along +y) lies in the world
RADIUS = 30.0  # each frame's road: the features within 30 m of ego (and those its entities' facts name)


def to_world(x: float, y: float) -> tuple[float, float]:
    a = math.radians(ANGLE)
    return ORIGIN[0] + x * math.cos(a) - y * math.sin(a), ORIGIN[1] + x * math.sin(a) + y * math.cos(a)


def _lane(fid: str, x0: float, y0: float, y1: float, **links) -> MapFeature:
    """A lane 3.5 m wide along the road's +y from y0 to y1, centred on x0, placed in the world."""
    ring = ((x0 - 1.75, y0), (x0 + 1.75, y0), (x0 + 1.75, y1), (x0 - 1.75, y1))
    line = ((x0, y0), (x0, (y0 + y1) / 2), (x0, y1))
    return MapFeature("m", fid, LANE, tuple(to_world(*p) for p in ring), tuple(to_world(*p) for p in line), **links)


# Ego's lane chain a -> b -> c ahead, and a lane d to its right beyond a gap (no neighbour of ego's), starting 50 m
# ahead of ego's first place: beyond the first frame's road.
MAP = RoadMap.of("m", [
    _lane("a", 0.0, -30.0, 30.0, successors=("b",)),
    _lane("b", 0.0, 30.0, 90.0, successors=("c",), predecessors=("a",)),
    _lane("c", 0.0, 90.0, 150.0, predecessors=("b",)),
    _lane("d", 10.0, 50.0, 150.0),
])


def frame(k: int, ego_y: float, others: list[tuple[str, float, float]], road_map: RoadMap = MAP) -> Scene:
    """Frame k: ego at (0, ego_y) of the road's frame heading along it, cars at (x, y) heading along it; lane
    facts decided in the world on the map (as extraction does), the road as r2s scene gives it (in_ego_frame)."""
    ex, ey = to_world(0.0, ego_y)
    pose = WorldPose(ex, ey, 90.0 + ANGLE, map_id=road_map.map_id)
    world = [{"id": "ego", "type": "Car", "x": ex, "y": ey, "heading": ANGLE}]
    world += [dict(zip(("x", "y"), to_world(x, y)), id=i, type="Car", heading=ANGLE) for i, x, y in others]
    ents = placed(road_map, world)  # headings from +y in the world: a direction from +x plus 90
    road = in_ego_frame(road_map, pose.x, pose.y, pose.heading, RADIUS, [(e.x, e.y) for e in ents],
                        {lane for e in ents for lane in e.lanes})
    local = [replace(e, x=p[0], y=p[1], heading=0.0) for e in ents for p in [pose.local(e.x, e.y)]]
    return make_scene(f"w/{k}", local, road, pose)


def clip() -> list[Scene]:
    """Ego drives 5 m a frame; car2 12 m ahead in its lane throughout; car1 in lane d from frame 2 on (60 m ahead,
    10 m right: only a later frame's road holds d); car3 in lane c, on ego's chain, in the last frame."""
    return [frame(k, 5.0 * k, [("car2", 0.0, 5.0 * k + 12.0)]
                  + ([("car1", 10.0, 5.0 * k + 60.0)] if k >= 2 else [])
                  + ([("car3", 0.0, 5.0 * k + 85.0)] if k == 3 else [])) for k in range(4)]


def scenic_road(text: str) -> dict:
    """The road data of an emitted text (the JSON literal synth.scenic.road writes), read without running it."""
    start = text.index("r'''", text.index(f"\n{DATA} = ")) + 4  # a feature a line, up to the closing quotes
    return json.loads(text[start:text.index("'''", start)])


def lanes_named(program) -> set[str]:
    return {st.lane.lane for st in program.statements if isinstance(st.lane, InLane)}


def assert_where_the_map_has_them(road: RoadMap, road_map: RoadMap, pose: WorldPose, tol: float = 1e-6) -> None:
    """Every feature of a window's road is the map's, moved into the first frame's ego frame by extraction's own
    transform from the map (in_ego_frame), within tol metres."""
    want = in_ego_frame(road_map, pose.x, pose.y, pose.heading, 0.0, named={f.feature_id for f in road.features})
    assert {f.feature_id for f in road.features} == {f.feature_id for f in want.features}
    for f in road.features:
        g = want[f.feature_id]
        assert f.kind == g.kind and f.is_intersection == g.is_intersection
        for got, exp in ((f.polygon, g.polygon), (f.line, g.line)):
            assert len(got) == len(exp) and np.allclose(got, exp, rtol=0.0, atol=tol), f.feature_id


def test_a_lane_only_a_later_frame_holds_is_a_region_of_the_window_text():
    scenes = clip()
    assert "d" not in scenes[0].road and "d" in scenes[2].road  # what the first frame's road alone lacked
    config = SynthConfig(lanes=True)
    result = synthesize_window(scenes, config)
    assert all(v.ok for v in check_window(result.program, scenes, config))
    named = lanes_named(result.program)
    assert "d" in named, str(result.program)
    data = scenic_road(result.scenic)
    assert named <= set(data["road__lanes"])
    road = window_road(scenes)
    assert_where_the_map_has_them(road, MAP, scenes[0].world)
    assert {i: f["polygon"] for i, f in data["road__lanes"].items()} == {
        f.feature_id: [c for p in f.polygon for c in p] for f in road.lanes}
    # the chain a -> b -> c: the first frame's road drops b's link to c (beyond it), the last frame's has it
    assert scenes[0].road["b"].successors == () and road["b"].successors == ("c",)
    assert "c" in LaneGraph(road).related("a", "same")


def test_official_scenic_compiles_and_samples_the_window_on_its_road():
    """Scenic 3.1.1 compiles the window's text and its samples meet every lane clause, decided exactly on the
    window's road (synth.road.lane_facts), not by Scenic's regions; r2s sample's own sampler finds variants too."""
    scenic = pytest.importorskip("scenic", reason="official Scenic is not installed (pip install scenic)")
    from pipeline.variants.sample import SampleOptions, sample_scenic

    scenes = clip()
    result = synthesize_window(scenes, SynthConfig(lanes=True))
    lanes = {st.id: st.lane for st in result.program.statements}
    assert isinstance(lanes["car1"], InLane) and lanes["car1"].lane == "d", str(result.program)
    index = RoadIndex(window_road(scenes))
    scenario = scenic.scenarioFromString(result.scenic, mode2D=True)
    random.seed(3)
    np.random.seed(3)
    samples, _ = scenario.generateBatch(6, maxIterations=5000)
    chain = LaneGraph(window_road(scenes)).related("a", "same")
    for s in samples:
        at = {o.name: o for o in s.objects}
        facts = {name: index.facts(np.array([o.position.x]), np.array([o.position.y]),
                                   np.array([(math.degrees(o.heading) + 90.0) % 360.0]))[0] for name, o in at.items()}
        assert facts["car1"].lane == "d"
        assert facts["ego"].lane == "a" and facts["car2"].lane in chain and facts["car3"].lane in chain
    assert len({(round(s.objects[1].position.x, 6), round(s.objects[1].position.y, 6)) for s in samples}) == 6
    variants = sample_scenic(result.scenic, SampleOptions(n=2, seed=1))  # checked against the program there
    assert len(variants.scenes) == 2


def test_one_feature_per_id_however_many_frames():
    """A window of 20 frames (ego 95 m along the road) carries each feature once: the union of its frames'
    features, no more than the map; a window of one frame, or of frames that add nothing, is its first road."""
    scenes = [frame(k, 5.0 * k, []) for k in range(20)]
    road = window_road(scenes)
    ids = [f.feature_id for f in road.features]
    assert len(ids) == len(set(ids)) == len({f.feature_id for s in scenes for f in s.road.features}) <= len(MAP.features)
    assert_where_the_map_has_them(road, MAP, scenes[0].world)
    assert window_road(scenes[:1]) is scenes[0].road
    still = [scenes[0], replace(scenes[0], frame_id="w/still")]
    assert window_road(still) is scenes[0].road
    assert window_road([Scene("bare", scenes[0].entities)]) is None


def test_roads_that_cannot_be_brought_together_are_refused_in_one_line(tmp_path):
    scenes = clip()
    other = RoadMap.of("n", [replace(f, map_id="n") for f in MAP.features])
    with pytest.raises(WindowRoadError, match="map 'm'.*map 'n'"):
        window_road([scenes[0], frame(1, 5.0, [], other)])
    bare = replace(scenes[1], world=None)
    with pytest.raises(WindowRoadError, match="has a world and frame 'w/1' none"):
        window_road([scenes[0], bare])
    renamed = replace(scenes[3], road=RoadMap.of("m", [replace(f, kind="crosswalk") if f.feature_id == "d" else f
                                                        for f in scenes[3].road.features]))
    with pytest.raises(WindowRoadError, match="'d' is a lane in one frame's road and a crosswalk in frame 'w/3'"):
        window_road([scenes[2], renamed])
    # as r2s synth says it: one line, exit 2, nothing written
    files = []
    for k, s in enumerate((scenes[0], bare)):
        files.append(tmp_path / f"{k}.json")
        files[-1].write_text(s.to_json())
    out = tmp_path / "p.dsl"
    assert_one_line_error(run_r2s("synth", *map(str, files), "--lanes", "--out", str(out)), contains="has a world")
    assert not out.exists()


# ------------------------------------------------------------------------------------------------ brute force


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), frames=st.integers(1, 6))
def test_random_windows_hold_each_frames_features_where_the_map_has_them(seed, frames):
    """A random road placed in a world (tests.support.lanes), ego at random places and headings along it, each
    frame's road within a random radius plus random named lanes: the window's road has exactly the features of
    some frame, each where the map has it in the first frame's ego frame, and a lane link exactly where some frame
    holds both its lanes (the map's links, read from the map)."""
    rng = random.Random(seed)
    local = random_road(rng)
    turn, (ox, oy) = rng.uniform(0, 360), (rng.uniform(-1e3, 1e3), rng.uniform(-1e3, 1e3))
    c, s = math.cos(math.radians(turn)), math.sin(math.radians(turn))

    def move(pts):
        return tuple((ox + x * c - y * s, oy + x * s + y * c) for x, y in pts)

    road_map = RoadMap.of("m", [replace(f, polygon=move(f.polygon), line=move(f.line)) for f in local.features])
    lanes = [f.feature_id for f in road_map.lanes]
    scenes = []
    for k in range(frames):
        x, y = move([(rng.uniform(-3, 3), rng.uniform(-45, 55))])[0]
        pose = WorldPose(x, y, (turn + 90.0 + rng.uniform(-30, 30)) % 360.0, map_id="m")
        road = in_ego_frame(road_map, pose.x, pose.y, pose.heading, rng.uniform(5, 40),
                            named=set(rng.sample(lanes, rng.randrange(3))))
        ego = make_scene("e", placed(road, [{"id": "ego", "type": "Car", "x": 0.0, "y": 0.0, "heading": 0.0}]))
        scenes.append(make_scene(f"r/{k}", ego.entities, road, pose))
    road = window_road(scenes)
    assert {f.feature_id for f in road.features} == {f.feature_id for s in scenes for f in s.road.features}
    assert_where_the_map_has_them(road, road_map, scenes[0].world)
    together = [{f.feature_id for f in s.road.features} for s in scenes]

    def kept(a: str, b: str | None) -> bool:
        return b is not None and any(a in ids and b in ids for ids in together)

    for f in road.lanes:
        m = road_map[f.feature_id]
        assert set(f.successors) == {x for x in m.successors if kept(f.feature_id, x)}
        assert set(f.predecessors) == {x for x in m.predecessors if kept(f.feature_id, x)}
        assert (f.left, f.right) == tuple(n if kept(f.feature_id, n) else None for n in (m.left, m.right))


# ------------------------------------------------------------------------------------------------ real data


def assert_every_named_lane_is_in_the_text(windows: list[list[Scene]], frames: Path, synthesize_all: bool) -> int:
    """Every lane of any entity's lane facts in any frame of a window is in the window's road, each feature where
    the map has it; every `in lane` of the window's program is a region of its Scenic text (all windows, or those
    whose first frame's road lacks a lane a later frame's facts name). Returns how many windows those are."""
    from frames.maps import maps_dir, read_maps

    road_map = next(iter(read_maps(maps_dir(frames), {windows[0][0].road.map_id})))
    lacking = 0
    for scenes in windows:
        facts = {lane for s in scenes for e in s.others for lane in (e.lanes or ())}
        road = window_road(scenes)
        assert facts <= {f.feature_id for f in road.lanes}, scenes[0].frame_id
        if road.map_id != road_map.map_id:
            road_map = next(iter(read_maps(maps_dir(frames), {road.map_id})))
        assert_where_the_map_has_them(road, road_map, scenes[0].world)
        lacks = not facts <= {f.feature_id for f in scenes[0].road.lanes}
        lacking += lacks
        if synthesize_all or lacks:
            result = synthesize_window(scenes, SynthConfig(lanes=True))
            assert lanes_named(result.program) <= set(scenic_road(result.scenic)["road__lanes"]), scenes[0].frame_id
    return lacking


@pytest.mark.parametrize("window_s", [1.0, 2.0])
def test_every_window_of_the_shipped_excerpt(excerpt_frames, window_s):
    windows = road_windows(excerpt_frames, window_s)
    assert any(len(w) > 1 for w in windows)
    assert_every_named_lane_is_in_the_text(windows, excerpt_frames, synthesize_all=True)


def test_every_2s_window_of_shared_nuscenes_mini(shared_dir, tmp_path):
    """../shared/data's nuScenes-mini extracted with its maps, cut into 2 s windows as `r2s run --window 2` cuts
    them: windows whose first road lacks a lane a later frame names occur, and every one is covered."""
    source = shared_dir / "data" / "nuscenes-mini" / "scenarionet"
    if not source.exists():
        pytest.skip(f"{source} not found in the shared data")
    frames = tmp_path / "frames"
    proc = run_r2s("extract", "scenarionet", str(source), "--out", str(frames))
    assert proc.returncode == 0, proc.stderr
    assert assert_every_named_lane_is_in_the_text(road_windows(frames, 2.0), frames, synthesize_all=False) > 0
