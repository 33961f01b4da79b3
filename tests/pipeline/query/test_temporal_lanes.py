"""Temporal patterns with lanes and ego's behaviours (docs/dsl.md, "Temporal patterns"): lane clauses in steps (on
variables and on ego), `changing lanes`, every behaviour of ego, and the shipped patterns that use them
(data/patterns/lanes/). The DuckDB engine against the plain loop over frames of tests/support/temporal_bruteforce.py
on real frames extracted with their maps (the shipped nuScenes excerpt and Argoverse 2 log; the nuScenes mini scenes
of /work/shared/data when present) and on random tracks with lane ids on a random road (hypothesis: gaps, frames in
no lane, the 3 s window met exactly and passed)."""

from __future__ import annotations

import functools
import random
import tempfile
from pathlib import Path

import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from frames.maps import maps_dir, maps_writer, read_maps
from frames.rows import FramesError, read_frames, write_frames
from pipeline.query.mining import query_frames
from synth.dsl import DslError
from synth.patterns.temporal import is_temporal, parse_temporal
from tests.support import ROOT, SHARED, assert_one_line_error, run_r2s
from tests.support.lanes import random_road
from tests.support.temporal_bruteforce import brute_temporal, prepare
from tests.support.temporal_engine import engine_temporal

ANY = "on Range(-999, 999) @ Range(-999, 999), facing Range(0, 360) deg"
NEAR = "on Range(-40, 40) @ Range(-40, 40), facing Range(0, 360) deg"
PATTERNS = [
    # lane clauses in steps: a vehicle in the lane left of ego, then in ego's lane (a cut-in read by lanes)
    f"v = new Vehicle {ANY}, in lane left of ego\nthen within 4 s\nv = new Vehicle {ANY}, in lane of ego\n",
    f"v = new Vehicle {NEAR}, in lane of ego\nego in lane of v\nfor at least 1 s\n",
    f"v = new Vehicle {ANY}, changing lanes\n",
    f"v = new Vehicle {NEAR}\nego changing lanes\n",
    f"v = new Vehicle {ANY}, in oncoming lane of ego\nego turning left\n",
    f"v = new Vehicle {NEAR}\nego in intersection, turning right\n",
    f"v = new Vehicle {NEAR}\nego braking\n",
    f"v = new Vehicle {NEAR}, braking\nego accelerating\n",
    f"v = new Vehicle {NEAR}\nego stopping\nthen\nv = new Vehicle {NEAR}\nego moving Range(0, 100) m/s, accelerating\n",
]
NUSCENES = SHARED / "data" / "nuscenes-mini" / "scenarionet"
# the two 20-second Waymo scenarios (198 steps at 10 Hz), as ScenarioNet's Waymo converter wrote them
WAYMO_CLIPS = [SHARED / "data" / "waymo" / f"sd_waymo_v1.2_{i}.pkl" for i in ("10810393add927f8", "1096927972b9efaa")]
SHIPPED = {p.name: p.read_text() for p in sorted((ROOT / "data" / "patterns" / "lanes").glob("*.dsl"))
           if is_temporal(p.read_text())}
# Where each shipped pattern finds what it says (docs/dsl.md lists those events with their render commands).
FINDS = {"cut-in-by-lane-change.dsl": ("av2-log",),
         "vehicle-turning-left-in-intersection.dsl": ("av2-log", "nuscenes"),
         "ego-left-turn-with-oncoming-traffic.dsl": ("nuscenes",)}  # ego turns left in scene-0061 only


@functools.cache
def _prepared(frames: Path):
    """The brute force's reading of a frames file and its maps, made once for all the patterns over it."""
    roads = list(read_maps(maps_dir(frames))) if maps_dir(frames).exists() else []
    return prepare(read_frames(frames), roads)


def engine_and_brute(frames: Path, text: str, tmp: Path) -> tuple[dict, dict]:
    here = Path(tempfile.mkdtemp(dir=tmp))
    return engine_temporal(frames, text, here), brute_temporal(None, parse_temporal(text), prepared=_prepared(Path(frames)))


@pytest.fixture(scope="module")
def mapped(excerpt_frames, tmp_path_factory):
    """Frames extracted with their maps, as `r2s extract` writes them: the shipped excerpts (the Argoverse 2 log is
    shipped with its map, frames.maps beside it), and /work/shared/data's nuScenes scenes and two 20-second Waymo
    clips (every other step) when present."""
    out = {"excerpt": excerpt_frames, "av2-log": ROOT / "data" / "argoverse2-log-excerpt" / "frames.parquet"}
    if NUSCENES.exists():
        target = tmp_path_factory.mktemp("nuscenes") / "frames"
        proc = run_r2s("extract", "scenarionet", str(NUSCENES), "--categories", "all", "--out", str(target))
        assert proc.returncode == 0, proc.stderr
        out["nuscenes"] = target
    if all(p.exists() for p in WAYMO_CLIPS):
        folder = tmp_path_factory.mktemp("waymo-in")
        for p in WAYMO_CLIPS:
            (folder / p.name).symlink_to(p)
        target = tmp_path_factory.mktemp("waymo") / "frames"
        proc = run_r2s("extract", "scenarionet", str(folder), "--every", "2", "--out", str(target))
        assert proc.returncode == 0, proc.stderr
        out["waymo"] = target
    return out


