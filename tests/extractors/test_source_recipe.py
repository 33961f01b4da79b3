"""The recipe of docs/layout.md ("Add a source"), as written there: its module, saved where Python finds it and
named in the registry, is a source like the others through `r2s extract`: frames out, `--jobs` pieces, its own
options, its categories, and a line naming it when its input is given to another source (and the other way)."""

from __future__ import annotations

import math
import os
import re
import sys

import pandas as pd
import pytest
from joblib.externals.loky import get_reusable_executor

from extractors.registry import SOURCES
from frames.rows import read_frames
from tests.support import ROOT
from tests.support.extract import EXCERPT, assert_refused, r2s

MODULE = "toy_recipe_source"
CLASSES = {"car": "Car", "walker": "Pedestrian"}  # what the recipe's taxonomy says, read by a person
LOGS = {  # scene -> lines: frame track category x y heading
    "crossing": ["0 c1 car 0 8 0", "0 w1 walker -3 4 90", "0 k1 kite 1 1 0", "1 c1 car 0 9 0",
                 "1 w1 walker -2 4 90", "2 c1 car 0 10 0"],
    "queue": ["0 c1 car 0 6 0", "0 c2 car 0 12 0", "0 c3 car 0 18 0", "1 c2 car 0 11 0"],
}


def recipe() -> str:
    text = (ROOT / "docs" / "layout.md").read_text()
    section = text[text.index("### Add a source"):]
    return re.search(r"```python\n(.*?)```", section, re.S).group(1)


@pytest.fixture
def toy(tmp_path, monkeypatch):
    """The recipe's module importable (here and in --jobs workers) and registered; a folder of two toy logs."""
    code = tmp_path / "code"
    code.mkdir()
    (code / f"{MODULE}.py").write_text(recipe())
    monkeypatch.syspath_prepend(str(code))
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(filter(None, [str(code), os.environ.get("PYTHONPATH")])))
    monkeypatch.setitem(SOURCES, "toy", MODULE)
    # --jobs workers left by an earlier test started without the module's folder: start afresh
    get_reusable_executor(max_workers=2).shutdown(wait=True)
    logs = tmp_path / "logs"
    logs.mkdir()
    for scene, lines in LOGS.items():
        (logs / f"{scene}.toy").write_text("\n".join(["#toy", *lines]) + "\n")
    yield logs
    sys.modules.pop(MODULE, None)


def expected(scale: float, keep: set[str]) -> pd.DataFrame:
    """The frames by hand from the log lines: ego first, then the kept objects by distance; ids stable across the
    scene (docs/formats.md: per type by first appearance, ties by distance then track)."""
    rows = []
    for scene, lines in sorted(LOGS.items()):
        frames: dict[int, list[list[str]]] = {}
        for line in lines:
            f, *rest = line.split()
            frames.setdefault(int(f), []).append(rest)
        ids: dict[str, str] = {}
        for f, objects in sorted(frames.items()):
            rows.append((f"{scene}/{f}", "ego", "Car", 0.0, 0.0, 0.0))
            kept = [(track, CLASSES.get(cat, "Object"), float(x) * scale, float(y) * scale, float(h))
                    for track, cat, x, y, h in objects if CLASSES.get(cat, "Object") in keep]
            ranked = sorted(kept, key=lambda o: (math.hypot(o[2], o[3]), o[0]))
            for track, t, *_ in ranked:
                ids.setdefault(track, f"{t.lower()}{sum(v.startswith(t.lower()) for v in ids.values()) + 1}")
            rows += [(f"{scene}/{f}", ids[track], t, x, y, h) for track, t, x, y, h in ranked]
    return pd.DataFrame(rows, columns=["frame_id", "entity_id", "type", "x", "y", "heading"])


def got(path) -> pd.DataFrame:
    df = read_frames(path)
    assert set(df.source) == {"toy"}
    return df[["frame_id", "entity_id", "type", "x", "y", "heading"]].reset_index(drop=True)


def test_the_recipe_is_a_source_end_to_end(tmp_path, capsys, toy):
    out = tmp_path / "frames.parquet"
    res = r2s(capsys, "extract", "toy", str(toy), "--categories", "all", "--toy-scale", "2", "--out", str(out))
    assert res.returncode == 0, res.stderr
    pd.testing.assert_frame_equal(got(out), expected(2.0, {"Car", "Pedestrian", "Object"}))
    assert "2 scenarios, 5 frames" in res.stderr and "kite x1" in res.stderr  # the unknown category, counted


def test_jobs_cut_the_input_into_its_files(tmp_path, capsys, toy):
    out = tmp_path / "frames"
    res = r2s(capsys, "extract", "toy", str(toy), "--jobs", "2", "--out", str(out))
    assert res.returncode == 0, res.stderr
    assert len(list(out.glob("part-*.parquet"))) == len(LOGS)
    pd.testing.assert_frame_equal(got(out), expected(1.0, {"Car", "Pedestrian", "Object"}))  # all by default


def test_categories_are_checked_against_its_taxonomy(tmp_path, capsys, toy):
    out = tmp_path / "frames.parquet"
    res = r2s(capsys, "extract", "toy", str(toy), "--categories", "walker", "--out", str(out))
    assert res.returncode == 0, res.stderr
    pd.testing.assert_frame_equal(got(out), expected(1.0, {"Pedestrian"}))
    out = tmp_path / "out" / "frames.parquet"
    res = r2s(capsys, "extract", "toy", str(toy), "--categories", "walkr", "--out", str(out))
    assert_refused(res, out, "the toy categories car, walker")


def test_a_wrong_source_is_named_both_ways(tmp_path, capsys, toy):
    out = tmp_path / "out" / "frames.parquet"
    res = r2s(capsys, "extract", "scenarionet", str(toy), "--out", str(out))
    assert_refused(res, out, f"looks like a folder of toy logs, not input of the scenarionet source: use "
                             f"`r2s extract toy {toy}`")
    one = toy / "queue.toy"
    res = r2s(capsys, "extract", "mcap", str(one), "--out", str(out))
    assert_refused(res, out, f"use `r2s extract toy {one}`")
    res = r2s(capsys, "extract", "toy", str(EXCERPT / "scenarionet"), "--out", str(out))
    assert_refused(res, out, f"use `r2s extract scenarionet {EXCERPT / 'scenarionet'}`")


def test_its_options_have_their_group_and_bad_lines_one_line(tmp_path, capsys, toy):
    with pytest.raises(SystemExit):
        r2s(capsys, "extract", "--help")
    words = " ".join(capsys.readouterr().out.split())
    assert "toy: --toy-scale" in words and ".toy file or dir (toy)" in words
    (toy / "queue.toy").write_text("#toy\n0 c1 car zero 6 0\n")
    out = tmp_path / "out" / "frames.parquet"
    assert_refused(r2s(capsys, "extract", "toy", str(toy), "--out", str(out)), out,
                   "queue.toy line 2 is not `frame track category x y heading`")


def test_the_registry_names_each_source_by_its_own_name(toy, monkeypatch):
    from extractors.registry import source, sources

    assert [s.name for s in sources()] == list(SOURCES) and source("toy").units(str(toy)) == [
        str(toy / "crossing.toy"), str(toy / "queue.toy")]
    with pytest.raises(KeyError, match="unknown source 'toys'.*toy"):
        source("toys")
    monkeypatch.setitem(SOURCES, "toy2", MODULE)  # a second key for the same module: its SOURCE says "toy"
    with pytest.raises(KeyError, match="named 'toy', not 'toy2'"):
        source("toy2")
