"""The Python API of every verb (docs/api.md) does what the verb does: the same files byte for byte (or the same
rows), the same summary line, the same one-line error for the same bad input. Each verb is run both ways on the
shipped data and compared."""

from __future__ import annotations

import json

import pandas as pd
import pytest

from pipeline.errors import UserError
from synth.errors import InputError
from tests.support import ROOT, assert_one_line_error, run_r2s

KEYFRAMES = ROOT / "data" / "nuscenes-mini-keyframes" / "frames.parquet"
EXCERPT = ROOT / "data" / "nuscenes-mini-excerpt" / "scenarionet"
FRAME = "scene-0061/0"


def test_extract_writes_what_r2s_extract_writes_and_says_the_same(tmp_path):
    from pipeline import extract

    proc = run_r2s("extract", "scenarionet", str(EXCERPT), "--out", str(tmp_path / "cli.parquet"))
    assert proc.returncode == 0, proc.stderr
    summary = extract("scenarionet", EXCERPT, tmp_path / "api.parquet")
    assert pd.read_parquet(tmp_path / "api.parquet").equals(pd.read_parquet(tmp_path / "cli.parquet"))
    line = proc.stderr.strip().splitlines()[-1]
    assert line == f"r2s extract: {summary.line()}".replace(str(tmp_path / "api.parquet"), str(tmp_path / "cli.parquet"))
    assert summary.frames == pd.read_parquet(tmp_path / "api.parquet").frame_id.nunique() > 0


@pytest.mark.parametrize("kwargs,words", [
    ({"categories": "Hovercraft"}, "Hovercraft"),
    ({"jobs": 0}, "--jobs"),
    ({"topics": ("a",)}, "no option 'topics'"),
])
def test_extract_refuses_bad_options_before_writing(tmp_path, kwargs, words):
    from pipeline import extract

    with pytest.raises(InputError, match=words):
        extract("scenarionet", EXCERPT, tmp_path / "f.parquet", **kwargs)
    assert not list(tmp_path.iterdir())
    with pytest.raises(InputError, match="unknown source"):
        extract("waymo", EXCERPT, tmp_path / "f.parquet")


def test_scene_from_a_file_is_r2s_scene_and_from_rows_is_the_same_frame():
    from pipeline import scene

    proc = run_r2s("scene", str(KEYFRAMES), FRAME)
    assert proc.returncode == 0, proc.stderr
    assert scene(KEYFRAMES, FRAME).to_json() == proc.stdout
    rows = pd.read_parquet(KEYFRAMES)
    want = json.loads(proc.stdout)
    want.pop("road", None)
    # A whole table with the frame's id, one frame's rows, and its rows as records (what scene_from_dict refused).
    one = rows[rows.frame_id == FRAME]
    for given in (scene(rows, FRAME), scene(one), scene(one.to_dict("records")), scene(one.reset_index(drop=True))):
        got = given.to_dict()
        got.pop("road", None)
        assert got == want


def test_scene_says_which_frame_when_the_rows_hold_several_and_names_unknown_ids():
    from pipeline import scene

    rows = pd.read_parquet(KEYFRAMES)
    with pytest.raises(UserError, match="242 frames"):
        scene(rows)
    with pytest.raises(UserError, match="no frame 'nope'"):
        scene(rows, "nope")
    proc = run_r2s("scene", str(KEYFRAMES), "scene-0061/99")
    with pytest.raises(UserError) as err:
        scene(KEYFRAMES, "scene-0061/99")
    assert proc.stderr.strip() == f"r2s scene: {err.value}"
    bad = rows[rows.frame_id == FRAME].drop(columns=["entity_id"])
    with pytest.raises(InputError, match="entity_id"):
        scene(bad)


@pytest.fixture(scope="module")
def frame(tmp_path_factory):
    """One real frame's scene JSON, its DSL program and its Scenic text, written by the verbs."""
    d = tmp_path_factory.mktemp("api")
    for args in (("scene", str(KEYFRAMES), "scene-0103/0", "--out", str(d / "scene.json")),
                 ("synth", str(d / "scene.json"), "--out", str(d / "scene.dsl")),
                 ("synth", str(d / "scene.json"), "--format", "scenic", "--out", str(d / "scene.scenic"))):
        proc = run_r2s(*args)
        assert proc.returncode == 0, proc.stderr
    return d


def test_sample_draws_what_r2s_sample_draws_by_every_route(frame, tmp_path):
    from pipeline import sample

    proc = run_r2s("sample", str(frame / "scene.scenic"), "--n", "3", "--seed", "7", "--out", str(tmp_path / "v"))
    assert proc.returncode == 0, proc.stderr
    files = [json.loads(f.read_text()) for f in sorted((tmp_path / "v").glob("sample_*.json"))]
    scenic = sample((frame / "scene.scenic").read_text(), n=3, seed=7)
    assert [s.to_dict() for s in scenic.scenes] == files
    # The DSL route with the scene as a dict, and as the CLI's --program route.
    dsl = sample((frame / "scene.dsl").read_text(), json.loads((frame / "scene.json").read_text()), n=3, seed=7)
    proc = run_r2s("sample", "--program", str(frame / "scene.dsl"), "--scene", str(frame / "scene.json"), "--n", "3",
                   "--seed", "7", "--out", str(tmp_path / "d"))
    assert proc.returncode == 0, proc.stderr
    assert [s.to_dict() for s in dsl.scenes] == [json.loads(f.read_text())
                                                 for f in sorted((tmp_path / "d").glob("sample_*.json"))]


