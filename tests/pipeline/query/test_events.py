"""`r2s query --events`: DuckDB's gaps-and-islands against a plain loop over frames (tests/support/events_bruteforce.py)
on the shipped keyframes and on random tracks (hypothesis: tracks that come and go, ids that change from frame to
frame while track ids stay, frames out of input order, missing timestamps), and --min-duration at its boundary."""

from __future__ import annotations

import tempfile
from pathlib import Path

import pandas as pd
import pyarrow.parquet as pq
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from frames.rows import read_frames, write_frames
from pipeline.query.mining import query_frames
from synth.patterns.one_frame import parse_pattern
from synth.patterns.temporal import is_temporal
from tests.support import ROOT, assert_one_line_error, run_r2s
from tests.support.events_bruteforce import brute_events

KEYFRAMES = ROOT / "data" / "nuscenes-mini-keyframes" / "frames.parquet"
PATTERNS = [t for p in sorted((ROOT / "data" / "patterns").glob("*.dsl")) if not is_temporal(t := p.read_text())] + [
    "car = new Vehicle behind ego by Range(0, 25), facing toward ego\n",
]


def engine_events(frames, text: str, tmp_path: Path, **kw) -> list[dict]:
    pattern = parse_pattern(text)
    out = tmp_path / "events.parquet"
    summary = query_frames(frames, pattern, out, events=True, log=lambda s: None, **kw)
    rows = pq.read_table(out).to_pylist()
    assert summary.events == len(rows)
    for r in rows:
        r["binding"] = tuple(r["binding"][n] for n in pattern.names)
        r["tracks"] = tuple(r["tracks"][n] for n in pattern.names)
    return rows


@pytest.mark.parametrize("k", range(len(PATTERNS)))
def test_events_on_shipped_keyframes_are_the_brute_force(tmp_path, k):
    frames = read_frames(KEYFRAMES)
    got = engine_events(KEYFRAMES, PATTERNS[k], tmp_path)
    assert got == brute_events(frames, parse_pattern(PATTERNS[k]))
    assert any(e["n_frames"] > 1 for e in got)  # runs, not single frames


ONE = "p = new Object ahead of ego by Range(0, 12), facing Range(0, 360) deg\n"
TWO = ("a = new Car on Range(-12, 12) @ Range(-12, 12), facing Range(0, 360) deg\n"
       "b = new Object left of a by Range(0, 12), facing Range(0, 360) deg\n")

_entity = st.tuples(st.sampled_from("abcde"), st.sampled_from(["Car", "Pedestrian"]),
                    st.integers(-10, 10), st.integers(-10, 10))
_frame = st.tuples(st.lists(_entity, max_size=5, unique_by=lambda e: e[0]), st.integers(0, 2),
                   st.booleans())  # entities, index step (0: a frame later in the input, 2: a frame not kept)
_scenes = st.lists(st.lists(_frame, min_size=1, max_size=8), min_size=1, max_size=3)


def random_frames(scenes, shuffle: bool, timestamps: bool, shared: bool = False) -> pd.DataFrame:
    """Frames of random tracks; ids ranked per frame (so they change while track ids stay), steps of 100 ms.
    shared: a track id per type, as another tool's frames may give (a frame then binds the same tracks twice)."""
    rows = []
    blocks = []
    for s, frames in enumerate(scenes):
        idx = 0
        for entities, step, late in frames:
            idx += max(step, 1)
            fid = f"s{s}/{idx}"
            block = [dict(frame_id=fid, source="test", scene=f"s{s}", frame_index=idx,
                          timestamp_us=idx * 100_000 if timestamps else None, entity_id="ego", track_id="ego",
                          type="Car", category="Car", x=0.0, y=0.0, heading=0.0, length=None, width=None,
                          is_ego=True)]
            ranked = sorted(entities, key=lambda e: (e[2] ** 2 + e[3] ** 2, e[0]))
            for r, (track, typ, x, y) in enumerate(ranked, start=1):
                block.append(dict(block[0], entity_id=f"{typ.lower()}{r}", track_id=typ if shared else track, type=typ,
                                  category=typ, x=float(x), y=float(y), heading=float(10 * r), is_ego=False))
            blocks.append((shuffle and late, block))
    for late in (False, True):  # shuffled: some frames come later in the input than their successors
        rows += [r for is_late, block in blocks if is_late == late for r in block]
    return pd.DataFrame(rows)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(_scenes, st.sampled_from([ONE, TWO]), st.booleans(), st.booleans(), st.booleans())
