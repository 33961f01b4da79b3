"""`r2s extract --jobs N` and dataset outputs, as a user runs them: the same frames as one reader gives, in the
same order, whatever the number of workers; bad input leaves nothing behind."""

from __future__ import annotations

import shutil
from pathlib import Path

import pandas as pd

from tests.support import ROOT, assert_one_line_error, run_r2s

EXCERPT = ROOT / "data" / "nuscenes-mini-excerpt" / "scenarionet"


def _leftovers(out: Path) -> list[str]:
    return [p.name for p in out.parent.iterdir() if p.name.startswith(f".{out.name}")]


def test_parallel_extraction_gives_the_frames_of_one_reader(tmp_path):
    one = tmp_path / "one.parquet"
    assert run_r2s("extract", "scenarionet", str(EXCERPT), "--categories", "all", "--out", str(one)).returncode == 0
    expected = pd.read_parquet(one)
    for jobs, out in (("2", tmp_path / "frames"), ("2", tmp_path / "merged.parquet"), ("1", tmp_path / "seq")):
        proc = run_r2s("extract", "scenarionet", str(EXCERPT), "--categories", "all", "--out", str(out),
                       "--jobs", jobs)
        assert proc.returncode == 0, proc.stderr
        assert f"3 scenarios, {expected['frame_id'].nunique()} frames, {len(expected)} rows -> {out}" in proc.stderr
        got = pd.read_parquet(out)
        pd.testing.assert_frame_equal(got, expected)  # same rows, same order: parts follow the input's order
        assert _leftovers(out) == []
    parts = [f"part-{i:06d}.parquet" for i in range(3)]
    assert sorted(p.name for p in (tmp_path / "frames").iterdir()) == ["_maps"] + parts
    # each scenario's map once, in the part named like its frames' part; a file output keeps them beside it
    maps = pd.read_parquet(tmp_path / "frames" / "_maps")
    assert sorted(p.name for p in (tmp_path / "frames" / "_maps").iterdir()) == parts
    assert list(maps.drop_duplicates("map_id").map_id) == list(expected.drop_duplicates("scene").scene)
    pd.testing.assert_frame_equal(pd.read_parquet(tmp_path / "merged.maps"), maps)
    pd.testing.assert_frame_equal(pd.read_parquet(one.with_suffix(".maps")), maps)
    # A frames dataset is a run's input as it is.
    proc = run_r2s("scene", str(tmp_path / "frames"), expected["frame_id"].iloc[-1])
    assert proc.returncode == 0 and '"frame_id"' in proc.stdout


def test_a_scene_given_twice_is_read_once_as_by_one_reader(tmp_path):
    db = tmp_path / "db"
    db.mkdir()
    first = sorted(EXCERPT.glob("sd_*.pkl"))[0]
    shutil.copy(first, db / "a.pkl")
    shutil.copy(first, db / "b.pkl")  # the same scenario id in a second file
    out = tmp_path / "frames"
    proc = run_r2s("extract", "scenarionet", str(db), "--categories", "all", "--out", str(out), "--jobs", "2")
    assert proc.returncode == 0, proc.stderr
    assert "skipping" in proc.stderr and "b.pkl" in proc.stderr and "already read from" in proc.stderr
    assert sorted(p.name for p in out.iterdir()) == ["_maps", "part-000000.parquet"]
    assert [p.name for p in (out / "_maps").iterdir()] == ["part-000000.parquet"]


def test_bad_input_writes_nothing_and_an_old_output_stays(tmp_path):
    db = tmp_path / "db"
    db.mkdir()
    shutil.copy(sorted(EXCERPT.glob("sd_*.pkl"))[0], db / "a.pkl")
    (db / "b.pkl").write_bytes(b"not a pickle")
    out = tmp_path / "frames"
    proc = run_r2s("extract", "scenarionet", str(db), "--out", str(out), "--jobs", "2")
    assert_one_line_error(proc, 2)
    assert not out.exists() and _leftovers(out) == []
    assert run_r2s("extract", "scenarionet", str(EXCERPT), "--out", str(out), "--jobs", "2").returncode == 0
    before = {str(p.relative_to(out)): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    proc = run_r2s("extract", "scenarionet", str(db), "--out", str(out), "--jobs", "2")
    assert_one_line_error(proc, 2)
    assert {str(p.relative_to(out)): p.read_bytes() for p in out.rglob("*") if p.is_file()} == before
    assert _leftovers(out) == []
    (out / "notes.txt").write_text("mine")
    proc = run_r2s("extract", "scenarionet", str(EXCERPT), "--out", str(out), "--jobs", "2")
    assert_one_line_error(proc, 2, "not frames parts")
    assert_one_line_error(run_r2s("extract", "scenarionet", str(EXCERPT), "--out", str(tmp_path / "x"), "--jobs", "0"),
                          2, "--jobs")


def test_frame_ids_are_compared_across_parts_by_the_workers_hashes(tmp_path):
    """The coordinator does not re-read the parts (each was validated as it was written): it compares the frame-id
    hashes the workers return, and only a clash sends it to the full check, which names the frame."""
    import pytest

    from extractors.base import ExtractOptions
    from extractors.categories import ALL
    from extractors.registry import source
    from frames.rows import FramesError
    from pipeline.batch.extract import _check, extract_unit

    stage = tmp_path / "stage"
    stage.mkdir()
    scenario = str(sorted(EXCERPT.glob("sd_*.pkl"))[0])
    first = extract_unit(source("scenarionet"), scenario, 0, ExtractOptions(categories=ALL), str(stage))
    again = extract_unit(source("scenarionet"), scenario, 1, ExtractOptions(categories=ALL), str(stage))
    assert first.frames > 0 and len(first.frame_hashes[0]) == first.frames
    with pytest.raises(FramesError, match="two places"):
        _check(stage, [first, again])
    # Distinct ids: the parts are not opened (an unreadable one stays unnoticed here; the writer validated it).
    (stage / "part-000001.parquet").write_bytes(b"not parquet")
    _check(stage, [first])
