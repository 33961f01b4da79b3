"""`r2s query`: the DuckDB engine against an independent brute force (tests/support/query_bruteforce.py) on real frames and on
scenes built within 1e-6 of every boundary of the semantics, plus the verb's contract (output, bad input)."""

from __future__ import annotations

import math
import random
import subprocess
from dataclasses import replace
from pathlib import Path

import pandas as pd
import pyarrow.parquet as pq
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from frames.dataset import FramesDataset
from frames.rows import iter_scenes, read_frames, scene_to_rows, write_frames
from pipeline.cli import main as cli_main
from pipeline.query import mining, sql
from pipeline.query.mining import query_frames
from synth.config import SynthConfig
from synth.dsl import DslError
from synth.patterns.one_frame import matches, parse_pattern
from synth.patterns.temporal import is_temporal, parse_query_pattern
from synth.scene import Entity, Scene
from tests.support import ROOT, assert_one_line_error, run_r2s
from tests.support.query_bruteforce import brute_matches

KEYFRAMES = ROOT / "data" / "nuscenes-mini-keyframes" / "frames.parquet"
ANY_HEADING = "facing Range(0, 360) deg"
ANYWHERE = "on Range(-1000, 1000) @ Range(-1000, 1000)"

FOLLOWER = "car = new Vehicle behind ego by Range(0, 25), facing toward ego\n"
# Real-frame patterns: every clause kind, references to ego, to names and to nothing, 1 to 3 names; the README's.
# The shipped one-frame patterns (temporal ones: tests/pipeline/query/test_temporal.py).
SHIPPED_PATTERNS = [p for p in sorted((ROOT / "data" / "patterns").glob("*.dsl")) if not is_temporal(p.read_text())]
REAL_PATTERNS = [p.read_text() for p in SHIPPED_PATTERNS] + [
    f"ped = new Pedestrian ahead of ego by Range(0, 30), {ANY_HEADING}\ncar = new Vehicle left of ped by Range(0, 10), {ANY_HEADING}\n",
    FOLLOWER,
    "lead = new Car on Range(-3, 3) @ Range(0, 40) relative to ego, facing Range(-20, 20) deg relative to ego\n"
    "follower = new Vehicle ahead of lead by Range(0, 20), facing Range(-15, 15) deg relative to lead\n",
    "ped = new Pedestrian on Range(-30, 30) @ Range(-30, 30), facing away from ego\n"
    f"thing = new Object ahead of ped by Range(0, 4), {ANY_HEADING}\n",
    f"ped = new Pedestrian on Range(-25, 25) @ Range(-25, 25), {ANY_HEADING}\n"
    "thing = new Object right of ped by Range(0, 4), facing toward ped\n",
    f"cone = new TrafficCone right of ego by Range(0, 20), {ANY_HEADING}\n"
    f"bar = new Barrier on Range(-3, 3) @ Range(-3, 3) relative to cone, {ANY_HEADING}\n",
    f"bar = new Barrier right of ego by Range(0, 30), {ANY_HEADING}\n"
    "bar2 = new Barrier on Range(-1, 1) @ Range(0, 4) relative to bar, facing Range(-10, 10) deg relative to bar\n",
]


def r2s_query(capsys, *args: str) -> subprocess.CompletedProcess:
    """`r2s query ARGS` in this process (the verbs' error handling is pipeline.cli.main's): fast enough for the many
    bad-input cases; the end-to-end tests run the real command."""
    code = cli_main(["query", *args])
    out = capsys.readouterr()
    return subprocess.CompletedProcess(["r2s", "query", *args], code, out.out, out.err)


def engine(frames, pattern_text: str, tmp_path: Path, config: SynthConfig | None = None, **kw):
    """{frame_id: [binding tuple, ...]} with --all, and the summary."""
    pattern = parse_pattern(pattern_text)
    out = tmp_path / "matches.parquet"
    summary = query_frames(frames, pattern, out, all_bindings=True, config=config, log=lambda s: None, **kw)
    got: dict[str, list[tuple[str, ...]]] = {}
    counts: dict[str, set[int]] = {}
    for row in pq.read_table(out).to_pylist():
        got.setdefault(row["frame_id"], []).append(tuple(row["binding"][n] for n in pattern.names))
        counts.setdefault(row["frame_id"], set()).add(row["n_matches"])
    assert counts == {fid: {len(bs)} for fid, bs in got.items()}  # every row of a frame carries the frame's count
    return got, summary


def brute(scenes, pattern_text: str, config: SynthConfig | None = None):
    pattern = parse_pattern(pattern_text)
    return {s.frame_id: b for s in scenes if (b := brute_matches(pattern, s, config))}


@pytest.fixture(scope="module")
def keyframe_scenes():
    return list(iter_scenes(read_frames(KEYFRAMES)))


@pytest.fixture(scope="module")
def keyframe_brute(keyframe_scenes):
    """The brute force's answer on the shipped keyframes, once per pattern."""
    cache: dict[str, dict] = {}
    return lambda text: cache.setdefault(text, brute(keyframe_scenes, text))