@pytest.mark.parametrize("text", PATTERNS + sorted(SHIPPED.values()))
@pytest.mark.parametrize("data", ["excerpt", "av2-log", "nuscenes", "waymo"])
def test_lanes_and_ego_behaviours_on_real_scenes_are_the_brute_force(mapped, data, text, tmp_path):
    if data not in mapped:
        pytest.skip(f"{data}: /work/shared/data is not on this machine")
    got, want = engine_and_brute(mapped[data], text, tmp_path)
    assert got == want


def test_real_scenes_change_lanes(mapped, tmp_path):
    """The comparisons above can fail: on the shipped Argoverse 2 log, vehicles change lanes (so the engine's
    windows meet real lane changes, not only empty sets)."""
    assert engine_and_brute(mapped["av2-log"], PATTERNS[2], tmp_path)[0]


def test_the_shipped_patterns_are_listed():
    assert set(SHIPPED) == set(FINDS)
    for text in SHIPPED.values():
        p = parse_temporal(text)
        assert parse_temporal(str(p)) == p and p.uses_lanes


@pytest.mark.parametrize("name", sorted(FINDS))
def test_the_shipped_patterns_find_what_they_say_on_real_data(mapped, name, tmp_path):
    """Each finds at least one event on the real data it is shown on (docs/dsl.md: those events, rendered)."""
    for data in FINDS[name]:
        if data not in mapped:
            pytest.skip(f"{data}: /work/shared/data is not on this machine")
        out = tmp_path / f"{data}.parquet"
        summary = query_frames(mapped[data], parse_temporal(SHIPPED[name]), out, events=True, log=lambda s: None)
        assert summary.events >= 1, (name, data)


# ----------------------------------------------------------------------------------------- random tracks

ROAD = random_road(random.Random(0))  # two lanes each way (n0, n1 northbound; s0, s1 south), three segments
LANES = [None, "n0_0", "n0_1", "n1_0", "n1_1", "s0_0", "s1_1", "turn"]
RANDOM = [
    "a = new Object on Range(-8, 8) @ Range(-8, 8), facing Range(0, 360) deg, changing lanes\n",
    "a = new Object on Range(-8, 8) @ Range(-8, 8), facing Range(0, 360) deg, in lane left of ego\nthen within 0.3 s\n"
    "a = new Object on Range(-8, 8) @ Range(-8, 8), facing Range(0, 360) deg, in lane of ego, changing lanes\n",
    "a = new Object on Range(-8, 8) @ Range(-8, 8), facing Range(0, 360) deg\nego in lane right of a, changing lanes\n",
    "a = new Object on Range(-8, 8) @ Range(-8, 8), facing Range(0, 360) deg, in oncoming lane of ego\n"
    "ego turning left\nfor at least 0.1 s\n",
    "a = new Object on Range(-8, 8) @ Range(-8, 8), facing Range(0, 360) deg\nego turning right, braking\n",
    "a = new Object on Range(-8, 8) @ Range(-8, 8), facing Range(0, 360) deg, stopping\nego accelerating\n",
]
_who = st.tuples(st.sampled_from(LANES), st.sampled_from([None, 0.0, 1.0, 2.0]),
                 st.sampled_from([None, 0.0, 30.0, 350.0, 20.0, 180.0]))
_box = st.tuples(st.sampled_from("ab"), st.integers(-8, 8), st.integers(-8, 8), _who)
_frame = st.tuples(_who, st.lists(_box, max_size=3, unique_by=lambda b: b[0]), st.sampled_from([0, 0, 1, 10, 20]))


def lane_frames(scenes) -> pd.DataFrame:
    """Random tracks (and ego) with a lane of ROAD or none, a speed and a heading in the world per row; timestamps
    step by 100 ms, sometimes 1 s or 2 s more (the 3 s windows met exactly and passed)."""
    rows = []
    for s, frames in enumerate(scenes):
        t = 0
        for index, ((lane, v, h), boxes, extra) in enumerate(frames, start=1):
            t += 100_000 * (1 + extra)
            ego = dict(frame_id=f"s{s}/{index}", source="test", scene=f"s{s}", frame_index=index, timestamp_us=t,
                       entity_id="ego", track_id="ego", type="Car", category="Car", x=0.0, y=0.0, heading=0.0,
                       length=None, width=None, is_ego=True, **_road(lane, v, h))
            rows.append(ego)
            for k, (track, x, y, who) in enumerate(boxes, start=1):
                rows.append(dict(ego, entity_id=f"car_{track}", track_id=track, x=float(x), y=float(y),
                                 heading=float(30 * k), is_ego=False, **_road(*who)))
    return pd.DataFrame(rows)


def _road(lane, speed, heading) -> dict:
    return dict(speed=speed, map_id="m", map_x=0.0, map_y=0.0, map_heading=heading, lanes=[lane] if lane else [],
                lane=lane, in_intersection=lane == "turn", on_crosswalk=False, off_road=False)


