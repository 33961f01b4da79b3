"""Untrusted scenes: nothing that arrives in data can reach generated Scenic or DSL text as code."""

from __future__ import annotations

import io
import json
import tokenize

import pytest
from hypothesis import given
from hypothesis import strategies as st

from synth.config import SynthConfig
from synth.scene import RESERVED_IDS, SceneError, scene_from_dict, scene_from_json
from synth.synthesize import synthesize

SMUGGLERS = [
    "__import__", "car1'); import os; ('", 'car"1', "car1)", "car1\nimport os", "os.system", "car-1", "1car",
    "car 1", "", "ego2 = 1", "car__1", "_private", "exec", "eval", "new", "facing", "Range", "Car", "print",
    "x" * 65, "cär", "car1\x00",
]


def _scene_with_id(eid, etype="Car"):
    return {"frame_id": "f", "entities": [
        {"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0},
        {"id": eid, "type": etype, "x": 0, "y": 10, "heading": 0},
    ]}


@pytest.mark.parametrize("eid", SMUGGLERS)
def test_injection_ids_are_refused_before_synthesis(eid):
    with pytest.raises(SceneError):
        scene_from_dict(_scene_with_id(eid))


@pytest.mark.parametrize("etype", ["Car()", "Car; import os", "object", "__class__", "car", ""])
def test_types_come_from_the_closed_set(etype):
    with pytest.raises(SceneError, match="unknown type"):
        scene_from_dict(_scene_with_id("car1", etype))


def _names(text: str) -> set[str]:
    return {t.string for t in tokenize.generate_tokens(io.StringIO(text).readline) if t.type == tokenize.NAME}


@pytest.fixture(scope="module")
def emitter_vocabulary():
    """Every name the Scenic emitter writes on its own (for a program using every relation kind)."""
    ents = [("car1", 0, 10, 0), ("car2", 3, 10, 0), ("car3", 7, 20, 123), ("car4", -30, -2, 180)]
    doc = {"frame_id": "v", "entities": [{"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0}] +
           [{"id": i, "type": "Car", "x": x, "y": y, "heading": h} for i, x, y, h in ents]}
    result = synthesize(scene_from_dict(doc), SynthConfig(oracle="closed-form"))
    ids = {e[0] for e in ents}
    return _names(result.scenic) - ids - {f"{i}__at" for i in ids}


@given(st.text(min_size=1, max_size=20))
def test_any_id_is_refused_or_yields_text_naming_only_itself(emitter_vocabulary, eid):
    try:
        scene = scene_from_dict(_scene_with_id(eid, "Pedestrian"))
    except SceneError:
        return
    assert eid not in RESERVED_IDS and eid.isascii()
    result = synthesize(scene, SynthConfig(oracle="closed-form"))
    names = _names(result.scenic)
    assert names <= emitter_vocabulary | {eid, f"{eid}__at", "Pedestrian"}
    assert _names(str(result.program)) <= {eid, "ego", "new", "Pedestrian", "ahead", "of", "by", "Range", "facing",
                                           "away", "from", "toward", "behind", "left", "right", "on", "relative",
                                           "to", "deg"}


@given(st.binary(max_size=400))
def test_arbitrary_bytes_are_a_scene_or_a_scene_error(data):
    try:
        scene_from_json(data)
    except SceneError as exc:
        assert "\n" not in str(exc)


json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False) | st.text(max_size=10),
    lambda children: st.lists(children, max_size=4) | st.dictionaries(st.text(max_size=8), children, max_size=4),
    max_leaves=20,
)
entity_like = st.fixed_dictionaries(
    {"id": st.one_of(st.just("ego"), st.text(max_size=6)), "type": st.sampled_from(["Car", "Truck", "X", 1]),
     "x": json_values, "y": st.floats(), "heading": st.floats(allow_nan=False)}
)


@given(st.one_of(json_values, st.fixed_dictionaries({"frame_id": json_values, "entities": st.lists(entity_like, max_size=4)})))
def test_arbitrary_json_is_a_scene_or_a_scene_error(doc):
    try:
        scene = scene_from_json(json.dumps(doc))
    except SceneError as exc:
        assert "\n" not in str(exc)
    else:
        assert sum(e.is_ego for e in scene.entities) == 1


def test_entity_cap_is_enforced():
    doc = {"frame_id": "big", "entities": [{"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0}] +
           [{"id": f"car{i}", "type": "Car", "x": i, "y": 0, "heading": 0} for i in range(1, 1001)]}
    with pytest.raises(SceneError, match="cap of 1000"):
        scene_from_json(json.dumps(doc))
    assert len(scene_from_json(json.dumps(doc), max_entities=2000).entities) == 1001