@pytest.mark.parametrize("k", range(len(REAL_PATTERNS)))
def test_real_frames_match_exactly_as_the_brute_force(k, keyframe_scenes, keyframe_brute, tmp_path):
    text = REAL_PATTERNS[k]
    got, summary = engine(KEYFRAMES, text, tmp_path)
    want = keyframe_brute(text)
    assert got == want  # same frames, same bindings, same order
    assert want, "a pattern that matches nothing tests nothing"
    assert summary.frames_scanned == len(keyframe_scenes) and summary.frames_matched == len(want)
    assert summary.bindings == sum(map(len, want.values()))
    # The definition in synth.patterns.one_frame (backtracking) agrees as well, order included.
    pattern = parse_pattern(text)
    for s in keyframe_scenes:
        assert [tuple(b.values()) for b in matches(pattern, s)] == want.get(s.frame_id, [])


def test_one_row_per_frame_has_the_count_and_the_first_binding(keyframe_scenes, keyframe_brute, tmp_path):
    text = (ROOT / "data" / "patterns" / "queue-of-three.dsl").read_text()
    pattern = parse_pattern(text)
    out = tmp_path / "m.parquet"
    summary = query_frames(KEYFRAMES, pattern, out, log=lambda s: None)
    table = pq.read_table(out)
    assert table.schema.names == ["frame_id", "scene", "timestamp_us", "n_matches", "binding"]
    rows = table.to_pylist()
    want = keyframe_brute(text)
    assert [r["frame_id"] for r in rows] == [s.frame_id for s in keyframe_scenes if s.frame_id in want]
    by_frame = read_frames(KEYFRAMES).groupby("frame_id").first()
    for r in rows:
        assert r["n_matches"] == len(want[r["frame_id"]])
        assert tuple(r["binding"].values()) == want[r["frame_id"]][0]
        assert (r["scene"], r["timestamp_us"]) == tuple(by_frame.loc[r["frame_id"], ["scene", "timestamp_us"]])
    assert summary.frames_matched == len(rows) and any(r["n_matches"] > 1 for r in rows)


# --------------------------------------------------------------------------- scenes at the semantics' boundaries

# Both sides of each boundary: inside the engine's 1e-6 band (decided by the checker) and just outside it (decided in SQL).
DELTAS = (-1e-4, -1e-5, -1e-6, -1e-7, -2e-9, -1e-9, -5e-10, 0.0, 5e-10, 1e-9, 2e-9, 1e-7, 1e-6, 1e-5, 1e-4)


def _point(ref: Entity, bearing_deg: float, d: float) -> tuple[float, float]:
    r = math.radians(bearing_deg)
    return ref.x - d * math.sin(r), ref.y + d * math.cos(r)


def _local(ref: Entity, lx: float, ly: float) -> tuple[float, float]:
    t = math.radians(ref.heading)
    return ref.x + lx * math.cos(t) - ly * math.sin(t), ref.y + lx * math.sin(t) + ly * math.cos(t)


def _bearing(fx, fy, tx, ty):
    return (math.degrees(math.atan2(ty - fy, tx - fx)) - 90.0) % 360.0


BOUNDARY_CASES = {
    # pattern subject clause (REF is ego or r) -> function(ref, rng, delta) -> (x, y, heading) of the subject
    "ahead of {R} by Range(5, 12.5), " + ANY_HEADING:
        lambda r, g, d: (*_point(r, r.heading + g.choice([-1, 1]) * (10 + d), g.uniform(5, 12.5)), 0.0)
        if g.random() < 0.5 else (*_point(r, r.heading + g.uniform(-9, 9), g.choice([5, 12.5]) + d), 0.0),
    "left of {R} by Range(0.5, 3), " + ANY_HEADING:
        lambda r, g, d: (*_point(r, r.heading + 90 + g.choice([-1, 1]) * (10 + d), g.uniform(0.5, 3)), 0.0),
    "behind {R} by Range(2, 7), " + ANY_HEADING:
        lambda r, g, d: (*_point(r, r.heading + 180 + g.uniform(-9.9, 9.9), g.choice([2, 7]) + d), 0.0),
    "right of {R} by Range(1, 6), " + ANY_HEADING:
        lambda r, g, d: (*_point(r, r.heading + 270 + g.choice([-1, 1]) * (10 + d), g.uniform(1, 6)), 0.0),
    "on Range(-2, 3) @ Range(4, 20) relative to {R}, " + ANY_HEADING:
        lambda r, g, d: (*_local(r, g.choice([-2, 3]) + d, g.uniform(4, 20)), 0.0) if g.random() < 0.5
        else (*_local(r, g.uniform(-2, 3), g.choice([4, 20]) + d), 0.0),
    "on Range(-2, 3) @ Range(4, 20), " + ANY_HEADING:
        lambda r, g, d: (g.choice([-2, 3]) + d, g.uniform(4, 20), 0.0),
    ANYWHERE + ", facing toward {R}":
        lambda r, g, d: (lambda x, y: (x, y, _bearing(x, y, r.x, r.y) + g.choice([-1, 1]) * (5 + d)))(
            *_point(r, g.uniform(0, 360), g.uniform(1, 30))),
    ANYWHERE + ", facing away from {R}":
        lambda r, g, d: (lambda x, y: (x, y, _bearing(r.x, r.y, x, y) + g.choice([-1, 1]) * (5 + d)))(
            *_point(r, g.uniform(0, 360), g.uniform(1, 30))),
    ANYWHERE + ", facing Range(-20, 30) deg relative to {R}":
        lambda r, g, d: (g.uniform(-30, 30), g.uniform(-30, 30), r.heading + g.choice([-20 - d, 30 + d])),
    ANYWHERE + ", facing Range(350, 365) deg relative to {R}":
        lambda r, g, d: (g.uniform(-30, 30), g.uniform(-30, 30), r.heading + g.choice([350 - d, 365 + d])),
    ANYWHERE + ", facing Range(10, 15) deg":
        lambda r, g, d: (g.uniform(-30, 30), g.uniform(-30, 30), g.choice([10 - d, 15 + d])),
}


