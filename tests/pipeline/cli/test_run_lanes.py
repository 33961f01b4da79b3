"""`r2s run --lanes` as a user runs it: each frame is synthesized on the scene `r2s scene` writes (its road from
the maps beside the frames), so every program passes `r2s check` on that scene; frames without a map are error
rows naming the missing road."""

from __future__ import annotations

import pandas as pd

from tests.support import ROOT, run_r2s


def test_every_program_of_a_lanes_run_holds_on_the_scene_r2s_scene_writes(excerpt_frames, tmp_path):
    out = tmp_path / "programs"
    proc = run_r2s("run", str(excerpt_frames), "--lanes", "--out", str(out), "--jobs", "1")
    assert proc.returncode == 0, proc.stderr
    programs = pd.read_parquet(out)
    assert len(programs) == pd.read_parquet(excerpt_frames, columns=["frame_id"]).frame_id.nunique()
    assert (programs.status == "optimal").all(), programs.error.tolist()
    for row in programs.itertuples():
        scene, program = tmp_path / "scene.json", tmp_path / "program.dsl"
        proc = run_r2s("scene", str(excerpt_frames), row.frame_id, "--out", str(scene))
        assert proc.returncode == 0, proc.stderr
        program.write_text(row.program)
        assert all(", in " in line or ", on " in line or ", off " in line for line in row.program.splitlines())
        proc = run_r2s("check", str(scene), str(program), "--config", str(_lanes_config(tmp_path)))
        assert proc.returncode == 0, proc.stdout + proc.stderr


def _lanes_config(tmp_path):
    path = tmp_path / "lanes.toml"
    path.write_text("[synth]\nlanes = true\n")
    return path


def test_frames_without_a_map_are_error_rows_naming_the_road(tmp_path):
    out = tmp_path / "programs"
    frames = ROOT / "data" / "nuscenes-mini-keyframes" / "frames.parquet"
    proc = run_r2s("run", str(frames), "--lanes", "--out", str(out), "--jobs", "1", "--chunk-size", "64")
    assert proc.returncode == 0, proc.stderr
    programs = pd.read_parquet(out)
    assert (programs.status == "error").all() and programs.error.str.contains("has no road").all()
