"""`make corpus` follows its inputs (issue 22): the frames are extracted again when SOURCE, INPUT or CATEGORIES
change (OUT/frames.args records them), not when nothing did; and its default categories are r2s extract's."""

from __future__ import annotations

import shutil
import subprocess
import sys

import pytest

from frames.rows import read_frames
from pipeline.programs import read_programs
from tests.support import ROOT

EXCERPT = ROOT / "data" / "nuscenes-mini-excerpt" / "scenarionet"


def _make(out, input_path, *variables: str) -> subprocess.CompletedProcess:
    # The project's own Python and no setup step (-o: the venv stamp is taken as made), whatever venv runs the tests.
    return subprocess.run(["make", "--no-print-directory", "-C", str(ROOT), "-o", ".venv/.installed", "corpus",
                           "SOURCE=scenarionet", f"INPUT={input_path}", f"OUT={out}", "JOBS=1", "TIME_LIMIT=20",
                           f"R2S={sys.executable} -m pipeline.cli", *variables],
                          capture_output=True, text=True, timeout=600)


@pytest.mark.skipif(shutil.which("make") is None, reason="make is not installed")
def test_make_corpus_extracts_again_when_its_arguments_change_and_only_then(tmp_path):
    out = tmp_path / "corpus"
    proc = _make(out, EXCERPT, "CATEGORIES=vehicles")
    assert proc.returncode == 0, proc.stderr
    assert "r2s extract: 3 scenarios" in proc.stderr
    assert "--categories vehicles" in (out / "frames.args").read_text()
    assert not read_programs(out / "programs")["program"].str.contains("Pedestrian").any()

    proc = _make(out, EXCERPT)  # CATEGORIES left out: r2s extract's default, every type
    assert proc.returncode == 0, proc.stderr
    assert "r2s extract: 3 scenarios" in proc.stderr
    assert "--categories" not in (out / "frames.args").read_text()
    assert "Pedestrian" in set(read_frames(out / "frames")["type"])
    assert "recomputed because their rows changed" in proc.stderr
    assert read_programs(out / "programs")["program"].str.contains("Pedestrian").any()

    proc = _make(out, EXCERPT)
    assert proc.returncode == 0, proc.stderr
    assert "r2s extract" not in proc.stderr and "frames is up to date" in proc.stdout
    assert "(0 computed, 9 kept)" in proc.stderr

    copy = tmp_path / "copy"  # another INPUT (a copy: the same frames, so every program is kept)
    shutil.copytree(EXCERPT, copy)
    proc = _make(out, copy)
    assert proc.returncode == 0, proc.stderr
    assert "r2s extract: 3 scenarios" in proc.stderr
    assert str(copy) in (out / "frames.args").read_text()
    assert "(0 computed, 9 kept)" in proc.stderr
