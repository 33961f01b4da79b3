"""`r2s simulate RUN_OUTPUT --frames FRAMES` as a user runs it: the shipped Argoverse 2 log cut to 2 s (its speeds and
maps), its clip programs made by `r2s run --clip 1 --lanes` (two clips), simulated once each by real workers. The run
is stopped (SIGTERM) after its first clip and resumed; every written variant, read back by pipeline.scenes (not by the
stage), passes `r2s check` as a process; the other verbs read the output; a changed program or recording redoes its
clip only; bad input is one line."""

from __future__ import annotations

import json
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from frames.maps import maps_dir
from frames.rows import write_frames
from pipeline import simulate_run
from pipeline.errors import UserError
from pipeline.scenes import scene
from synth.behaviour.program import ClipProgram, parse_clip_program
from tests.support import ROOT, assert_one_line_error, run_r2s, run_r2s_on_terminal
from tests.support.faults import r2s_with_fault

pytest.importorskip("scenic")

AV2 = ROOT / "data" / "argoverse2-log-excerpt" / "frames.parquet"
N_FRAMES = 20  # 1.9 s at 10 Hz: clips of 1 s are 11 and 9 frames
FLAGS = ("--motion",)


def _frames(df: pd.DataFrame, path: Path) -> Path:
    write_frames(df, path)
    shutil.copytree(maps_dir(AV2), maps_dir(path))
    return path


def _simulate(run_output: Path, frames: Path, out: Path, *more: str) -> list[str]:
    return [sys.executable, "-m", "pipeline.cli", "simulate", str(run_output), "--frames", str(frames), *FLAGS,
            "--n", "1", "--seed", "3", "--out", str(out), *more]


def _rows(out: Path) -> dict[str, dict]:
    """The per-clip rows, by first frame."""
    return {r["frame_id"]: r for r in pq.read_table(out / "_simulations").to_pylist()}


def _sim_files(out: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(out.glob("sim-*.parquet"))}


@pytest.fixture(scope="module")
def log() -> pd.DataFrame:
    df = pd.read_parquet(AV2)
    return df[df.frame_index < N_FRAMES].reset_index(drop=True)


