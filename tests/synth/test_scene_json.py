"""Scene JSON is strict (docs/formats.md): every key is a known one, a misspelling is refused naming the key it
misspells, and every writer of scene JSON writes only known keys."""

from __future__ import annotations

import json
import re

import pytest

from synth.scene import ENTITY_KEYS, SCENE_KEYS, SceneError, scene_from_dict, scene_from_json
from tests.support import ROOT, assert_one_line_error, run_r2s

EGO = {"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0}
CAR = {"id": "car1", "type": "Car", "x": 1.5, "y": 9, "heading": 3}


def _refusal(doc) -> str:
    with pytest.raises(SceneError) as info:
        scene_from_dict(doc)
    return str(info.value)


@pytest.mark.parametrize("typo, key", [("pos_sgima", "pos_sigma"), ("hedding_sigma", "heading_sigma"),
                                       ("Speed", "speed"), ("lenght", "length"), ("widht", "width")])
def test_a_misspelt_optional_key_is_refused_with_the_key_it_misspells(typo, key):
    message = _refusal({"entities": [EGO, {**CAR, typo: 0.5}]})
    assert f"entity 'car1' has unknown key {typo!r} (did you mean {key!r}?)" == message


@pytest.mark.parametrize("typo, key", [("hedding", "heading"), ("tpye", "type"), ("xx", "x")])
def test_a_misspelt_required_key_is_missing_and_named(typo, key):
    ent = {typo if k == key else k: v for k, v in CAR.items()}
    message = _refusal({"entities": [EGO, ent]})
    assert message.startswith(f"entity 1 lacks {key} ") and f"{typo!r} is not a key: did you mean {key!r}?" in message


def test_a_misspelt_entities_key_says_entities_is_missing():
    assert _refusal({"frame_id": "f", "entites": [EGO]}) == (
        "scene lacks entities ('entites' is not a key: did you mean 'entities'?)")
    assert _refusal({"frame_id": "f"}) == "scene lacks entities"
    assert "did you mean 'frame_id'" in _refusal({"frameid": "f", "entities": [EGO]})


def test_an_unrelated_key_lists_the_known_ones():
    message = _refusal({"entities": [EGO, {**CAR, "colour": "red"}]})
    assert "unknown key 'colour'" in message and ", ".join(ENTITY_KEYS) in message


def test_r2s_synth_refuses_a_typo_with_exit_2(tmp_path):
    path = tmp_path / "scene.json"
    path.write_text(json.dumps({"frame_id": "f", "entities": [EGO, {**CAR, "pos_sgima": 0.5}]}))
    assert_one_line_error(run_r2s("synth", str(path)), 2, "did you mean 'pos_sigma'")


def test_every_key_written_is_read_back():
    """The writer (Scene.to_dict: r2s scene, r2s sample) with every optional field set reads back equal."""
    full = {**CAR, "length": 4.5, "width": 1.8, "speed": 3.0, "pos_sigma": 0.5, "heading_sigma": 2.0,
            "speed_sigma": 0.2, "lanes": ["l1", "l2"], "lane": "l2", "in_intersection": True,
            "on_crosswalk": False, "off_road": False}
    assert set(full) == set(ENTITY_KEYS)
    road = {"map_id": "m", "features": [
        {"id": "l1", "kind": "lane", "polygon": [[0.0, 0.0], [3.5, 0.0], [3.5, 20.0], [0.0, 20.0]],
         "line": [[1.75, 0.0], [1.75, 20.0]], "left": "l2", "right": None, "successors": [], "predecessors": [],
         "is_intersection": True},
        {"id": "l2", "kind": "lane", "polygon": [[-3.5, 0.0], [0.0, 0.0], [0.0, 20.0], [-3.5, 20.0]],
         "line": [[-1.75, 0.0], [-1.75, 20.0]], "left": None, "right": "l1", "successors": [], "predecessors": [],
         "is_intersection": False},
        {"id": "w", "kind": "crosswalk", "polygon": [[-3.5, 5.0], [3.5, 5.0], [3.5, 8.0], [-3.5, 8.0]]}]}
    world = {"source": "scenarionet", "scene": "scene-0061", "frame_index": 3, "map_id": "scene-0061",
             "x": 411.25, "y": -1163.5, "heading": 271.5}
    scene = scene_from_dict({"frame_id": "f", "entities": [EGO, full], "road": road, "world": world})
    assert scene.to_dict()["road"] == road
    assert scene.to_dict()["world"] == world
    assert scene_from_json(scene.to_json()) == scene
    assert set(scene.to_dict()) == set(SCENE_KEYS)
    assert list(scene.to_dict()) == ["frame_id", "entities", "world", "road"]  # the documented order


def test_the_documented_keys_are_the_accepted_keys():
    """docs/formats.md's two scene JSON tables name exactly the keys the reader accepts."""
    text = (ROOT / "docs" / "formats.md").read_text()
    section = text[text.index("## Scene JSON"):text.index("## Frames Parquet")]
    documented = set(re.findall(r"^\| `([a-z_]+)`(?:, `([a-z_]+)`)?", section, flags=re.M))
    keys = {k for pair in documented for k in pair if k}
    assert keys == set(SCENE_KEYS) | set(ENTITY_KEYS)
