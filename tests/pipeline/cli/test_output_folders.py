"""Output folders never lose or hide a user's files (issue 35 items 1, 15, 16), for every verb with --out, as real
`r2s` processes: a folder replaced whole (export, report, extract --out DIR) is replaced only when absent, empty
or an earlier output of the verb; never the working directory (--out .); a symbolic link is written through and
stays a link (one that points nowhere yet too); a loop of links, a directory where one file goes: one line, exit 2,
nothing written."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
from pathlib import Path

import pytest

from tests.support import ROOT, assert_one_line_error, run_r2s, wait_for_file
from tests.support.faults import r2s_with_fault

EXCERPT = ROOT / "data" / "nuscenes-mini-excerpt" / "scenarionet"
KEYFRAMES = ROOT / "data" / "nuscenes-mini-keyframes" / "frames.parquet"


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("inputs")
    frames, scene, scenic, programs = d / "frames.parquet", d / "scene.json", d / "scene.scenic", d / "programs"
    for args in (("extract", "scenarionet", str(EXCERPT), "--out", str(frames)),
                 ("scene", str(frames), "scene-0061/0", "--out", str(scene)),
                 ("synth", str(scene), "--format", "scenic", "--out", str(scenic)),
                 ("run", str(frames), "--out", str(programs))):
        res = run_r2s(*args)
        assert res.returncode == 0, res.stderr
    return {"frames": frames, "scene": scene, "scenic": scenic, "programs": programs}


# The verbs that replace a folder whole: their arguments before --out, and a file their output holds.
REPLACING = {
    "export scenarionet": ("export {scene} --to scenarionet", "dataset_summary.pkl"),
    "export openscenario": ("export {scene} --to openscenario", "scene-0061_0.xodr"),
    "report": ("report {programs}", "report.html"),
    "extract": (f"extract scenarionet {EXCERPT}", "part-000000.parquet"),
}
# The verbs that add their files to a folder (the others' stay) and the file they write.
ADDING = {
    "sample": ("sample {scenic} --n 2", "sample_000.json"),
    "eval-frontend": ("eval-frontend {frames} {frames}", "metrics.json"),
    "run": ("run {frames}", "part-000000.parquet"),
}


def _r2s(command: str, inputs: dict[str, Path], out: str, cwd: Path):
    return run_r2s(*command.format(**inputs).split(), "--out", out, cwd=cwd)


def _tree(folder: Path) -> dict[str, bytes | str]:
    """Every entry under a folder, hidden ones too: a file's bytes, a link's target."""
    return {str(p.relative_to(folder)): os.readlink(p) if p.is_symlink() else p.read_bytes() if p.is_file() else "/"
            for p in sorted(folder.rglob("*"))}


@pytest.mark.parametrize("verb", REPLACING)
def test_a_folder_of_the_user_s_files_is_refused_and_kept(verb, inputs, tmp_path):
    command, _ = REPLACING[verb]
    (tmp_path / "precious").mkdir()
    (tmp_path / "precious" / "thesis.txt").write_text("keep")
    before = _tree(tmp_path)
    assert_one_line_error(_r2s(command, inputs, "precious", tmp_path), contains="thesis.txt")
    assert _tree(tmp_path) == before


@pytest.mark.parametrize("verb", REPLACING)
def test_the_working_directory_is_refused(verb, inputs, tmp_path):
    command, _ = REPLACING[verb]
    here = tmp_path / "here"
    here.mkdir()
    assert_one_line_error(_r2s(command, inputs, ".", here), contains="working directory")
    assert _tree(tmp_path) == {"here": "/"}


@pytest.mark.parametrize("verb", REPLACING)
def test_a_link_is_written_through_and_stays_a_link(verb, inputs, tmp_path):
    """A link that points nowhere yet: the folder is made where it points; again, over the earlier output: the
    folder it points to is replaced, and nothing is left beside either (no hidden link, no temporary)."""
    command, written = REPLACING[verb]
    (tmp_path / "out").symlink_to("real")
    for _ in range(2):
        res = _r2s(command, inputs, "out", tmp_path)
        assert res.returncode == 0, res.stderr
        assert os.readlink(tmp_path / "out") == "real" and (tmp_path / "real" / written).is_file()
        assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "real"]


@pytest.mark.parametrize("verb", ADDING)
def test_verbs_that_add_files_write_through_a_link_and_keep_the_user_s(verb, inputs, tmp_path):
    command, written = ADDING[verb]
    (tmp_path / "out").symlink_to("real")
    res = _r2s(command, inputs, "out", tmp_path)
    assert res.returncode == 0, res.stderr
    assert (tmp_path / "real" / written).is_file() and os.readlink(tmp_path / "out") == "real"
    if verb != "run":  # a run's folder holds its parts only: another file is refused (tests/pipeline/batch)
        (tmp_path / "real" / "thesis.txt").write_text("keep")
        res = _r2s(command, inputs, "out", tmp_path)
        assert res.returncode == 0, res.stderr
        assert (tmp_path / "real" / "thesis.txt").read_text() == "keep"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "real"]


@pytest.mark.parametrize("verb", [*REPLACING, *ADDING])
def test_a_loop_of_links_is_one_line(verb, inputs, tmp_path):
    command, _ = {**REPLACING, **ADDING}[verb]
    (tmp_path / "a").symlink_to("b")
    (tmp_path / "b").symlink_to("a")
    assert_one_line_error(_r2s(command, inputs, "a", tmp_path), contains="loop of symbolic links")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a", "b"]


@pytest.mark.parametrize("command", ["scene {frames} scene-0061/0", "synth {scene}"])
def test_one_file_outputs(command, inputs, tmp_path):
    """A directory where one file goes (--out . too) is one line, exit 2; a link to a file is written through."""
    (tmp_path / "folder").mkdir()
    for out in (".", "folder"):
        assert_one_line_error(_r2s(command, inputs, out, tmp_path), contains="is a directory")
    (tmp_path / "old.txt").write_text("old")
    (tmp_path / "link").symlink_to("old.txt")
    res = _r2s(command, inputs, "link", tmp_path)
    assert res.returncode == 0, res.stderr
    assert os.readlink(tmp_path / "link") == "old.txt" and (tmp_path / "old.txt").read_text() != "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["folder", "link", "old.txt"]


def test_an_earlier_export_of_the_other_target_is_replaced_and_foreign_scenarios_are_not(inputs, tmp_path):
    for to in ("openscenario", "scenarionet", "openscenario"):
        res = _r2s(f"export {{scene}} --to {to}", inputs, "db", tmp_path)
        assert res.returncode == 0, res.stderr
    assert sorted(p.suffix for p in (tmp_path / "db").iterdir()) == [".xodr", ".xosc"]
    shutil.copy(tmp_path / "db" / "scene-0061_0.xosc", tmp_path / "db" / "theirs.xosc")
    (tmp_path / "db" / "theirs.xosc").write_text((tmp_path / "db" / "theirs.xosc").read_text()
                                                 .replace('author="r2sgen', 'author="someone'))
    assert_one_line_error(_r2s("export {scene} --to scenarionet", inputs, "db", tmp_path), contains="theirs.xosc")


@pytest.mark.parametrize("command", ["scene {frames} scene-0061/0", "synth {scene}", "render {scene}",
                                     f"query {{frames}} {ROOT / 'data' / 'patterns' / 'queue-of-three.dsl'}"])
def test_a_loop_of_links_for_one_file_is_one_line(command, inputs, tmp_path):
    (tmp_path / "a.png").symlink_to("b.png")
    (tmp_path / "b.png").symlink_to("a.png")
    assert_one_line_error(_r2s(command, inputs, "a.png", tmp_path), contains="loop of symbolic links")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.png", "b.png"]


def test_the_maps_beside_a_frames_file_are_replaced_through_their_link(tmp_path):
    """r2s extract --out F.parquet replaces F.maps/ (the maps of its scenarios): a link there is written through
    and stays; a user's file in the folder it points to is refused and kept."""
    command = f"extract scenarionet {EXCERPT}"
    res = _r2s(command, {}, "f.parquet", tmp_path)
    assert res.returncode == 0, res.stderr
    (tmp_path / "f.maps").rename(tmp_path / "real")
    (tmp_path / "f.maps").symlink_to("real")
    for jobs in ("1", "2"):
        res = run_r2s(*command.split(), "--out", "f.parquet", "--jobs", jobs, cwd=tmp_path)
        assert res.returncode == 0, res.stderr
        assert sorted(p.name for p in tmp_path.iterdir()) == ["f.maps", "f.parquet", "real"]
        assert os.readlink(tmp_path / "f.maps") == "real" and list((tmp_path / "real").glob("part-*.parquet"))
    (tmp_path / "real" / "notes.txt").write_text("keep")
    assert_one_line_error(_r2s(command, {}, "f.parquet", tmp_path), contains="notes.txt")
    assert (tmp_path / "real" / "notes.txt").read_text() == "keep"