def _boundary_frames(subject: str, ref_is_ego: bool, n: int, seed: int) -> tuple[str, list[Scene]]:
    g = random.Random(seed)
    ref_line = "" if ref_is_ego else f"r = new Truck {ANYWHERE}, {ANY_HEADING}\n"
    text = ref_line + "a = new Car " + subject.format(R="ego" if ref_is_ego else "r") + "\n"
    scenes = []
    for i in range(n):
        ego = Entity("ego", "Car", g.uniform(-5, 5), g.uniform(-5, 5), g.uniform(0, 360))
        ref = ego if ref_is_ego else Entity("truck1", "Truck", g.uniform(-20, 20), g.uniform(-20, 20), g.uniform(0, 360))
        d = g.choice(DELTAS)
        x, y, h = BOUNDARY_CASES[subject](ref, g, d)
        ents = [ego, Entity("car1", "Car", x, y, h % 360.0)]
        if not ref_is_ego:
            ents.insert(1, ref)
        # A second candidate elsewhere keeps injectivity and ordering honest.
        ents.append(Entity("car2", "Car", *_point(ref, g.uniform(0, 360), g.uniform(0, 15)), g.uniform(0, 360)))
        scenes.append(Scene(f"b{seed}/{i}", tuple(ents)))
    return text, scenes


def _write(scenes, path: Path) -> Path:
    rows = [r for s in scenes for r in scene_to_rows(s, source="test", scene_name=s.frame_id.split("/")[0])]
    write_frames(rows, path)
    return path


@pytest.mark.parametrize("ref_is_ego", [True, False], ids=["ego", "name"])
@pytest.mark.parametrize("subject", list(BOUNDARY_CASES))
def test_boundaries_within_1e_6_on_both_sides(subject, ref_is_ego, tmp_path):
    text, scenes = _boundary_frames(subject, ref_is_ego, 300, seed=len(subject) + ref_is_ego)
    got, summary = engine(_write(scenes, tmp_path / "f.parquet"), text, tmp_path)
    want = brute(scenes, text)
    assert got == want
    # Both sides of the boundary occur, and the near-boundary bindings went to the exact check.
    assert 0 < len(want) < len(scenes)
    assert summary.checked_exactly > 0


def test_delta_constants_come_from_the_config(keyframe_scenes, tmp_path):
    text = "car = new Vehicle ahead of ego by Range(0, 50), facing away from ego\n"
    config = SynthConfig(delta1=3.0, delta2=1.0)
    got, _ = engine(KEYFRAMES, text, tmp_path, config=config)
    assert got == brute(keyframe_scenes, text, config) != brute(keyframe_scenes, text)


def test_wild_magnitudes_are_decided_by_the_checker(tmp_path):
    # Coordinates beyond 1e6 m (1e160: squares overflow where hypot does not), headings beyond 1e4 deg, tiny and
    # subnormal offsets: the engine sends every clause such an entity takes part in to the checker.
    g = random.Random(7)
    scenes = []
    for i, big in enumerate([1e7, 3e12, 1e160, 1e-300, 5e-324] * 12):
        ego = Entity("ego", "Car", 0.0, 0.0, 0.0)
        a = Entity("car1", "Car", big * g.choice([-1, 1]), big * g.uniform(6, 20), g.choice([0.0, 1e5, 360.0 * 1e9 + 3]))
        b = Entity("car2", "Car", a.x + g.uniform(-1, 1), a.y + g.choice([5.0, 1e-310, 1e7]), g.uniform(0, 360))
        scenes.append(Scene(f"w/{i}", (ego, a, b)))
    path = _write(scenes, tmp_path / "f.parquet")
    for text, magnitudes in ((f"a = new Car {ANYWHERE.replace('1000', '1e300')}, {ANY_HEADING}\n"
                              "b = new Car ahead of a by Range(0, 1e200), facing Range(-100, 100) deg relative to a\n",
                              {0, 1, 3, 4}),  # at 1e160, b + 5 m rounds onto a: no bearing, no match
                             (f"a = new Car ahead of ego by Range(0, 1e300), {ANY_HEADING}\n"
                              f"b = new Car on Range(-2, 2) @ Range(0, 1e8) relative to a, {ANY_HEADING}\n",
                              {0, 1, 2, 3, 4})):
        got, summary = engine(path, text, tmp_path)
        want = brute(scenes, text)
        assert got == want
        assert {int(fid.split("/")[1]) % 5 for fid in want} == magnitudes  # which magnitudes match somewhere