@pytest.fixture(scope="module")
def made(log, tmp_path_factory):
    """The clips' programs, then `r2s simulate` stopped after its first clip (--jobs 1) and resumed (--jobs 2)."""
    root = tmp_path_factory.mktemp("simulate-clips")
    frames = _frames(log, root / "frames.parquet")
    clips = root / "clips"
    proc = run_r2s("run", str(frames), "--clip", "1", "--lanes", *FLAGS, "--jobs", "2", "--out", str(clips))
    assert proc.returncode == 0, proc.stderr
    out = root / "sims"
    stop = subprocess.Popen(_simulate(clips, frames, out, "--jobs", "1", "--log-every", "0"), cwd=ROOT,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    lines = []
    try:
        for line in stop.stderr:  # the progress line after the first clip's row is buffered (--log-every 0)
            lines.append(line.rstrip("\n"))
            if " 1 of 2 clips (" in line:
                stop.send_signal(signal.SIGTERM)
                break
        lines += stop.communicate(timeout=120)[1].splitlines()
    finally:
        if stop.poll() is None:
            stop.kill()
    stopped = (stop.returncode, lines, _sim_files(out), _rows(out))
    resumed = run_r2s_on_terminal("simulate", str(clips), "--frames", str(frames), *FLAGS, "--n", "1", "--seed",
                                  "3", "--jobs", "2", "--out", str(out))
    return frames, clips, out, stopped, resumed


def test_a_stop_keeps_the_finished_clip_and_the_resume_simulates_the_other(made):
    frames, clips, out, (code, lines, files, rows), resumed = made
    assert code == 128 + signal.SIGTERM, lines
    assert any(ln.startswith("r2s simulate: 1 of 2 clips (50.0%), ") and "clips/s, ETA" in ln for ln in lines), lines
    assert f"r2s simulate: stopped: 1 of 2 clips are saved in {out}; run the same command again to resume" in lines
    assert len(rows) == 1 and len(files) == 1
    assert resumed.returncode == 0, resumed.stderr
    assert "resuming: 1 of 2 clips already done" in resumed.stderr
    assert "r2s simulate: 100%" in resumed.stderr and "r2s run" not in resumed.stderr  # the bar names the verb
    assert "2 clips (1 computed, 1 kept)" in resumed.stderr
    now = _sim_files(out)
    assert all(now[name] == data for name, data in files.items())  # the finished clip's variants are untouched
    assert len(now) == 2


def test_each_written_variant_is_the_clips_frames_and_passes_the_checker(made, log, tmp_path):
    frames, clips, out, _, _ = made
    rows = _rows(out)
    recorded = {r["frame_id"]: r for r in pq.read_table(clips).to_pylist()}
    assert set(rows) == set(recorded)  # one row per clip of the run
    (tmp_path / "c.toml").write_text("motion = true\nlanes = true\n")
    index = log.drop_duplicates("frame_id").set_index("frame_id").frame_index
    for first, row in rows.items():
        clip = recorded[first]
        assert row["written"] + row["rejected_by_scenic"] + row["timed_out"] == 1, row
        assert row["rejected_by_checker"] == 0 and row["written"] == 1, row  # what Scenic draws holds the program
        variant = json.loads(row["variants"])[0]
        name = f"{clip['scene']}-clip{index[first]:06d}-sim000"
        assert variant["scene"] == name and variant["outcome"] == "written"
        table = pq.read_table(out / row["frames_file"])
        assert set(table.column("scene").to_pylist()) == {name}
        assert sorted(set(table.column("timestamp_us").to_pylist())) == clip["timestamps_us"]
        # read back as any user reads a frame, then checked by r2s check against the clip program less the
        # entities the simulation could not place
        full = parse_clip_program(clip["program"])
        kept = ClipProgram(full.program, tuple(b for b in full.behaviours if b.id not in row["not_simulated"]))
        (tmp_path / "kept.dsl").write_text(str(kept))
        paths = []
        for k in range(clip["n_frames"]):
            path = tmp_path / f"{name}-{k}.json"
            path.write_text(scene(str(out), f"{name}/{k}").to_json())
            paths.append(str(path))
        ok = run_r2s("check", *paths, str(tmp_path / "kept.dsl"), "--config", str(tmp_path / "c.toml"))
        assert ok.returncode == 0, ok.stdout + ok.stderr


def _variant_scenes(out: Path) -> list[str]:
    return sorted(json.loads(r["variants"])[0]["scene"] for r in _rows(out).values())


def test_a_clips_variant_is_what_r2s_simulate_writes_from_its_scene_files(made, log, tmp_path):
    """Cross-check: the second clip's program and frames given to `r2s simulate PROGRAM.json SCENE...` (frames read
    whole as scene JSON, the program as JSON: another path in) write the same rows, but for the scene's name."""
    frames, _, out, _, _ = made
    row = max(_rows(out).values(), key=lambda r: r["first_timestamp_us"])
    heads = log.drop_duplicates("frame_id").sort_values("frame_index").frame_id.tolist()
    paths = []
    for k, fid in enumerate(heads[heads.index(row["frame_id"]):][:row["n_frames"]]):
        paths.append(tmp_path / f"f{k}.json")
        paths[-1].write_text(scene(str(frames), fid).to_json())
    program = tmp_path / "clip.json"
    program.write_text(json.dumps({"program": row["program"], "boundaries": json.loads(row["boundaries"]),
                                   "frames": row["n_frames"], "first_frame": row["frame_id"],
                                   "last_frame": row["last_frame"]}))
    proc = run_r2s("simulate", str(program), *map(str, paths), *FLAGS, "--lanes", "--n", "1", "--seed", "3", "--out",
                   str(tmp_path / "one"))
    assert proc.returncode == 0, proc.stderr
    names = ["scene", "frame_id", "source"]
    one = pq.read_table(tmp_path / "one" / "part-000000.parquet").drop(names)
    assert pq.read_table(out / row["frames_file"]).drop(names).equals(one)


def test_query_reads_the_output(made, tmp_path):
    out = made[2]
    query = run_r2s("query", str(out), str(ROOT / "data" / "patterns" / "queue-of-three.dsl"), "--out",
                    str(tmp_path / "m.parquet"))
    # every frame of both clips' variants (11 and 9)
    assert query.returncode == 0 and f"{N_FRAMES} frames scanned" in query.stdout, query.stdout + query.stderr


def test_run_reads_the_output(made, tmp_path):
    out = made[2]
    again = run_r2s("run", str(out), "--clip", "1", "--lanes", *FLAGS, "--jobs", "2", "--out", str(tmp_path / "c"))
    assert again.returncode == 0, again.stderr
    assert {r["scene"] for r in pq.read_table(tmp_path / "c").to_pylist() if r["program"]} == set(_variant_scenes(out))


def test_export_scene_reads_the_output(made, tmp_path):
    out = made[2]
    name = _variant_scenes(out)[0]
    export = run_r2s("export", str(out), "--scene", name, "--to", "scenarionet", "--out", str(tmp_path / "x"))
    assert export.returncode == 0 and name in export.stdout, export.stdout + export.stderr


def test_render_reads_the_output(made, log, tmp_path):
    """The recorded first clip with every variant of the output overlaid (the variants of both clips: the same
    entities)."""
    frames, _, out, _, _ = made
    first = min(_rows(out).values(), key=lambda r: r["first_timestamp_us"])
    heads = log.drop_duplicates("frame_id").sort_values("frame_index").frame_id.tolist()
    shots = []
    for k, fid in enumerate(heads[heads.index(first["frame_id"]):][:first["n_frames"]]):
        path = tmp_path / f"r{k}.json"
        path.write_text(scene(str(frames), fid).to_json())
        shots.append(str(path))
    render = run_r2s("render", *shots, "--simulated", str(out), "--out", str(tmp_path / "r.png"))
    assert render.returncode == 0 and (tmp_path / "r.png").stat().st_size > 0, render.stderr


def _rewrite(clips: Path, change) -> None:
    """The run output's rows with `change(rows)` applied, in place (one part, its schema)."""
    [part] = sorted(clips.glob("part-*.parquet"))
    table = pq.read_table(part)
    rows = table.to_pylist()
    change(rows)
    pq.write_table(pa.Table.from_pylist(rows, schema=table.schema), part)


def test_a_changed_program_or_recording_redoes_its_clip_only(made, log, tmp_path):
    frames, clips, out, _, _ = made
    clips2, out2 = tmp_path / "clips", tmp_path / "sims"
    shutil.copytree(clips, clips2)
    shutil.copytree(out, out2)
    before = _rows(out2)
    first, last = sorted(before, key=lambda f: before[f]["first_timestamp_us"])

    def edit(rows):  # the same behaviours, another text: another program for the key
        for r in rows:
            if r["frame_id"] == last:
                r["program"] = r["program"] + "\n"

    _rewrite(clips2, edit)
    # a recording changed under the other clip too: its row is an error (its program is not of these frames)
    changed = log.copy()
    mask = (changed.frame_id == first) & ~changed.is_ego
    changed.loc[mask, "x"] = changed.loc[mask, "x"] + 0.5
    frames2 = _frames(changed, tmp_path / "frames.parquet")
    proc = subprocess.run(_simulate(clips2, frames2, out2, "--jobs", "2"), cwd=ROOT, capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "recomputing 2 clip(s) whose rows changed" in proc.stderr, proc.stderr
    after = _rows(out2)
    assert after[first]["status"] == "error" and "changed since its program was made" in after[first]["error"]
    assert after[first]["frames_file"] is None
    assert after[last]["written"] == 1 and after[last]["frame_hash"] != before[last]["frame_hash"]
    files = _sim_files(out2)
    assert set(files) == {after[last]["frames_file"]}  # nothing stale survives: the old variants are gone


def test_a_clip_past_its_memory_limit_is_a_memout_row_and_the_other_clip_is_simulated(made, tmp_path):
    frames, clips, out, _, _ = made
    first = min(_rows(out).values(), key=lambda r: r["first_timestamp_us"])["frame_id"]
    target = tmp_path / "sims"
    proc = subprocess.run(r2s_with_fault(f"alloc=1500@{first}", "simulate", str(clips), "--frames", str(frames),
                                         *FLAGS, "--n", "1", "--jobs", "2", "--memory-limit", "200", "--out",
                                         str(target)), cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    rows = _rows(target)
    assert rows[first]["status"] == "memout" and rows[first]["frames_file"] is None, rows[first]
    [other] = [r for f, r in rows.items() if f != first]
    assert other["written"] == 1 and set(_sim_files(target)) == {other["frames_file"]}


def test_bad_input_is_one_line(made, log, tmp_path):
    frames, clips, out, _, _ = made
    target = tmp_path / "out"
    assert_one_line_error(run_r2s("simulate", str(frames), "--frames", str(frames), "--out", str(target)), 2,
                          "no clip programs")
    short = _frames(log[log.frame_index < 15], tmp_path / "short.parquet")
    assert_one_line_error(run_r2s("simulate", str(clips), "--frames", str(short), "--out", str(target)), 2,
                          "lacks frames of the clip")
    assert_one_line_error(run_r2s("simulate", str(clips), "--frames", str(frames), "--n", "0", "--out",
                                  str(target)), 2, "--n")
    assert not target.exists()
    target.mkdir()
    (target / "notes.txt").write_text("mine")
    assert_one_line_error(run_r2s("simulate", str(clips), "--frames", str(frames), "--out", str(target)), 2,
                          "not r2s simulate's (notes.txt)")
    assert [p.name for p in target.iterdir()] == ["notes.txt"]
    target = tmp_path / "new"
    with pytest.raises(UserError, match="--n must be"):
        simulate_run(clips, frames, target, n=0)
    assert not target.exists()