def test_a_run_through_a_link_holds_the_lock_of_the_folder_it_writes(inputs, tmp_path):
    """Two runs on one folder, one naming it through a link: the second is refused (their locks were two files)."""
    (tmp_path / "real").mkdir()
    (tmp_path / "link").symlink_to("real")
    first = subprocess.Popen(r2s_with_fault("sleep=120@*", "run", str(inputs["frames"]), "--out",
                                            str(tmp_path / "link"), "--jobs", "1"),
                             cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        assert wait_for_file(tmp_path / ".real.lock")
        second = run_r2s("run", str(inputs["frames"]), "--out", str(tmp_path / "real"))
        assert_one_line_error(second, 2, contains=f"another r2s run (pid {first.pid} on ")
    finally:
        os.killpg(first.pid, signal.SIGKILL)
        first.wait(timeout=30)


@pytest.mark.parametrize("command, out", [
    *[(c, "x") for c, _ in (*REPLACING.values(), *ADDING.values())],
    ("scene {frames} scene-0061/0", "x.json"), ("synth {scene}", "x.dsl"), ("render {scene}", "x.png"),
    (f"query {{frames}} {ROOT / 'data' / 'patterns' / 'queue-of-three.dsl'}", "x.parquet"),
    (f"extract scenarionet {EXCERPT}", "x.parquet")])
def test_an_output_below_a_file_is_one_line_before_any_work(command, out, inputs, tmp_path):
    (tmp_path / "file").write_text("keep")
    assert_one_line_error(_r2s(command, inputs, f"file/{out}", tmp_path), contains="which is not a directory")
    assert _tree(tmp_path) == {"file": b"keep"}