def test_coincident_points_have_no_bearing(tmp_path):
    # An entity exactly on its reference: no direction or facing relation holds, local coordinates (0, 0) do.
    g = random.Random(3)
    scenes = []
    for i in range(40):
        ego = Entity("ego", "Car", g.choice([0.0, 2.5]), 0.0, g.choice([0.0, 90.0, 270.0]))
        a = Entity("car1", "Car", *g.choice([(ego.x, ego.y), (1.0, 1.0)]), g.choice([0.0, 90.0, 180.0, 270.0]))
        b = Entity("car2", "Car", *g.choice([(a.x, a.y), (a.x, a.y + 1.0)]), g.choice([0.0, 180.0, 270.0]))
        scenes.append(Scene(f"c/{i}", (ego, a, b)))
    path = _write(scenes, tmp_path / "f.parquet")
    # Ranges reaching below 0 make a distance of 0 surely inside: only the coincidence rule can refuse it.
    for text in ("a = new Car on Range(-1, 1) @ Range(-1, 1) relative to ego, facing toward ego\n"
                 "b = new Car on Range(-1, 1) @ Range(-1, 1.5) relative to a, facing away from a\n",
                 f"a = new Car ahead of ego by Range(-1, 5), {ANY_HEADING}\nb = new Car behind a by Range(-1, 2), {ANY_HEADING}\n",
                 f"a = new Car on Range(-1, 1) @ Range(-1, 1) relative to ego, {ANY_HEADING}\n"
                 "b = new Car left of a by Range(0, 2), facing Range(-1, 1) deg relative to a\n",
                 f"a = new Car right of ego by Range(0, 3), {ANY_HEADING}\nb = new Car on Range(0, 0) @ Range(0, 0) relative to a, facing toward ego\n"):
        got, _ = engine(path, text, tmp_path)
        want = brute(scenes, text)
        assert got == want


MOTION_CASES = {
    # motion clause (REF is ego or r) -> function(ref speed, rng, delta) -> the subject's speed
    "stationary": lambda rs, g, d: 0.5 + d,
    "moving like {R}": lambda rs, g, d: max(0.0, rs + g.choice([-1, 1]) * (1.0 + d)),
    "moving Range(-2, 3.5) m/s relative to {R}": lambda rs, g, d: max(0.0, rs + g.choice([-2 - d, 3.5 + d])),
    "moving Range(4, 6) m/s": lambda rs, g, d: g.choice([4 - d, 6 + d]),
}


@pytest.mark.parametrize("ref_is_ego", [True, False], ids=["ego", "name"])
@pytest.mark.parametrize("clause", list(MOTION_CASES))
def test_motion_boundaries_and_missing_speeds(clause, ref_is_ego, tmp_path):
    g = random.Random(len(clause) * 2 + ref_is_ego)
    ref_line = "" if ref_is_ego else f"r = new Truck {ANYWHERE}, {ANY_HEADING}, moving Range(0, 100) m/s\n"
    text = ref_line + f"a = new Car {ANYWHERE}, {ANY_HEADING}, {clause.format(R='ego' if ref_is_ego else 'r')}\n"
    scenes = []
    for i in range(300):
        ego = Entity("ego", "Car", 0.0, 0.0, 0.0, speed=g.choice([0.0, 3.0, g.uniform(0, 15)]))
        ref = ego if ref_is_ego else Entity("truck1", "Truck", 5.0, 5.0, 0.0, speed=g.uniform(0, 15))
        speed = MOTION_CASES[clause](ref.speed, g, g.choice(DELTAS))
        ents = [ego, Entity("car1", "Car", 1.0, 2.0, 0.0, speed=None if g.random() < 0.1 else speed)]
        ents += [] if ref_is_ego else [ref]
        ents.append(Entity("car2", "Car", -3.0, 8.0, 90.0, speed=g.choice([None, 0.2, 5.0])))
        if not ref_is_ego and g.random() < 0.1:
            ents[2] = replace(ref, speed=None)  # a reference without speed: no motion relation to it
        scenes.append(Scene(f"m/{i}", tuple(ents)))
    got, summary = engine(_write(scenes, tmp_path / "f.parquet"), text, tmp_path)
    want = brute(scenes, text)
    assert got == want and 0 < len(want) < len(scenes)
    assert summary.checked_exactly > 0


