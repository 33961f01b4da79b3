"""`r2s run --window` as a user runs it: real frames (shipped nuScenes-mini keyframes and the Argoverse 2 log
excerpt, cut short), real workers. Each row is checked against synth.window.program on the frames the row names, read
back independently, and every window program against the checker in each of its frames."""

from __future__ import annotations

from pathlib import Path

import pyarrow.parquet as pq
import pytest

from frames.rows import frame_to_scene, read_frames, write_frames
from frames.schema import ROAD_COLUMNS
from pipeline.programs import read_programs
from synth import check_window, synthesize_window, tile
from synth.config import SynthConfig
from tests.support import ROOT, assert_one_line_error, run_r2s

KEYFRAMES = ROOT / "data" / "nuscenes-mini-keyframes" / "frames.parquet"
AV2 = ROOT / "data" / "argoverse2-log-excerpt" / "frames.parquet"


@pytest.fixture(scope="module")
def clips(tmp_path_factory) -> Path:
    """Two nuScenes scenes (first 6 keyframes, 2 Hz) and the AV2 log (first 14 frames, 10 Hz) in one file."""
    nu = pq.read_table(KEYFRAMES).to_pandas()
    nu = nu[nu.scene.isin(["scene-0103", "scene-0553"]) & (nu.frame_index < 6)]
    av2 = pq.read_table(AV2).to_pandas()
    av2 = av2[av2.frame_index < 14]
    import pandas as pd

    path = tmp_path_factory.mktemp("clips") / "frames.parquet"
    write_frames(pd.concat([nu, av2], ignore_index=True), path)
    return path


def expected_windows(frames: Path, window_s: float, stride_s: float | None = None, roads: bool = False):
    """(scene, [frame ids], [Scenes], [timestamps]) of every window, from the frames read whole with pandas (with
    `roads`: each frame with the road r2s scene gives it, from the maps beside the frames)."""
    import pandas as pd

    from frames.maps import FrameRoads, maps_dir

    df = pd.read_parquet(frames) if roads else read_frames(frames)
    found = FrameRoads(maps_dir(frames)) if roads else None
    out = []
    for scene, rows in df.groupby("scene", sort=True):
        heads = rows.drop_duplicates("frame_id").sort_values("frame_index")
        ids, stamps = heads.frame_id.tolist(), [int(t) for t in heads.timestamp_us]
        by = {fid: g for fid, g in rows.groupby("frame_id", sort=False)}
        for a, b in tile(stamps, round(window_s * 1e6), None if stride_s is None else round(stride_s * 1e6)):
            scenes = [frame_to_scene(by[f], found.road(by[f])[0] if found is not None else None)
                      for f in ids[a:b + 1]]
            out.append((scene, ids[a:b + 1], scenes, stamps[a:b + 1]))
    return out


def _run(frames: Path, out: Path, *more: str):
    proc = run_r2s("run", str(frames), "--out", str(out), "--jobs", "2", *more)
    assert proc.returncode == 0, proc.stderr
    return proc


def _summary(stderr: str) -> str:
    return next(ln for ln in stderr.splitlines() if " windows (" in ln and " computed, " in ln)


def test_window_rows_are_the_window_programs(clips, tmp_path):
    out = tmp_path / "windows"
    proc = _run(clips, out, "--window", "1")
    rows = read_programs(out)  # the programs columns, as every reader sees them
    full = pq.read_table(out).to_pandas().set_index("frame_id")
    expected = expected_windows(clips, 1.0)
    assert len(rows) == len(expected) == len(full)
    assert f"{len(expected)} windows ({len(expected)} computed, 0 kept)" in _summary(proc.stderr)
    covered = []
    for scene, ids, scenes, stamps in expected:
        row = full.loc[ids[0]]
        assert (row.scene, row.last_frame, row.n_frames, row.window_s) == (scene, ids[-1], len(ids), 1.0)
        assert (row.first_timestamp_us, row.last_timestamp_us) == (stamps[0], stamps[-1])
        assert stamps[-1] - stamps[0] < 1_000_000
        result = synthesize_window(scenes)
        assert (row.status, row.cost, row.program, bool(row.certified)) == \
            (result.status, result.cost, str(result.program), True)
        verdicts = check_window(row.program, scenes)
        assert all(v.ok for v in verdicts), [str(v) for c in verdicts for v in c.violations][:3]
        covered += ids
    # Consecutive windows that do not overlap: every frame in exactly one window.
    assert sorted(covered) == sorted(read_frames(clips).frame_id.unique())
    sizes = {len(ids) for _, ids, _, _ in expected}
    assert 2 in sizes and max(sizes) >= 10  # 2 Hz and 10 Hz scenes
    assert full.config_hash.nunique() == 1 and full.config_hash.iloc[0] != SynthConfig().hash


