"""Valid-looking values that are not (issue 22, items 8, 9, 13): each is bad input, one line on stderr and exit 2
(before: an internal error, exit 1, or a silent change), on real processes; and the values at the edge of the
supported range still give certified programs."""

from __future__ import annotations

import json

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from synth.config import SynthConfig
from synth.dsl import DslError, parse_program
from synth.patterns.one_frame import parse_pattern
from synth.scene import MAX_COORDINATE, scene_from_dict
from synth.synthesize import synthesize
from tests.support import ROOT, assert_one_line_error, run_r2s

KEYFRAMES = ROOT / "data" / "nuscenes-mini-keyframes" / "frames.parquet"


def _scene(x: str, y: str = "5") -> str:
    return ('{"frame_id": "s", "entities": [{"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0}, '
            f'{{"id": "c", "type": "Car", "x": {x}, "y": {y}, "heading": 0}}, '
            '{"id": "d", "type": "Car", "x": 3, "y": 7, "heading": 10}]}')


@pytest.mark.parametrize("x,needle", [
    ("1" + "0" * 400, "finite"),  # a JSON integer no float holds
    ("1e154", "outside the supported range"),
    ("5e-324", "outside the supported range"),
    ("-1000000.5", "outside the supported range"),
])
def test_scene_values_beyond_the_range_are_bad_input(x, needle, tmp_path):
    (tmp_path / "s.json").write_text(_scene(x))
    proc = run_r2s("synth", str(tmp_path / "s.json"))
    assert_one_line_error(proc, 2, needle)


@pytest.mark.parametrize("x,y", [(MAX_COORDINATE, MAX_COORDINATE), (-MAX_COORDINATE, 3.0), (2.3e-308, 0.0),
                                 (3.0, 7.0), (1e-300, 1e-300)])
def test_the_edges_of_the_range_are_certified(x, y):
    """The range is where exact certification holds: its edges and co-located entities give certified programs."""
    raw = json.loads(_scene(json.dumps(x), json.dumps(y)))
    result = synthesize(scene_from_dict(raw), SynthConfig())
    assert result.status == "optimal" and result.certified, result


@pytest.mark.parametrize("text,needle", [("delta1 = true\n", "delta1"), ("c_dist = false\n", "c_dist"),
                                         ("c_dist = 1" + "0" * 400 + "\n", "c_dist")])
def test_booleans_and_huge_integers_are_not_numbers_in_a_config(text, needle, tmp_path):
    (tmp_path / "c.toml").write_text(text)
    (tmp_path / "s.json").write_text(_scene("1"))
    proc = run_r2s("synth", str(tmp_path / "s.json"), "--config", str(tmp_path / "c.toml"))
    assert_one_line_error(proc, 2, needle)


@pytest.mark.parametrize("text,column", [
    ("x = new Car ahead of ego by Range(\u0661, 5), facing Range(0, 360) deg\n", 35),  # Arabic-Indic one
    ("x = new Car ahead of ego by Range(1, \uff15), facing Range(0, 360) deg\n", 38),  # full-width five
    ("x = new Car ahead of ego by Range(1, 5),\u2028facing Range(0, 360) deg\n", 41),  # a line separator
    ("x = new Car ahead of ego by Range(1, 5),\u00a0facing Range(0, 360) deg\n", 41),  # a no-break space
])
def test_the_dsl_is_ascii(text, column):
    with pytest.raises(DslError, match=f"line 1 column {column}: unexpected character"):
        parse_pattern(text)
    with pytest.raises(DslError, match="unexpected character"):
        parse_program(text)


def test_dsl_lines_end_at_newlines_only():
    """\\r\\n and \\r end a line as \\n does; a form feed or U+0085 inside a line is an unexpected character."""
    two = "x = new Car ahead of ego by Range(1, 5), facing Range(0, 360) deg"
    assert len(parse_pattern(f"{two}\r\n{two.replace('x =', 'y =')}\r").statements) == 2
    with pytest.raises(DslError, match="line 1 column 41"):
        parse_pattern(two.replace(", facing", ",\x85facing"))


def test_the_dsl_error_is_one_line_through_the_cli(tmp_path):
    (tmp_path / "p.dsl").write_text("x = new Car ahead of ego by Range(1, 5),\u2028facing Range(0, 360) deg\n")
    proc = run_r2s("query", str(KEYFRAMES), str(tmp_path / "p.dsl"), "--out", str(tmp_path / "m.parquet"))
    assert_one_line_error(proc, 2, "unexpected character '\\u2028'")