MOTION_PATTERNS = [
    # "a parked car ahead and a vehicle passing it"
    f"parked = new Car ahead of ego by Range(0, 40), {ANY_HEADING}, stationary\n"
    f"other = new Vehicle on Range(-5, 5) @ Range(-10, 10) relative to parked, {ANY_HEADING}, moving Range(2, 30) m/s\n",
    "car = new Vehicle ahead of ego by Range(0, 40), facing Range(-20, 20) deg relative to ego, moving like ego\n",
    f"ped = new Pedestrian on Range(-20, 20) @ Range(-20, 20), {ANY_HEADING}, moving Range(0.5, 3) m/s\n",
    f"car = new Vehicle on Range(-30, 30) @ Range(-30, 30), {ANY_HEADING}, moving Range(-30, -3) m/s relative to ego\n",
    f"a = new Car on Range(-50, 50) @ Range(-50, 50), {ANY_HEADING}, stationary\n"
    "b = new Car ahead of a by Range(1, 10), facing Range(-20, 20) deg relative to a, moving like a\n",
]


# On the 9 frames of the shipped excerpt: every motion clause kind, each pattern matching somewhere.
EXCERPT_MOTION_PATTERNS = MOTION_PATTERNS[2:4] + [
    f"a = new Object on Range(-50, 50) @ Range(-50, 50), {ANY_HEADING}, stationary\n"
    f"b = new Object ahead of a by Range(0, 10), {ANY_HEADING}, moving like a\n",
    f"a = new Vehicle on Range(-50, 50) @ Range(-50, 50), {ANY_HEADING}, moving like ego\n",
    f"a = new Object on Range(-50, 50) @ Range(-50, 50), {ANY_HEADING}, moving Range(2, 30) m/s\n"
    f"b = new Object left of a by Range(0, 10), {ANY_HEADING}, stationary\n",
]