def test_events_on_random_tracks_are_the_brute_force(tmp_path, scenes, text, shuffle, timestamps, shared):
    frames = random_frames(scenes, shuffle, timestamps, shared)
    here = Path(tempfile.mkdtemp(dir=tmp_path))  # one directory per example (tmp_path is the test's)
    path = here / "frames.parquet"
    write_frames(frames, path)
    assert engine_events(path, text, here) == brute_events(read_frames(path), parse_pattern(text))


def test_min_duration_keeps_events_at_least_that_long(tmp_path):
    frames = read_frames(KEYFRAMES)
    text = PATTERNS[0]
    every = brute_events(frames, parse_pattern(text))
    durations = sorted({e["duration_s"] for e in every})
    assert len(durations) >= 3
    s = durations[1]  # an event exactly this long is kept; a shorter one is not
    got = engine_events(KEYFRAMES, text, tmp_path, min_duration_s=s)
    assert got == [e for e in every if e["duration_s"] >= s] == brute_events(frames, parse_pattern(text), s)
    assert {e["duration_s"] for e in got} == set(durations[1:])


def test_events_verb_and_its_errors(tmp_path):
    pattern = ROOT / "data" / "patterns" / "pedestrian-ahead.dsl"
    out = tmp_path / "events.parquet"
    proc = run_r2s("query", str(KEYFRAMES), str(pattern), "--out", str(out), "--events", "--min-duration", "2")
    assert proc.returncode == 0, proc.stderr
    assert "events" in proc.stdout
    got = pq.read_table(out).to_pylist()
    assert got and all(e["duration_s"] >= 2 for e in got)
    for args, says in ((["--min-duration", "-1", "--events"], "--min-duration"),
                       (["--min-duration", "nan", "--events"], "--min-duration"),
                       (["--min-duration", "1"], "needs --events"), (["--events", "--all"], "choose one")):
        bad = tmp_path / "bad.parquet"
        proc = run_r2s("query", str(KEYFRAMES), str(pattern), "--out", str(bad), *args)
        assert_one_line_error(proc, 2, says)
        assert not bad.exists()


def test_min_duration_without_timestamps_is_one_line(tmp_path):
    frames = read_frames(KEYFRAMES)
    frames["timestamp_us"] = None
    path = tmp_path / "frames.parquet"
    write_frames(frames, path)
    out = tmp_path / "events.parquet"
    proc = run_r2s("query", str(path), str(ROOT / "data" / "patterns" / "pedestrian-ahead.dsl"), "--out", str(out),
                   "--events", "--min-duration", "1")
    assert_one_line_error(proc, 2, "timestamps")
    assert not out.exists()


def test_a_frame_binding_the_same_tracks_twice_is_one_binding(tmp_path):
    """Two boxes with one track id (another tool's frames) in each of three frames: one event of three frames, its
    binding the first box in key order, as the brute force says."""
    two = [("a", "Car", 0, 5), ("b", "Car", 0, 8)]
    frames = random_frames([[(two, 1, False)] * 3], shuffle=False, timestamps=True, shared=True)
    path = tmp_path / "frames.parquet"
    write_frames(frames, path)
    got = engine_events(path, ONE, tmp_path)
    assert got == brute_events(read_frames(path), parse_pattern(ONE))
    assert [(e["tracks"], e["n_frames"]) for e in got] == [(("Car",), 3)]
