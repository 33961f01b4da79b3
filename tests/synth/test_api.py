"""The Python API (docs/api.md): `from synth import ...` takes dicts or values and gives what the verbs give."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

import synth
from synth import SynthConfig, check, parse_program, scene_from_dict, scene_from_json, synthesize
from tests.support import ROOT, run_r2s, shipped_frames

FIG2 = {"frame_id": "fig2", "entities": [
    {"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0},
    {"id": "car1", "type": "Car", "x": 3, "y": 8, "heading": 0},
    {"id": "car2", "type": "Car", "x": 3, "y": 5, "heading": 0},
    {"id": "car3", "type": "Car", "x": 0, "y": 5, "heading": 0},
]}


def _doc(result) -> dict:
    doc = result.to_json_dict()
    doc.pop("stats")
    return doc


def test_every_exported_name_resolves_and_is_documented():
    for name in synth.__all__:
        value = getattr(synth, name)
        assert value.__doc__, name
    assert set(synth.__all__) <= set(dir(synth))


def test_a_dict_and_a_scene_give_the_same_result_as_the_verb(tmp_path):
    scene = shipped_frames()[0]
    as_dict = json.loads(scene.to_json())
    config = {"oracle": "smt", "strategy": "astar-cpa"}
    by_dict = synthesize(as_dict, config)
    by_value = synthesize(scene, SynthConfig(**config))
    assert _doc(by_dict) == _doc(by_value)
    path = tmp_path / "scene.json"
    path.write_text(scene.to_json())
    proc = run_r2s("synth", str(path), "--format", "json", "--oracle", "smt", "--strategy", "astar-cpa")
    assert proc.returncode == 0, proc.stderr
    doc = json.loads(proc.stdout)
    doc.pop("stats")
    assert doc == _doc(by_dict)
    # A TOML-shaped config ({"synth": {...}}) is the same configuration.
    assert _doc(synthesize(as_dict, {"synth": config})) == _doc(by_dict)


def test_check_takes_text_and_dicts():
    result = synthesize(FIG2)
    text = str(result.program)
    assert check(text, FIG2).ok and check(result.program, scene_from_dict(FIG2)).ok
    assert check(parse_program(text), scene_from_json(json.dumps(FIG2)), {"delta1": 10}).ok
    moved = {**FIG2, "entities": [*FIG2["entities"][:3], {**FIG2["entities"][3], "x": 4.0}]}
    violations = check(text, moved).violations
    assert violations and {v.entity for v in violations} <= {"car3", "car2", "car1"}


@pytest.mark.parametrize("bad, error", [
    ('{"frame_id": "x"}', TypeError),  # JSON text is not a scene: scene_from_json reads text
    ({"entities": [{"id": "car1", "type": "Car", "x": 0, "y": 0, "heading": 0}]}, ValueError),  # no ego
])
def test_bad_scenes_raise(bad, error):
    with pytest.raises(error):
        synthesize(bad)


def test_bad_configs_raise_with_the_closest_key():
    with pytest.raises(ValueError, match="did you mean 'delta1'"):
        synthesize(FIG2, {"deltta1": 5})
    with pytest.raises(TypeError):
        synthesize(FIG2, "paper")


def _fresh(code: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)


def test_import_synth_stays_light():
    """No numpy, z3, flint or pandas until the DSL or synthesis is used."""
    proc = _fresh("import sys, synth; from synth import synthesize, scene_from_dict, SynthConfig; "
                  "print(sorted(m for m in ('numpy', 'z3', 'flint', 'pandas', 'synth.dsl') if m in sys.modules))")
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "[]"


def test_synthesize_is_the_function_whatever_was_imported_first():
    """The module synth.synthesize shares the function's name; loading it first (as the pipeline does) must not
    make `from synth import synthesize` the module."""
    proc = _fresh("import synth.synthesize, pipeline.batch.task\nfrom synth import synthesize\nimport synth\n"
                  "assert callable(synthesize) and synth.synthesize is synthesize, synthesize\n"
                  "from synth.synthesize import SynthResult\nprint(SynthResult.__name__)")
    assert proc.returncode == 0, proc.stderr
