"""`r2s run --clip` as a user runs it: the shipped Argoverse 2 log cut short (its speeds and maps), real workers.
Each clip row is checked against `r2s synth A.json ... --behaviours --format json` run as a process on that clip's
scene JSON (each frame read whole by pipeline.scenes, not by the batch stage), and `r2s check` accepts each row's
program on them; resume is checked against a changed row and a changed timestamp."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pandas as pd
import pyarrow.parquet as pq
import pytest

from frames.maps import maps_dir
from frames.rows import write_frames
from pipeline.scenes import scene
from tests.support import ROOT, assert_one_line_error, run_r2s

AV2 = ROOT / "data" / "argoverse2-log-excerpt" / "frames.parquet"
N_FRAMES = 25  # 2.4 s at 10 Hz: clips of 1 s are 11, 10 and 4 frames


def _copy(df: pd.DataFrame, path: Path) -> Path:
    """Frames written to `path` with the log's maps beside them (--lanes reads them there)."""
    write_frames(df, path)
    shutil.copytree(maps_dir(AV2), maps_dir(path))
    return path


@pytest.fixture(scope="module")
def log() -> pd.DataFrame:
    df = pd.read_parquet(AV2)
    return df[df.frame_index < N_FRAMES].reset_index(drop=True)


@pytest.fixture(scope="module")
def frames(log, tmp_path_factory) -> Path:
    return _copy(log, tmp_path_factory.mktemp("clip") / "frames.parquet")


def _run(frames: Path, out: Path, *more: str):
    proc = run_r2s("run", str(frames), "--out", str(out), "--jobs", "2", "--clip", "1", "--lanes", *more)
    assert proc.returncode == 0, proc.stderr
    return proc


def _contents(out: Path) -> dict[str, bytes]:
    """An output's bytes by relative path (a file or a folder of parts)."""
    files = sorted(out.rglob("*")) if out.is_dir() else [out]
    return {str(f.relative_to(out.parent)): f.read_bytes() for f in files if f.is_file()}


def _summary(stderr: str) -> str:
    return next(ln for ln in stderr.splitlines() if " clips (" in ln and " computed, " in ln)


def _clips(log: pd.DataFrame, clip_us: int) -> list[list[str]]:
    """Brute force: each clip's frame ids, a clip starting at the first frame not in the one before and holding
    every frame up to clip_us after its start (docs/dsl.md, "Programs over a window": consecutive windows)."""
    heads = log.drop_duplicates("frame_id").sort_values("frame_index")
    ids, stamps = heads.frame_id.tolist(), heads.timestamp_us.tolist()
    out, at = [], 0
    while at < len(ids):
        end = at
        while end + 1 < len(ids) and stamps[end + 1] - stamps[at] <= clip_us:
            end += 1
        out.append(ids[at:end + 1])
        at = end + 1
    return out


@pytest.fixture(scope="module")
def clip_run(frames, tmp_path_factory):
    """One `r2s run --clip 1` of the whole cut, shared: its rows are checked by one test and it is the clip output
    another test tries to add window rows to (that test works on a copy, so the shared output is never written)."""
    out = tmp_path_factory.mktemp("clip-run") / "clips"
    return out, _run(frames, out)


def test_clip_rows_are_r2s_synth_behaviours_on_each_clip(clip_run, frames, log, tmp_path):
    out, proc = clip_run
    rows = pq.read_table(out).to_pandas().set_index("frame_id")
    expected = _clips(log, 1_000_000)
    assert len(expected) == 3 and len(rows) == 3
    assert "3 clips (3 computed, 0 kept)" in _summary(proc.stderr)
    for k, ids in enumerate(expected):
        row = rows.loc[ids[0]]
        paths = []
        for fid in ids:  # each frame as r2s scene gives it, whole (no radius crop: the run does not crop)
            path = tmp_path / f"c{k}-{fid.rsplit('/', 1)[1]}.json"
            path.write_text(scene(frames, fid, radius=1e6).to_json())
            paths.append(str(path))
        synth = run_r2s("synth", *paths, "--behaviours", "--lanes", "--format", "json")
        assert synth.returncode == 0, synth.stderr
        doc = json.loads(synth.stdout)
        assert (row.status, row.cost, row.lower_bound, row.program, row.relational_cost) == \
            (doc["status"], doc["cost"], doc["lower_bound"], doc["program"], doc["relational_cost"])
        assert json.loads(row.boundaries) == doc["boundaries"]
        assert (row.last_frame, row.n_frames, row.clip_s) == (doc["last_frame"], doc["frames"], 1.0)
        assert row.duration_s == pytest.approx(doc["duration_s"], abs=1e-9)
        stamps = [int(log[log.frame_id == f].timestamp_us.iloc[0]) for f in ids]
        assert list(row.timestamps_us) == stamps
        assert (row.first_timestamp_us, row.last_timestamp_us) == (stamps[0], stamps[-1])
        program = tmp_path / f"c{k}.dsl"
        program.write_text(row.program)
        check = run_r2s("check", *paths, str(program))
        assert check.returncode == 0, check.stdout + check.stderr