def test_sample_refuses_what_r2s_sample_refuses(frame):
    from pipeline import sample

    with pytest.raises(UserError, match="needs the scene"):
        sample(object())
    with pytest.raises(UserError, match="give a program"):
        sample()
    with pytest.raises(InputError, match="seed"):
        sample((frame / "scene.scenic").read_text(), seed=-1)
    with pytest.raises(InputError, match="r2s-source"):
        sample("ego = new Car at 0 @ 0\n")


def test_render_writes_the_bytes_r2s_render_writes(frame, tmp_path):
    from pipeline import render

    proc = run_r2s("render", str(frame / "scene.json"), "--program", str(frame / "scene.dsl"), "--samples", "2",
                   "--out", str(tmp_path / "cli.png"))
    assert proc.returncode == 0, proc.stderr
    scene = json.loads((frame / "scene.json").read_text())
    path = render(scene, tmp_path / "api.png", program=(frame / "scene.dsl").read_text(), samples=2)
    assert path.read_bytes() == (tmp_path / "cli.png").read_bytes()
    with pytest.raises(UserError, match="must end in"):
        render(scene, tmp_path / "x.gif")
    with pytest.raises(UserError, match="--samples needs --program"):
        render(scene, tmp_path / "x.png", samples=2)
    assert not (tmp_path / "x.png").exists()


@pytest.fixture(scope="module")
def programs(tmp_path_factory):
    """A run's programs over four real frames."""
    from pipeline import run_frames

    d = tmp_path_factory.mktemp("run")
    rows = pd.read_parquet(KEYFRAMES)
    rows[rows.frame_id.isin(sorted(set(rows.frame_id))[:4])].to_parquet(d / "frames.parquet")
    run_frames(d / "frames.parquet", d / "programs", jobs=1, log=lambda _: None)
    return d / "programs"


def test_sample_programs_frame_samples_the_run_s_program_of_that_frame(programs, tmp_path):
    """`r2s sample --programs PROGRAMS FRAME` (and sample(programs=, frame_id=)) is `r2s sample` of the frame's
    scenic column, as a user would dig it out with pandas."""
    from pipeline import sample

    table = pd.read_parquet(programs)
    fid = sorted(table.frame_id)[1]
    (tmp_path / "dug.scenic").write_text(table[table.frame_id == fid].scenic.iloc[0])
    want = run_r2s("sample", str(tmp_path / "dug.scenic"), "--n", "2", "--seed", "3", "--out", str(tmp_path / "a"))
    got = run_r2s("sample", "--programs", str(programs), fid, "--n", "2", "--seed", "3", "--out", str(tmp_path / "b"))
    assert want.returncode == got.returncode == 0, (want.stderr, got.stderr)
    files = sorted(f.name for f in (tmp_path / "a").iterdir())
    assert files and files == sorted(f.name for f in (tmp_path / "b").iterdir())
    assert all((tmp_path / "a" / f).read_bytes() == (tmp_path / "b" / f).read_bytes() for f in files)
    api = sample(programs=programs, frame_id=fid, n=2, seed=3)
    assert [s.to_json() for s in api.scenes] == [(tmp_path / "a" / f).read_text() for f in files]
    # An unknown frame, and the routes mixed up: one line, nothing written.
    for args, words in ((("--programs", str(programs), "nope/0"), "no program for frame 'nope/0'"),
                        (("--programs", str(programs)), "takes the frame id"),
                        (("--programs", str(programs), fid, "--scene", "s.json"), "takes the frame id"),
                        (("--programs", str(programs), fid, "--program", "p.dsl"), "give either")):
        proc = run_r2s("sample", *args, "--out", str(tmp_path / "c"))
        assert_one_line_error(proc, contains=words)
        assert words in proc.stderr and not (tmp_path / "c").exists()


def test_report_writes_what_r2s_report_writes(programs, tmp_path):
    from pipeline.report import report

    proc = run_r2s("report", str(programs), "--out", str(tmp_path / "cli"))
    assert proc.returncode == 0, proc.stderr
    summary = report(programs, tmp_path / "api")
    assert proc.stdout.strip() == f"r2s report: {summary.line} -> {tmp_path / 'cli' / 'report.html'}"
    assert summary.html == tmp_path / "api" / "report.html"
    assert (tmp_path / "api" / "report.md").read_text() == (tmp_path / "cli" / "report.md").read_text()
    with pytest.raises(UserError, match="needs --frames"):
        report(programs, tmp_path / "q", query="p = new Car ahead of ego by Range(0, 10)")
    assert not (tmp_path / "q").exists()