def _extracted(source: Path, out: Path) -> Path:
    proc = run_r2s("extract", "scenarionet", str(source), "--categories", "all", "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    return out


@pytest.fixture(scope="module")
def excerpt_frames(tmp_path_factory) -> Path:
    """The shipped ScenarioNet excerpt (real velocities) through r2s extract: frames with speeds."""
    return _extracted(ROOT / "data" / "nuscenes-mini-excerpt" / "scenarionet", tmp_path_factory.mktemp("x") / "f.parquet")


@pytest.mark.parametrize("k", range(len(EXCERPT_MOTION_PATTERNS)))
def test_motion_patterns_on_real_speeds(k, excerpt_frames, tmp_path):
    text = EXCERPT_MOTION_PATTERNS[k]
    scenes = list(iter_scenes(read_frames(excerpt_frames)))
    assert all(e.speed is not None for s in scenes for e in s.entities)
    got, _ = engine(excerpt_frames, text, tmp_path)
    want = brute(scenes, text)
    assert got == want and want


def test_motion_patterns_on_every_shared_keyframe(shared_dir, tmp_path):
    frames = _extracted(shared_dir / "data" / "nuscenes-mini" / "scenarionet", tmp_path / "f.parquet")
    scenes = list(iter_scenes(read_frames(frames)))
    for text in MOTION_PATTERNS:
        got, _ = engine(frames, text, tmp_path)
        want = brute(scenes, text)
        assert got == want and want, text


def test_motion_patterns_need_a_speed_column(tmp_path, capsys):
    pattern = tmp_path / "p.dsl"
    pattern.write_text(f"a = new Car {ANYWHERE}, {ANY_HEADING}, stationary\n")
    proc = r2s_query(capsys, str(KEYFRAMES), str(pattern), "--out", str(tmp_path / "m.parquet"))
    assert_one_line_error(proc, 2, "no speed column")


@settings(max_examples=25)
@given(seed=st.integers(0, 10**6), subjects=st.lists(st.sampled_from(list(BOUNDARY_CASES)), min_size=2, max_size=2))
def test_random_two_name_patterns_at_boundaries(seed, subjects, tmp_path_factory):
    """Two boundary clauses chained: r at a boundary relative to ego, a at a boundary relative to r."""
    g = random.Random(seed)
    first, second = subjects
    text = (f"r = new Truck {first.format(R='ego')}\n" f"a = new Car {second.format(R='r')}\n")
    scenes = []
    for i in range(40):
        ego = Entity("ego", "Car", 0.0, 0.0, g.uniform(0, 360))
        rx, ry, rh = BOUNDARY_CASES[first](ego, g, g.choice(DELTAS))
        ref = Entity("truck1", "Truck", rx, ry, (rh + g.uniform(0, 360) * ("facing Range(0, 360)" in first)) % 360.0)
        ax, ay, ah = BOUNDARY_CASES[second](ref, g, g.choice(DELTAS))
        scenes.append(Scene(f"h/{i}", (ego, ref, Entity("car1", "Car", ax, ay, ah % 360.0),
                                       Entity("truck2", "Truck", ax + 1, ay, ah % 360.0))))
    tmp = tmp_path_factory.mktemp("h")
    got, _ = engine(_write(scenes, tmp / "f.parquet"), text, tmp)
    assert got == brute(scenes, text)


# ------------------------------------------------------------------------------------------ the verb's contract

def test_cli_writes_matches_and_a_summary_line(tmp_path):
    pattern = tmp_path / "p.dsl"
    pattern.write_text(FOLLOWER)
    out = tmp_path / "m.parquet"
    proc = run_r2s("query", str(KEYFRAMES), str(pattern), "--out", str(out), "--threads", "1")
    assert proc.returncode == 0, proc.stderr
    table = pq.read_table(out)
    assert f"242 frames scanned, {table.num_rows} matched" in proc.stdout
    first = out.read_bytes()
    proc = run_r2s("query", str(KEYFRAMES), str(pattern), "--out", str(out), "--threads", "2")
    assert proc.returncode == 0 and out.read_bytes() == first  # deterministic, whatever the threads
    proc = run_r2s("query", str(KEYFRAMES), str(pattern), "--out", str(tmp_path / "all.parquet"), "--all")
    every = pq.read_table(tmp_path / "all.parquet")
    assert every.num_rows == sum(table.column("n_matches").to_pylist()) > table.num_rows
    assert sorted(p.name for p in tmp_path.iterdir()) == ["all.parquet", "m.parquet", "p.dsl"]  # no spill left


def test_a_dataset_directory_is_one_table(keyframe_scenes, keyframe_brute, tmp_path):
    half = len(keyframe_scenes) // 2
    d = tmp_path / "frames"
    _write(keyframe_scenes[:half], d / "part-0.parquet")
    _write(keyframe_scenes[half:], d / "sub" / "part-1.parquet")
    (d / "_SUCCESS").write_text("")
    got, summary = engine(d, REAL_PATTERNS[0], tmp_path)
    assert got == keyframe_brute(REAL_PATTERNS[0]) and summary.frames_scanned == len(keyframe_scenes)


def test_no_match_writes_an_empty_table_with_the_schema(tmp_path):
    pattern = parse_pattern(f"x = new Bus ahead of ego by Range(0, 0.01), {ANY_HEADING}\n")
    summary = query_frames(KEYFRAMES, pattern, tmp_path / "m.parquet", log=lambda s: None)
    table = pq.read_table(tmp_path / "m.parquet")
    assert table.num_rows == 0 and summary.frames_matched == 0
    assert table.schema.field("binding").type.names == ["x"]


@pytest.mark.parametrize("text,where,needle", [
    ("a = new Car ahead of b by Range(0, 5), facing toward ego", "line 1 column 22", "neither ego nor declared"),
    ("a = new Car ahead of ego by Range(0, 5), facing toward ego\nb = new Rocket ahead of a by Range(0, 5), facing toward a",
     "line 2 column 9", "unknown type"),
    ("a = new Car ahead ego by Range(0, 5), facing toward ego", "line 1 column 19", "expected of"),
    ("# nothing\n", "line 1 column 1", "declares no name"),
])
def test_bad_pattern_is_one_line_with_line_and_column(text, where, needle, tmp_path, capsys):
    pattern = tmp_path / "p.dsl"
    pattern.write_text(text)
    # The first case runs the real command; the others the same code in this process.
    args = (str(KEYFRAMES), str(pattern), "--out", str(tmp_path / "m.parquet"))
    proc = run_r2s("query", *args) if "neither" in needle else r2s_query(capsys, *args)
    assert_one_line_error(proc, 2, needle)
    assert where in proc.stderr and not (tmp_path / "m.parquet").exists()
    with pytest.raises(DslError, match=where):
        parse_pattern(text)


@pytest.mark.parametrize("args,needle", [
    (["--threads", "0"], "--threads must be at least 1"),
    (["--memory-limit", "-5"], "--memory-limit must be at least 1"),
    (["--config", "missing.toml"], "does not exist"),
])
def test_bad_options_are_one_line_exit_2(args, needle, tmp_path, capsys):
    pattern = tmp_path / "p.dsl"
    pattern.write_text(FOLLOWER)
    proc = r2s_query(capsys, str(KEYFRAMES), str(pattern), "--out", str(tmp_path / "m.parquet"), *args)
    assert_one_line_error(proc, 2, needle)
    proc = r2s_query(capsys, str(KEYFRAMES), str(pattern), "--out", str(tmp_path))
    assert_one_line_error(proc, 2, "is a directory")


def _frames_with(tmp_path, change) -> Path:
    df = read_frames(KEYFRAMES).head(200)
    df = change(df.copy())
    import pyarrow as pa

    path = tmp_path / "bad.parquet"
    pq.write_table(pa.Table.from_pandas(df, preserve_index=False), path)
    return path


@pytest.mark.parametrize("make,needle", [
    (lambda t: t / "missing.parquet", "does not exist"),
    (lambda t: (t / "x.parquet").write_text("not parquet") and t / "x.parquet", "not a readable parquet"),
    (lambda t: (t / "empty").mkdir() or t / "empty", "without frames parquet files"),
    (lambda t: _frames_with(t, lambda df: df.drop(columns=["heading"])), "lacks column"),
    (lambda t: _frames_with(t, lambda df: df.assign(x=df["x"].where(df.index != 5, float("nan")))), "non-finite"),
    (lambda t: _frames_with(t, lambda df: df.assign(heading=df["heading"].where(df.index != 5, float("inf")))), "non-finite"),
    (lambda t: _frames_with(t, lambda df: df.assign(type=df["type"].where(df.index != 5, "Rocket"))), "unknown entity type"),
    (lambda t: _frames_with(t, lambda df: df[df.index != 0]), "exactly one ego"),
    (lambda t: _frames_with(t, lambda df: df.assign(entity_id=df["entity_id"].where(df.index != 2, df["entity_id"][1]))),
     "twice"),
    (lambda t: _frames_with(t, lambda df: pd.concat([df.drop(index=5), df.loc[[5]]])), "occurs in two places"),
])
def test_bad_frames_input_is_one_line_exit_2(make, needle, tmp_path, capsys):
    pattern = tmp_path / "p.dsl"
    pattern.write_text(f"x = new Object {ANYWHERE}, {ANY_HEADING}\n")
    frames = make(tmp_path)
    args = (str(frames), str(pattern), "--out", str(tmp_path / "m.parquet"))
    proc = run_r2s("query", *args) if needle == "non-finite" else r2s_query(capsys, *args)
    assert_one_line_error(proc, 2, needle)
    assert not (tmp_path / "m.parquet").exists()


# ------------------------------------------------------------------ pruning the joins, frames in chunks (issue 39)
# pipeline.query.sql, "Pruning the joins": the box around a name's anchor is a necessary condition of the clauses'
# semantics (checked by the checker's own Clause.holds, at and beyond the boundaries), and random scenes with
# random Ranges give the brute force's matches with the box and without it; chunks of frames give the one query's.

PAIR = ROOT / "data" / "patterns" / "pedestrian-beside-vehicle.dsl"
CUT_IN = ROOT / "data" / "patterns" / "cut-in-from-right.dsl"
LOG = ROOT / "data" / "argoverse2-log-excerpt" / "frames.parquet"


CLAUSES = ["ahead of {r} by Range({a}, {b})", "left of {r} by Range({a}, {b})", "within Range({a}, {b}) of {r}",
           "on Range({c}, {d}) @ Range({a}, {b}) relative to {r}"]


def _clause(form: str, a: float, b: float, c: float, d: float):
    text = f"r = new Car on Range(-1e3, 1e3) @ Range(-1e3, 1e3)\ne = new Car {form.format(a=a, b=b, c=c, d=d, r='r')}\n"
    pattern = parse_pattern(text)
    return pattern, next(cl for _, cl in pattern.statements[1].clauses() if cl.ref == "r")


ranges = st.tuples(st.floats(0, 50), st.floats(0, 50)).map(sorted)


@settings(max_examples=400, deadline=None)
@given(form=st.sampled_from(CLAUSES), ab=ranges, cd=ranges, rx=st.floats(-1e6, 1e6), ry=st.floats(-1e6, 1e6),
       rh=st.floats(0, 360), bearing=st.floats(0, 360), nudge=st.sampled_from([0.0, 1e-9, -1e-9, 1e-6]))
def test_every_pair_that_holds_is_within_the_box(form, ab, cd, rx, ry, rh, bearing, nudge):
    """A pair the semantics accept lies within box(reach) of its reference on each axis: entities placed on the
    Range's far boundary (and a hair either side) in a random direction, far from the origin too."""
    (a, b), (c, d) = ab, (cd[0] - 25, cd[1] - 25)
    _, clause = _clause(form, a, b, c, d)
    bound = sql.reach(clause)
    assert bound is not None
    far = math.hypot(max(abs(c), abs(d)), b) if form.startswith("on") else b
    r = Entity("r", "Car", rx, ry, rh)
    t = math.radians(bearing)
    e = Entity("e", "Car", rx + (far + nudge) * math.cos(t), ry + (far + nudge) * math.sin(t), 0.0)
    if clause.holds(e, r, SynthConfig()):
        half = sql.box(bound)
        assert abs(e.x - r.x) <= half and abs(e.y - r.y) <= half


def test_clauses_without_a_distance_have_no_reach():
    pattern = parse_pattern("r = new Car on Range(-5, 5) @ Range(-5, 5)\n"
                            "e = new Car on Range(-5, 5) @ Range(-5, 5), facing toward r\n")
    assert all(sql.reach(cl) is None for _, cl in pattern.statements[1].clauses() if cl.ref == "r")
    assert sql.anchor(pattern.statements[1]) == sql.Anchor("r")  # still paired with r, on the frame alone
    assert sql.reach(_clause(CLAUSES[0], 0, 1e300, 0, 0)[1]) is None  # beyond any two entities that are not wild


def _scenes(g: random.Random, n: int) -> list[Scene]:
    """Frames of 6 to 12 cars in a 40 m square (so Ranges of a few metres keep some pairs and drop others),
    one in eight frames with a wild car (beyond 1e6 m)."""
    scenes = []
    for i in range(n):
        ents = [Entity("ego", "Car", 0.0, 0.0, g.uniform(0, 360))]
        for j in range(g.randint(6, 12)):
            x, y = g.uniform(-20, 20), g.uniform(-20, 20)
            if g.random() < 0.02:
                x *= 1e6
            ents.append(Entity(f"car{j}", g.choice(["Car", "Truck"]), x, y, g.uniform(0, 360)))
        scenes.append(Scene(f"p/{i}", tuple(ents)))
    return scenes


@settings(max_examples=12, deadline=None)
@given(seed=st.integers(0, 10**6), forms=st.lists(st.sampled_from(CLAUSES), min_size=2, max_size=2),
       bounds=st.lists(st.tuples(st.floats(0, 8), st.floats(0, 8)).map(sorted), min_size=4, max_size=4))
def test_random_scenes_and_ranges_match_with_and_without_the_box(seed, forms, bounds, tmp_path_factory):
    g = random.Random(seed)
    (a1, b1), (a2, b2), (c1, d1), (c2, d2) = bounds
    text = ("a = new Vehicle on Range(-30, 30) @ Range(-30, 30), facing Range(0, 360) deg\n"
            f"b = new Vehicle {forms[0].format(r='a', a=a1, b=b1, c=c1 - 4, d=d1 - 4)}\n"
            f"c = new Vehicle {forms[1].format(r='b', a=a2, b=b2 + 2, c=c2 - 4, d=d2 - 4)}\n")
    scenes = _scenes(g, 30)
    tmp = tmp_path_factory.mktemp("p")
    path = _write(scenes, tmp / "f.parquet")
    got, _ = engine(path, text, tmp)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(sql, "reach", lambda clause: None)  # no box: every pair of the frame is a candidate
        unpruned, _ = engine(path, text, tmp)
    assert got == unpruned == brute(scenes, text)


def _split(source, folder, cuts):
    """The frames file as a dataset of files cut before the frames at `cuts` (rows and columns as they are)."""
    table = pq.read_table(source)
    ids = table.column("frame_id").to_pylist()
    starts = [i for i in range(len(ids)) if i == 0 or ids[i] != ids[i - 1]]
    bounds = [0] + [starts[c] for c in cuts] + [len(ids)]
    folder.mkdir()
    for k in range(len(bounds) - 1):
        pq.write_table(table.slice(bounds[k], bounds[k + 1] - bounds[k]), folder / f"part-{k}.parquet")
    return folder


@pytest.mark.parametrize("size", [1, 7, 100])
def test_frames_in_chunks_match_as_in_one(size, tmp_path, monkeypatch):
    """Frames as datasets of three files, queried CHUNK_FRAMES frames at a time (chunks across the files): the
    brute force's matches of a two-name pattern on the shipped keyframes, and a temporal pattern's events on the
    Argoverse 2 log as in one chunk."""
    keyframes = _split(KEYFRAMES, tmp_path / "k", [50, 51])
    log = _split(LOG, tmp_path / "log", [60, 61])
    text = PAIR.read_text()
    temporal = parse_query_pattern(CUT_IN.read_text())
    whole, _ = engine(keyframes, text, tmp_path)
    query_frames(log, temporal, tmp_path / "one.parquet", events=True, log=lambda s: None)
    monkeypatch.setattr(sql, "CHUNK_FRAMES", size)
    got, _ = engine(keyframes, text, tmp_path)
    assert got == whole == brute(list(iter_scenes(read_frames(KEYFRAMES))), text) and got
    query_frames(log, temporal, tmp_path / "chunked.parquet", events=True, log=lambda s: None)
    events = pq.read_table(tmp_path / "chunked.parquet")
    assert events.equals(pq.read_table(tmp_path / "one.parquet")) and events.num_rows


def test_the_estimate_in_chunks_is_the_estimate_of_the_whole(tmp_path):
    """Per frame, the chunks' estimates (both kinds) are the one query's: each frame is in exactly one chunk."""
    folder = _split(KEYFRAMES, tmp_path / "k", [50, 51])
    con = mining._open([p.path for p in FramesDataset.open(folder).parts], False, 1, None, str(tmp_path))
    pattern = parse_pattern(PAIR.read_text())
    chunks = sql.frame_chunks(con, False, size=7)
    for fanout in (False, True):
        whole = sorted(con.execute(sql.estimate_query(pattern, SynthConfig(), fanout, per_frame=True)).fetchall())
        parts = sorted(r for c in chunks for r in con.execute(
            sql.estimate_query(pattern, SynthConfig(), fanout, per_frame=True, chunk=c)).fetchall())
        assert parts == whole and len(whole) == 242
    con.close()