def test_resume_redoes_a_clip_whose_row_or_timestamp_changed(frames, log, tmp_path):
    out = tmp_path / "clips.parquet"
    _run(frames, out)
    first = pq.read_table(out).to_pandas().set_index("frame_id")
    assert "3 clips (0 computed, 3 kept)" in _summary(_run(frames, out).stderr)
    ids = _clips(log, 1_000_000)
    # A frame inside the second clip (neither its first nor its last) 1 us later: only that clip is redone (a
    # frame's hash does not cover its timestamp; the clip's does).
    later = log.copy()
    later.loc[later.frame_id == ids[1][3], "timestamp_us"] += 1
    changed = _copy(later, tmp_path / "later" / "frames.parquet")
    proc = _run(changed, out)
    assert "3 clips (1 computed, 2 kept)" in _summary(proc.stderr)
    again = pq.read_table(out).to_pandas().set_index("frame_id")
    assert again.loc[ids[1][0], "frame_hash"] != first.loc[ids[1][0], "frame_hash"]
    assert list(again.loc[ids[1][0], "timestamps_us"]) != list(first.loc[ids[1][0], "timestamps_us"])
    # An entity of a frame of the first clip moves: that clip is redone.
    moved = later.copy()
    victim = moved[(moved.frame_id == ids[0][4]) & ~moved.is_ego].index[0]
    moved.loc[victim, "x"] += 0.5
    changed = _copy(moved, tmp_path / "moved" / "frames.parquet")
    assert "3 clips (1 computed, 2 kept)" in _summary(_run(changed, out).stderr)
    # Another clip length is another configuration: every clip redone.
    proc = run_r2s("run", str(changed), "--out", str(out), "--jobs", "2", "--clip", "2", "--lanes")
    assert proc.returncode == 0, proc.stderr
    assert "2 clips (2 computed, 0 kept)" in _summary(proc.stderr)


def test_bad_clip_runs_are_one_line_and_write_nothing(clip_run, frames, log, tmp_path):
    out = tmp_path / "never"
    for more, says in ((("--clip", "0"), "--clip must be a positive"), (("--clip", "nan"), "--clip must be"),
                       (("--clip", "1", "--window", "1"), "give one"), (("--clip", "4000"), "at most"),
                       (("--stride", "1"), "need --window or --clip")):
        more = (*more, "--lanes")
        assert_one_line_error(run_r2s("run", str(frames), "--out", str(out), *more), 2, says)
    no_speed = tmp_path / "no-speed.parquet"
    write_frames(log.drop(columns="speed"), no_speed)
    assert_one_line_error(run_r2s("run", str(no_speed), "--out", str(out), "--clip", "1", "--lanes"), 2, "speed")
    assert_one_line_error(run_r2s("run", str(frames), "--out", str(out), "--clip", "1"), 2, "--clip needs --lanes")
    assert not out.exists()
    # An entity without a speed in one frame: an error row for its clip that names it; the other clips go on.
    gap = log.copy()
    victim = gap[(gap.frame_id == _clips(log, 1_000_000)[0][3]) & ~gap.is_ego].index[0]
    gap.loc[victim, "speed"] = None
    gapped = _copy(gap, tmp_path / "gap" / "frames.parquet")
    _run(gapped, out)
    rows = pq.read_table(out).to_pandas()
    assert sorted(rows.status) == ["error", "optimal", "optimal"]
    error = rows[rows.status == "error"].iloc[0]
    assert f"entity {gap.loc[victim, 'entity_id']!r} has no speed" in error.error
    # Clip rows never go into an output of window or per-frame rows, nor window rows into one of clip rows (a
    # per-frame run drops them, as it drops window rows: docs/formats.md).
    # The window and per-frame outputs come from the first 3 frames: the refusal is about the rows' kind, not their
    # number; the clip output is clip_run's, copied.
    few = _copy(log[log.frame_index < 3], tmp_path / "few" / "frames.parquet")
    for kind, more in (("window", ("--window", "1")), ("per-frame", ())):
        other = tmp_path / kind
        assert run_r2s("run", str(few), "--out", str(other), "--jobs", "2", *more).returncode == 0
        assert_one_line_error(run_r2s("run", str(frames), "--out", str(other), "--clip", "1", "--lanes"), 2,
                              f"{kind} programs")
    clips = tmp_path / "clips"
    (shutil.copytree if clip_run[0].is_dir() else shutil.copy)(clip_run[0], clips)
    before = _contents(clips)
    assert_one_line_error(run_r2s("run", str(frames), "--out", str(clips), "--window", "1"), 2, "clip programs")
    assert _contents(clips) == before
