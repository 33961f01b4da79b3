"""The names `r2s export` writes (issue 35 items 11, 16): two variants whose files would get one name are refused
before anything is written (no scenario lost: "3 scenarios" with 2 on disk); a frame id starting with '.' or '-'
gives visible file names."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from tests.support import assert_one_line_error, run_r2s


@pytest.mark.parametrize("names", [("a b", "a_b"), ("é", "ü"), ("A", "a"), ("_a", "a")])
def test_variants_written_under_one_name_are_refused(names, recorded, tmp_path):
    scene_file, variants = recorded["scene-0061/0"]
    folder = tmp_path / "variants"
    folder.mkdir()
    for name, sample in zip(names, sorted(variants.iterdir())):
        shutil.copy(sample, folder / f"{name}.json")
    res = run_r2s("export", str(scene_file), str(folder), "--to", "scenarionet", "--out", str(tmp_path / "db"))
    assert_one_line_error(res, contains="rename one")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["variants"]


def test_distinct_names_all_arrive(recorded, tmp_path):
    scene_file, variants = recorded["scene-0061/0"]
    folder = tmp_path / "variants"
    folder.mkdir()
    names = ("a b", "é", "a-b", "A_c")
    for name, sample in zip(names, sorted(variants.iterdir())):
        shutil.copy(sample, folder / f"{name}.json")
    res = run_r2s("export", str(scene_file), str(folder), "--to", "openscenario", "--out", str(tmp_path / "osc"))
    assert res.returncode == 0, res.stderr
    assert "wrote 5 scenarios" in res.stdout
    assert len(list((tmp_path / "osc").glob("*.xosc"))) == 5


@pytest.mark.parametrize("frame_id", [".", "..", ".hidden/0", "-rf", "_/0"])
def test_frame_ids_give_visible_file_names(frame_id, recorded, tmp_path):
    scene_file, variants = recorded["scene-0061/0"]
    doc = json.loads(scene_file.read_text())
    doc["frame_id"] = frame_id
    scene = tmp_path / "scene.json"
    scene.write_text(json.dumps(doc))
    for to, n in (("openscenario", 3), ("scenarionet", 4)):  # 2 scenarios, and the road or the summaries
        out = tmp_path / to
        res = run_r2s("export", str(scene), str(sorted(variants.iterdir())[0]), "--to", to, "--out", str(out))
        assert res.returncode == 0, res.stderr
        files = [p.name for p in Path(out).iterdir()]
        assert len(files) == n and not [f for f in files if f.startswith((".", "-"))], files
