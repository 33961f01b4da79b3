"""`r2s sample` runs Scenic text, and Scenic is Python: only the emitter's own, unedited text is compiled.

The guard needs no Scenic install (it refuses before compiling), so these tests run everywhere; the ones that
also sample skip without scenic.
"""

from __future__ import annotations

import json

import pytest

from pipeline.variants.sample import ScenicProgramError, ensure_generated
from synth.scenic.emit import SOURCE_PREFIX, NotGenerated, rebuild_from_source
from synth.synthesize import synthesize
from tests.support import assert_one_line_error, run_r2s


@pytest.fixture(scope="module")
def generated(real_frames):
    return synthesize(real_frames[0]).scenic


def test_the_emitters_own_text_is_rebuilt_byte_for_byte(real_frames):
    for scene in real_frames[:6]:
        text = synthesize(scene).scenic
        assert rebuild_from_source(text) == text
        ensure_generated(text)


def _record(text: str) -> dict:
    return json.loads(text.splitlines()[-1][len(SOURCE_PREFIX):])


def _with_record(text: str, rec: dict) -> str:
    lines = text.splitlines()
    return "\n".join(lines[:-1] + [SOURCE_PREFIX + json.dumps(rec, separators=(",", ":"))]) + "\n"


PAYLOAD = "import os; os.system('touch {marker}')"


@pytest.mark.parametrize("where", ["after the prelude", "before the record", "inside a helper", "appended"])
def test_injected_code_is_refused_and_never_runs(generated, tmp_path, where):
    marker = tmp_path / "pwned"
    payload = PAYLOAD.format(marker=marker)
    lines = generated.splitlines()
    at = {"after the prelude": next(i for i, s in enumerate(lines) if s.startswith("ego = new")),
          "before the record": len(lines) - 1,
          "inside a helper": next(i for i, s in enumerate(lines) if s.startswith("def dsl__sector(")) + 1,
          "appended": len(lines)}[where]
    indent = "    " if where == "inside a helper" else ""
    text = "\n".join(lines[:at] + [indent + payload] + lines[at:]) + "\n"
    path = tmp_path / "p.scenic"
    path.write_text(text)
    proc = run_r2s("sample", str(path), "--n", "1", "--out", str(tmp_path / "out"))
    assert_one_line_error(proc, 2, contains="refusing to run it")
    assert not marker.exists() and not (tmp_path / "out").exists()


def test_a_file_from_an_older_emitter_says_how_to_write_it_again(generated, tmp_path):
    # As an older r2sgen wrote it: without the collision rule's requirements (issue 15 added them).
    older = "".join(line for line in generated.splitlines(keepends=True) if not line.lstrip().startswith("require dsl__apart"))
    assert older != generated
    path = tmp_path / "old.scenic"
    path.write_text(older)
    proc = run_r2s("sample", str(path), "--n", "1", "--out", str(tmp_path / "out"))
    assert_one_line_error(proc, 2, contains="older r2sgen: write it again with `r2s synth SCENE --format scenic`")
    assert not (tmp_path / "out").exists()


def test_a_forged_record_can_only_yield_what_the_emitter_writes(generated, tmp_path):
    rec = _record(generated)
    # Code smuggled through every free-text field of the record: each is refused by validation, or stays inert.
    for field, value in [("frame_id", "x'\nimport os\n'"), ("program", "car1 = __import__('os')"),
                         ("delta1", "10; import os")]:
        with pytest.raises((NotGenerated, ScenicProgramError)):
            ensure_generated(_with_record(generated, {**rec, field: value}))
    bad_entities = [dict(rec["entities"][0], id="ego"), dict(rec["entities"][1], type="Car()")]
    with pytest.raises(ScenicProgramError):
        ensure_generated(_with_record(generated, {**rec, "entities": bad_entities}))
    # A header with line breaks of any kind renders as comments only; the file then must match that rendering.
    forged = {**rec, "header": "x\nimport os\x0cos.system('true')\u2028y"}
    text = rebuild_from_source(_with_record(generated, forged))
    body = [s for s in text.splitlines() if s.startswith("# ") is False and "import os" in s]
    assert body == []
    ensure_generated(text)  # self-consistent: it is exactly what the emitter writes, comments and all


@pytest.mark.parametrize("text", ["", "ego = new Car\n", "# r2s-source: {\n", "# r2s-source: []\n",
                                  "# r2s-source: {\"frame_id\": 1}\n", "# r2s-source: " + "[" * 100_000 + "\n"])
def test_foreign_or_broken_records_are_refused(text):
    with pytest.raises(ScenicProgramError, match="not Scenic text written by r2sgen"):
        ensure_generated(text)


def test_trusted_compiles_an_edited_file(generated, tmp_path):
    pytest.importorskip("scenic", reason="scenic is not installed (pip install .[scenic])")
    edited = generated.replace("requireVisible: False", "requireVisible: False  # edited by hand", 1)
    path = tmp_path / "edited.scenic"
    path.write_text(edited)
    refused = run_r2s("sample", str(path), "--n", "1", "--out", str(tmp_path / "a"))
    assert_one_line_error(refused, 2, contains="at line")
    proc = run_r2s("sample", str(path), "--n", "1", "--allow-collisions", "--trusted", "--out", str(tmp_path / "b"))
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "b" / "sample_000.json").exists()


def test_a_smaller_rerun_leaves_no_samples_of_the_earlier_run(generated, tmp_path):
    pytest.importorskip("scenic", reason="scenic is not installed (pip install .[scenic])")
    path = tmp_path / "p.scenic"
    path.write_text(generated)
    out = tmp_path / "out"
    (out).mkdir()
    (out / "notes.txt").write_text("mine")
    (out / "sample_notes.json").write_text("{}")  # looks like ours, is not: kept
    for n in ("4", "2"):
        proc = run_r2s("sample", str(path), "--n", n, "--allow-collisions", "--out", str(out))
        assert proc.returncode == 0, proc.stderr
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt", "sample_000.json", "sample_001.json",
                                                     "sample_notes.json"]


@pytest.mark.parametrize("statement", [
    "car1 = new Car ahead of ego by Range(-5, 0), facing Range(0, 5) deg relative to ego",  # distance 0 only
    "car1 = new Car on Range(0, 0) @ Range(0, 0) relative to ego, facing toward ego",
])
def test_a_degenerate_user_program_is_bad_input_not_a_crash(tmp_path, statement):
    pytest.importorskip("scenic", reason="scenic is not installed (pip install .[scenic])")
    scene = tmp_path / "s.json"
    scene.write_text(json.dumps({"frame_id": "f", "entities": [
        {"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0},
        {"id": "car1", "type": "Car", "x": 0, "y": 10, "heading": 0}]}))
    program = tmp_path / "p.dsl"
    program.write_text(statement + "\n")
    proc = run_r2s("sample", "--program", str(program), "--scene", str(scene), "--allow-collisions",
                   "--out", str(tmp_path / "out"))
    assert_one_line_error(proc, 2)
    assert not (tmp_path / "out").exists()
