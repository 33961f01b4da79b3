"""No verb overwrites its own input (issue 22 item 6): an output that is an input (the same path, a symlink to it,
a hard link), inside an input dataset directory, or holding an input, is refused with one line and exit 2 before
any work, and the input is left byte for byte as it was. Real `r2s` processes."""

from __future__ import annotations

import hashlib
import os
import shutil
from pathlib import Path

import pytest

from tests.support import ROOT, assert_one_line_error, run_r2s

FRAMES = ROOT / "data" / "nuscenes-mini-keyframes" / "frames.parquet"
PATTERN = ROOT / "data" / "patterns" / "queue-of-three.dsl"
EXCERPT = ROOT / "data" / "nuscenes-mini-excerpt" / "scenarionet"
FRAME = "scene-0103/0"


def _digest(path: Path) -> dict[str, str]:
    """Every file under a path (or the file itself) and the hash of its bytes."""
    files = [path] if path.is_file() else sorted(p for p in path.rglob("*") if p.is_file())
    return {str(f): hashlib.sha256(f.read_bytes()).hexdigest() for f in files}


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("inputs")
    frames = d / "frames.parquet"
    shutil.copy(FRAMES, frames)
    dataset = d / "dataset"
    dataset.mkdir()
    shutil.copy(FRAMES, dataset / "part-000000.parquet")
    pattern = d / "pattern.dsl"
    shutil.copy(PATTERN, pattern)
    scene, program, scenic = d / "scene.json", d / "program.dsl", d / "program.scenic"
    assert run_r2s("scene", str(frames), FRAME, "--out", str(scene)).returncode == 0
    assert run_r2s("synth", str(scene), "--out", str(program)).returncode == 0
    assert run_r2s("synth", str(scene), "--format", "scenic", "--out", str(scenic)).returncode == 0
    extract_in = d / "scenarionet"
    shutil.copytree(EXCERPT, extract_in)
    return {"frames": frames, "dataset": dataset, "pattern": pattern, "scene": scene, "program": program,
            "scenic": scenic, "extract_in": extract_in, "dir": d}


# (verb arguments with {name} for an input path, the input that must survive, where --out points: "same",
# "link" (a symlink to the input), "inside" (a file in the input directory)
CASES = [
    ("query {frames} {pattern}", "frames", "same"),
    ("query {frames} {pattern}", "pattern", "same"),
    ("query {frames} {pattern}", "frames", "link"),
    ("query {dataset} {pattern}", "dataset", "inside"),
    ("scene {frames} " + FRAME, "frames", "same"),
    ("scene {dataset} " + FRAME, "dataset", "inside"),
    ("synth {scene}", "scene", "same"),
    ("synth {scene}", "scene", "hardlink"),
    ("synth {scene} --format json", "scene", "link"),
    ("sample {scenic}", "scenic", "same"),
    ("sample --program {program} --scene {scene}", "scene", "same"),
    ("render {scene} --program {program}", "program", "same"),
    ("extract scenarionet {extract_in}", "extract_in", "same"),
    ("extract scenarionet {extract_in}", "extract_in", "inside"),
    ("run {frames}", "frames", "link"),
    ("run {dataset}", "dataset", "inside"),
    ("eval-frontend {frames} {frames}", "frames", "same"),
    ("report {dataset}", "dataset", "same"),
]


@pytest.mark.parametrize(("command", "victim", "where"), CASES)
def test_an_output_that_is_an_input_is_refused_and_the_input_survives(inputs, tmp_path, command, victim, where):
    target = inputs[victim]
    if where == "same":
        out = target
    elif where == "link":
        out = tmp_path / f"link{target.suffix}"
        out.symlink_to(target)
    elif where == "hardlink":
        out = tmp_path / f"hard{target.suffix}"
        os.link(target, out)
    else:
        out = target / ("out.parquet" if command.startswith(("query", "run")) else "out.json")
    before = _digest(target)
    args = command.format(**{k: str(v) for k, v in inputs.items()}).split()
    proc = run_r2s(*args, "--out", str(out))
    assert_one_line_error(proc, 2)
    assert "--out" in proc.stderr and ("is the" in proc.stderr or "inside" in proc.stderr), proc.stderr
    assert _digest(target) == before
    assert not [p.name for p in inputs["dir"].iterdir() if p.name.startswith(".")]  # no temporaries left


def test_an_input_inside_the_output_directory_is_refused(inputs, tmp_path):
    """`report --out D` replaces D whole: programs or frames inside D would be deleted with it."""
    d = tmp_path / "work"
    d.mkdir()
    shutil.copy(inputs["frames"], d / "frames.parquet")
    before = _digest(d)
    proc = run_r2s("eval-frontend", str(d / "frames.parquet"), str(d / "frames.parquet"), "--out", str(d))
    assert_one_line_error(proc, 2, contains="is inside --out")
    proc = run_r2s("report", str(d / "frames.parquet"), "--out", str(d))
    assert_one_line_error(proc, 2, contains="is inside --out")
    assert _digest(d) == before


def test_a_full_disk_during_sample_leaves_no_samples(inputs, tmp_path):
    """50 variants do not fit on a 64 KB disk: the verb says so in one line and the output has none of them (they
    are written beside it and moved in only when all are), nor any temporary."""
    from tests.support.faults import small_filesystem

    with small_filesystem(tmp_path / "disk", size_kb=64) as disk:
        out = disk / "samples"
        out.mkdir()
        (out / "notes.txt").write_text("mine")
        proc = run_r2s("sample", "--program", str(inputs["program"]), "--scene", str(inputs["scene"]), "--n", "50",
                       "--allow-collisions", "--out", str(out))
        assert_one_line_error(proc, 2, contains="no space left on device")
        assert sorted(p.name for p in disk.rglob("*")) == ["notes.txt", "samples"]
        proc = run_r2s("sample", "--program", str(inputs["program"]), "--scene", str(inputs["scene"]), "--n", "2",
                       "--allow-collisions", "--out", str(out))
        assert proc.returncode == 0, proc.stderr
        assert sorted(p.name for p in out.iterdir()) == ["notes.txt", "sample_000.json", "sample_001.json"]