def _write(frames: pd.DataFrame, here: Path) -> Path:
    path = here / "frames.parquet"
    write_frames(frames, path)
    maps_dir(path).mkdir()
    with maps_writer(maps_dir(path) / "part-0.parquet") as w:
        w.add(ROAD)
    return path


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(st.lists(_frame, min_size=1, max_size=9), min_size=1, max_size=2), st.sampled_from(RANDOM))
def test_random_tracks_with_lanes_are_the_brute_force(tmp_path, scenes, text):
    here = Path(tempfile.mkdtemp(dir=tmp_path))
    frames = lane_frames(scenes)
    path = _write(frames, here)
    turners = parse_temporal(text).behaving(("turning left", "turning right"))
    if turners and not frames[frames.is_ego].map_heading.notna().any():
        with pytest.raises(FramesError, match="turning needs ego's heading"):
            engine_temporal(path, text, here)
        return
    got, want = engine_and_brute(path, text, here)
    assert got == want


@pytest.mark.parametrize("lanes,extra,expect", [
    (["n0_0", "n1_0"], 0, True),  # into the lane right of the earlier one
    (["n1_1", "n0_1"], 0, True),  # and left
    (["n0_0", "n0_1"], 0, False),  # continuing straight down the chain is no change
    (["n0_0", "s0_0"], 0, False),  # nor is the oncoming lane
    (["n0_0"] + [None] * 29 + ["n1_1"], 0, True),  # 3 s before exactly; rows in no lane take part in none
    (["n0_0"] + [None] * 29 + ["n1_1"], 1, False),  # 3.1 s before
    (["n0_0", "turn"], 0, False),
])
def test_changing_lanes_boundaries_by_hand(tmp_path, lanes, extra, expect):
    frames = [(("n0_0", 1.0, 0.0), [("a", 0, 5, (ln, 1.0, 0.0))], 0) for ln in lanes]
    frames[-1] = (frames[-1][0], frames[-1][1], extra)
    text = "a = new Object ahead of ego by Range(0, 8), facing Range(0, 360) deg, changing lanes\n"
    got, want = engine_and_brute(_write(lane_frames([frames]), tmp_path), text, tmp_path)
    assert (f"s0/{len(lanes)}" in got) is expect
    assert got == want
    ego = [((ln, 1.0, 0.0), [("a", 0, 5, ("n0_0", 1.0, 0.0))], 0) for ln in lanes]  # the same, on ego
    ego[-1] = (ego[-1][0], ego[-1][1], extra)
    text = "a = new Object ahead of ego by Range(0, 8), facing Range(0, 360) deg\nego changing lanes\n"
    here = Path(tempfile.mkdtemp(dir=tmp_path))
    got, want = engine_and_brute(_write(lane_frames([ego]), here), text, here)
    assert (f"s0/{len(lanes)}" in got) is expect
    assert got == want


# ----------------------------------------------------------------------------------------- syntax and errors

def test_ego_behaviours_read_and_print_back():
    text = (f"v = new Vehicle {NEAR}, in oncoming lane of ego, braking\nego turning left, braking\nthen\n"
            f"v = new Vehicle {NEAR}, changing lanes\nego moving Range(1, 20) m/s, in intersection, changing lanes\n")
    p = parse_temporal(text)
    assert p.steps[0].behaviours == (("v", "braking"), ("ego", "turning left"), ("ego", "braking"))
    assert p.steps[1].behaviours == (("v", "changing lanes"), ("ego", "changing lanes"))
    assert p.steps[1].pattern.ego is not None and p.uses_lanes and p.behaving(("turning left",)) == {"ego"}
    assert parse_temporal(str(p)) == p
    with pytest.raises(DslError, match="line 1: a step declares at least one name"):
        parse_temporal("ego turning left\n")


def test_changing_lanes_without_a_map_is_one_line(tmp_path):
    pattern = tmp_path / "p.dsl"
    pattern.write_text(RANDOM[0])
    out = tmp_path / "m.parquet"
    keyframes = ROOT / "data" / "nuscenes-mini-keyframes" / "frames.parquet"  # no lane columns
    assert_one_line_error(run_r2s("query", str(keyframes), str(pattern), "--out", str(out)), 2, "no lane columns")
    frames = lane_frames([[(("n0_0", 1.0, 0.0), [("a", 0, 5, ("n0_0", 1.0, 0.0))], 0)]])
    frames["map_id"] = None  # the lane columns of a source without a map: all null
    path = tmp_path / "f.parquet"
    write_frames(frames, path)
    assert_one_line_error(run_r2s("query", str(path), str(pattern), "--out", str(out)), 2, "no frame names a map")
    pattern.write_text(RANDOM[4])  # ego's turns need ego's heading in the world
    frames = lane_frames([[((None, 1.0, None), [("a", 0, 5, ("n0_0", 1.0, 0.0))], 0)]])
    write_frames(frames, path)
    assert_one_line_error(run_r2s("query", str(path), str(pattern), "--out", str(out)), 2,
                          "turning needs ego's heading in the world")
    assert not out.exists()