def test_resume_keeps_a_window_only_for_the_same_rows_and_options(clips, tmp_path):
    out = tmp_path / "windows.parquet"
    _run(clips, out, "--window", "1")
    first = pq.read_table(out).to_pandas().set_index("frame_id")
    n = len(first)
    assert f"{n} windows (0 computed, {n} kept)" in _summary(_run(clips, out, "--window", "1").stderr)
    # One entity of one frame moves: only the window holding that frame is recomputed.
    df = read_frames(clips)
    victim = df[(df.scene == "scene-0553") & (df.frame_index == 3) & ~df.is_ego].index[0]
    df.loc[victim, "x"] += 0.5
    changed = tmp_path / "changed.parquet"
    write_frames(df, changed)
    proc = _run(changed, out, "--window", "1")
    assert f"{n} windows (1 computed, {n - 1} kept)" in _summary(proc.stderr)
    assert "rows changed" in proc.stderr
    again = pq.read_table(out).to_pandas().set_index("frame_id")
    assert again.loc["scene-0553/2", "frame_hash"] != first.loc["scene-0553/2", "frame_hash"]
    assert (again.drop("scene-0553/2").frame_hash == first.drop("scene-0553/2").frame_hash).all()
    # Another stride is another configuration: every window recomputed, the output holds the new tiling only.
    proc = _run(changed, out, "--window", "1", "--stride", "0.5")
    strided = expected_windows(changed, 1.0, 0.5)
    assert f"{len(strided)} windows ({len(strided)} computed, 0 kept)" in _summary(proc.stderr)
    rows = pq.read_table(out).to_pandas()
    assert sorted(rows.frame_id) == sorted(ids[0] for _, ids, _, _ in strided)
    assert len(strided) > n


def test_window_runs_with_lanes_give_each_frame_its_road(excerpt_frames, tmp_path):
    """`r2s run --window --lanes` on the shipped excerpt extracted with its maps: each row is synth.window.program's
    program of its frames, each with the road r2s scene gives it, and holds in each of them; frames without a
    map are error rows that name the missing road, and the run goes on."""
    out = tmp_path / "lanes"
    _run(excerpt_frames, out, "--window", "2", "--lanes")
    full = pq.read_table(out).to_pandas().set_index("frame_id")
    expected = expected_windows(excerpt_frames, 2.0, roads=True)
    assert len(full) == len(expected) and any(len(ids) > 2 for _, ids, _, _ in expected)
    config = SynthConfig(lanes=True)
    for _, ids, scenes, _ in expected:
        row = full.loc[ids[0]]
        result = synthesize_window(scenes, config)
        assert (row.status, row.cost, row.program, bool(row.certified)) == \
            (result.status, result.cost, str(result.program), True)
        assert all(st.lane is not None for st in result.program.statements)
        assert all(v.ok for v in check_window(row.program, scenes, config))
    bare = tmp_path / "bare.parquet"
    plain = read_frames(excerpt_frames)  # the same frames without their road columns, no maps beside them
    write_frames(plain.drop(columns=[c for c in ROAD_COLUMNS if c in plain]), bare)
    _run(bare, tmp_path / "bare-out", "--window", "2", "--lanes")
    rows = pq.read_table(tmp_path / "bare-out").to_pandas()
    assert (rows.status == "error").all() and rows.error.str.contains("has no road").all()


def test_bad_window_runs_are_one_line_and_write_nothing(clips, tmp_path):
    out = tmp_path / "w"
    for args, words in ((("--stride", "1"), "need --window"), (("--window", "0"), "positive"),
                        (("--window", "nan"), "positive"), (("--window", "1", "--max-gap", "-1"), "positive"),
                        (("--window", "1", "--strategy", "monolithic"), "encodes one frame")):
        assert_one_line_error(run_r2s("run", str(clips), "--out", str(out), *args), 2, words)
        assert not out.exists()
    df = read_frames(clips)
    df["timestamp_us"] = None
    untimed = tmp_path / "untimed.parquet"
    write_frames(df, untimed)
    assert_one_line_error(run_r2s("run", str(untimed), "--out", str(out), "--window", "1"), 2, "timestamp")
    assert not out.exists()
    df = read_frames(clips)
    df.loc[df.frame_id == "scene-0103/2", "timestamp_us"] = 0
    disordered = tmp_path / "disordered.parquet"
    write_frames(df, disordered)
    assert_one_line_error(run_r2s("run", str(disordered), "--out", str(out), "--window", "1"), 2, "not later than")
    assert not out.exists()
    # A window run never writes into an output of per-frame programs (nor mixes the two kinds of rows).
    frames_out = tmp_path / "per-frame"
    assert run_r2s("run", str(clips), "--out", str(frames_out), "--jobs", "2").returncode == 0
    assert_one_line_error(run_r2s("run", str(clips), "--out", str(frames_out), "--window", "1"), 2, "per-frame")


def test_a_bad_frame_is_an_error_row_for_its_window_and_the_run_goes_on(clips, tmp_path):
    df = read_frames(clips)
    victim = df[(df.frame_id == "scene-0103/1") & ~df.is_ego].index[0]
    df.loc[victim, "x"] = 5e6  # beyond the supported range: the frame's scene is refused
    bad = tmp_path / "bad.parquet"
    write_frames(df, bad)
    out = tmp_path / "w"
    proc = _run(bad, out, "--window", "1")
    rows = pq.read_table(out).to_pandas().set_index("frame_id")
    assert rows.loc["scene-0103/0", "status"] == "error" and "scene-0103/1" in rows.loc["scene-0103/0", "error"]
    assert (rows.drop("scene-0103/0").status == "optimal").all()
    assert "1 errors" in _summary(proc.stderr)