def test_scene_refuses_rows_without_a_frame_id(tmp_path):
    """Before: `r2s scene` dropped the frame's row whose frame_id was null, silently (51 of 52 entities)."""
    table = pq.read_table(KEYFRAMES)
    fid = table.column("frame_id").to_pylist()
    fid[5] = None
    for stats in (True, False):  # from the footer's statistics, or by reading the column where there are none
        path = tmp_path / f"frames-{stats}.parquet"
        pq.write_table(table.set_column(0, "frame_id", pa.array(fid, pa.string())), path, write_statistics=stats)
        proc = run_r2s("scene", str(path), "scene-0061/0")
        assert_one_line_error(proc, 2, "column frame_id has 1 missing value")


@pytest.mark.parametrize("verb", ["scene", "run", "query"])
def test_a_speed_stored_as_text_is_bad_input(verb, tmp_path):
    table = pq.read_table(KEYFRAMES)
    path = tmp_path / "frames.parquet"
    pq.write_table(table.append_column("speed", pa.array(["1.5"] * table.num_rows, pa.string())), path)
    args = {"scene": ("scene", str(path), "scene-0061/0"), "run": ("run", str(path), "--out", str(tmp_path / "p")),
            "query": ("query", str(path), str(ROOT / "data" / "patterns" / "queue-of-three.dsl"),
                      "--out", str(tmp_path / "m.parquet"))}[verb]
    proc = run_r2s(*args)
    assert_one_line_error(proc, 2, "column speed is string")


def test_numpy_warnings_do_not_precede_the_line(tmp_path):
    """An overflow warning from numpy (an input far out of range) would print before the error line."""
    (tmp_path / "s.json").write_text(_scene("1e308", "1e308"))
    proc = run_r2s("synth", str(tmp_path / "s.json"))
    assert_one_line_error(proc, 2, "outside the supported range")


@pytest.fixture(scope="module")
def scene_with_a_huge_road_coordinate(tmp_path_factory):
    """A real scene with its road (`r2s scene` on the Argoverse 2 excerpt), its first road point's x replaced by an
    integer of 400 digits (JSON has no bound; no float holds it); and the program of the scene as it was."""
    where = tmp_path_factory.mktemp("road")
    frames = ROOT / "data" / "argoverse2-log-excerpt" / "frames.parquet"
    proc = run_r2s("scene", str(frames), "adcf7d18-0510-35b0-a2fa-b4cea13a6d76/0", "--out", str(where / "s.json"))
    assert proc.returncode == 0, proc.stderr
    assert run_r2s("synth", str(where / "s.json"), "--out", str(where / "p.dsl")).returncode == 0
    doc = json.loads((where / "s.json").read_text())
    feature = next(f for f in doc["road"]["features"] if f.get("polygon"))
    feature["polygon"][0][0] = 10 ** 400
    (where / "big.json").write_text(json.dumps(doc))
    return where, feature["id"]


@pytest.mark.parametrize("verb", ["synth", "check", "sample"])
def test_a_road_coordinate_beyond_a_float_is_bad_input(scene_with_a_huge_road_coordinate, verb):
    """Issue 35, item 15: was an OverflowError (exit 1) in every verb that reads scene JSON."""
    where, feature = scene_with_a_huge_road_coordinate
    scene, program = str(where / "big.json"), str(where / "p.dsl")
    args = {"synth": [scene], "check": [scene, program],
            "sample": ["--program", program, "--scene", scene, "--out", str(where / "variants")]}[verb]
    assert_one_line_error(run_r2s(verb, *args), 2, f"road feature '{feature}': a coordinate is an integer beyond a float")
    assert not (where / "variants").exists()


def test_a_temporal_pattern_ends_its_lines_as_the_dsl_does():
    """`then` on a line of its own only where the DSL ends lines: U+2028 is inside a line, as in any pattern."""
    from synth.patterns.temporal import parse_query_pattern

    with pytest.raises(DslError, match="line 1 column 12: unexpected character"):
        parse_query_pattern("c = new Car\u2028then\u2028c = new Car\n")
    assert len(parse_query_pattern("c = new Car\r\nthen\rc = new Car\n").steps) == 2
