"""`r2s synth` and `r2s check` as a user runs them: formats, fields, exit codes, one-line errors."""

from __future__ import annotations

import json

import pytest

from tests.support import assert_one_line_error, run_r2s

FIG2 = {"frame_id": "fig2", "entities": [
    {"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0},
    {"id": "car1", "type": "Car", "x": 3, "y": 8, "heading": 0},
    {"id": "car2", "type": "Car", "x": 3, "y": 5, "heading": 0},
    {"id": "car3", "type": "Car", "x": 0, "y": 5, "heading": 0},
]}


@pytest.fixture
def fig2(tmp_path):
    p = tmp_path / "fig2.json"
    p.write_text(json.dumps(FIG2))
    return p


def test_json_output_has_the_contract_fields(fig2):
    proc = run_r2s("synth", str(fig2), "--format", "json")
    assert proc.returncode == 0, proc.stderr
    doc = json.loads(proc.stdout)
    assert set(doc) == {"frame_id", "status", "cost", "lower_bound", "n_entities", "program", "scenic", "certified", "stats"}
    assert set(doc["stats"]) == {"runtime_s", "search_s", "smt_s", "smt_queries", "nodes_expanded", "peak_rss_mb"}
    assert (doc["frame_id"], doc["status"], doc["cost"], doc["lower_bound"], doc["n_entities"]) == ("fig2", "optimal", 1, 1, 3)
    assert doc["certified"] is True
    statements = [line for line in doc["scenic"].splitlines() if not line.startswith("#")]
    assert sum(" = new Car " in line for line in statements) == 4


def test_dsl_output_round_trips_through_check(fig2, tmp_path):
    proc = run_r2s("synth", str(fig2), "--strategy", "bfs-cpa", "--oracle", "smt")
    assert proc.returncode == 0, proc.stderr
    assert len(proc.stdout.strip().splitlines()) == 3
    prog = tmp_path / "p.dsl"
    prog.write_text(proc.stdout)
    ok = run_r2s("check", str(fig2), str(prog))
    assert ok.returncode == 0 and ok.stdout.startswith("ok"), ok.stdout + ok.stderr


def test_check_reports_violations_with_exit_3(fig2, tmp_path):
    prog = tmp_path / "p.dsl"
    prog.write_text("car3 = new Car behind ego by Range(0, 5), facing away from ego\n"
                    "car2 = new Car right of car3 by Range(0.5, 5.5), facing Range(-2.5, 2.5) deg relative to ego\n")
    proc = run_r2s("check", str(fig2), str(prog))
    assert proc.returncode == 3
    out = proc.stdout
    assert "car3: position" in out and "car1: missing" in out and "car2" not in out


def test_out_file_and_scenic_format(fig2, tmp_path):
    out = tmp_path / "sub" / "prog.scenic"
    proc = run_r2s("synth", str(fig2), "--format", "scenic", "--out", str(out))
    assert proc.returncode == 0 and proc.stdout == ""
    assert "sector_ahead(ego" in out.read_text()
    assert not list(out.parent.glob(".*.tmp"))


def test_a_timeout_still_produces_a_program_and_says_so(tmp_path, real_frames):
    scene = next(s for s in real_frames if len(s.others) == 12)
    p = tmp_path / "s.json"
    p.write_text(scene.to_json())
    proc = run_r2s("synth", str(p), "--strategy", "bfs", "--oracle", "closed-form", "--time-limit", "0.01", "--format", "json")
    assert proc.returncode == 0
    doc = json.loads(proc.stdout)
    assert doc["status"] in ("feasible", "timeout") and doc["lower_bound"] <= doc["cost"]
    assert doc["status"] in proc.stderr


BAD_SCENES = {
    "not json": ("{ this is not json", "not valid JSON"),
    "empty": ("", "empty"),
    "nan": ('{"frame_id": "f", "entities": [{"id": "ego", "type": "Car", "x": NaN, "y": 0, "heading": 0}]}', "NaN"),
    "infinity": ('{"frame_id": "f", "entities": [{"id": "ego", "type": "Car", "x": 1, "y": Infinity, "heading": 0}]}', "Infinity"),
    "huge number": ('{"frame_id": "f", "entities": [{"id": "ego", "type": "Car", "x": 1e999, "y": 0, "heading": 0}]}', "finite"),
    "no ego": ('{"frame_id": "f", "entities": [{"id": "car1", "type": "Car", "x": 1, "y": 0, "heading": 0}]}', "ego"),
    "two egos": ('{"frame_id": "f", "entities": [{"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0},'
                 '{"id": "ego", "type": "Car", "x": 1, "y": 0, "heading": 0}]}', "duplicate"),
    "duplicate id": ('{"frame_id": "f", "entities": [{"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0},'
                     '{"id": "car1", "type": "Car", "x": 1, "y": 0, "heading": 0},'
                     '{"id": "car1", "type": "Car", "x": 2, "y": 0, "heading": 0}]}', "duplicate"),
    "non-identifier id": ('{"frame_id": "f", "entities": [{"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0},'
                          '{"id": "car 1", "type": "Car", "x": 1, "y": 0, "heading": 0}]}', "identifier"),
    "keyword id": ('{"frame_id": "f", "entities": [{"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0},'
                   '{"id": "lambda", "type": "Car", "x": 1, "y": 0, "heading": 0}]}', "reserved"),
    "string for number": ('{"frame_id": "f", "entities": [{"id": "ego", "type": "Car", "x": "0", "y": 0, "heading": 0}]}', "number"),
    "bool for number": ('{"frame_id": "f", "entities": [{"id": "ego", "type": "Car", "x": true, "y": 0, "heading": 0}]}', "number"),
    "unknown type": ('{"frame_id": "f", "entities": [{"id": "ego", "type": "Spaceship", "x": 0, "y": 0, "heading": 0}]}', "unknown type"),
    "missing field": ('{"frame_id": "f", "entities": [{"id": "ego", "type": "Car", "x": 0, "heading": 0}]}', "lacks y"),
    "entities not a list": ('{"frame_id": "f", "entities": {"ego": 1}}', "list"),
    "top level list": ('[1, 2, 3]', "object"),
    "negative length": ('{"frame_id": "f", "entities": [{"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0, "length": -1}]}', "positive"),
    "binary": ("\udcff\udcfe", "UTF-8"),
}


@pytest.mark.parametrize("name", list(BAD_SCENES))
def test_bad_scenes_exit_2_with_one_clear_line(name, tmp_path):
    text, needle = BAD_SCENES[name]
    p = tmp_path / "bad.json"
    p.write_bytes(text.encode("utf-8", "surrogateescape"))
    out = tmp_path / "out.dsl"
    assert_one_line_error(run_r2s("synth", str(p), "--out", str(out)), 2, needle)
    assert not out.exists()


def test_missing_file_and_directory_and_bad_usage(tmp_path):
    assert_one_line_error(run_r2s("synth", str(tmp_path / "nope.json")), 2, "does not exist")
    assert_one_line_error(run_r2s("synth", str(tmp_path)), 2, "directory")
    assert_one_line_error(run_r2s("synth"), 2)
    assert_one_line_error(run_r2s("synth", "x.json", "--strategy", "magic"), 2, "invalid choice")
    assert_one_line_error(run_r2s("frobnicate"), 2, "unknown verb")


def test_bad_config_and_unavailable_dreal_are_usage_errors(fig2, tmp_path):
    cfg = tmp_path / "c.toml"
    cfg.write_text("[synth]\ndelta1 = 100\n")
    assert_one_line_error(run_r2s("synth", str(fig2), "--config", str(cfg)), 2, "delta1")
    cfg.write_text("[synth]\nspeed = 3\n")
    assert_one_line_error(run_r2s("synth", str(fig2), "--config", str(cfg)), 2, "unknown config key")
    cfg.write_text("[synth\n")
    assert_one_line_error(run_r2s("synth", str(fig2), "--config", str(cfg)), 2, "TOML")
    from synth.smt import SolverUnavailable
    from synth.smt.dreal_backend import load_dreal

    try:
        load_dreal()  # as r2s loads it (`make dreal` may have made it loadable)
    except SolverUnavailable:
        assert_one_line_error(run_r2s("synth", str(fig2), "--solver", "dreal"), 2, "libibex")


def test_bad_program_for_check(fig2, tmp_path):
    prog = tmp_path / "p.dsl"
    prog.write_text("car1 = new Car ahead of car9 by Range(0, 5), facing away from ego\n")
    assert_one_line_error(run_r2s("check", str(fig2), str(prog)), 2, "car9")


def test_entity_cap_on_the_command_line(tmp_path):
    doc = {"frame_id": "many", "entities": [{"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0}] +
           [{"id": f"car{i}", "type": "Car", "x": 3.0 * i, "y": 0, "heading": 0} for i in range(1, 6)]}
    p = tmp_path / "s.json"
    p.write_text(json.dumps(doc))
    assert_one_line_error(run_r2s("synth", str(p), "--max-entities", "3"), 2, "cap of 3")
    assert run_r2s("synth", str(p), "--max-entities", "10").returncode == 0


def test_a_clip_is_one_program_for_its_frames(tmp_path):
    """`r2s synth A.json B.json`: one program over the clip, the same as synthesize_window's, holding in each frame
    by `r2s check` (each frame checked with its own entities' statements); bad clips: one line, exit 2."""
    from synth import frame_program, scene_from_json, synthesize_window

    paths = []
    for k in range(3):
        path = tmp_path / f"f{k}.json"
        proc = run_r2s("scene", "data/nuscenes-mini-keyframes/frames.parquet", f"scene-0103/{k}", "--out", str(path))
        assert proc.returncode == 0, proc.stderr
        paths.append(str(path))
    proc = run_r2s("synth", *paths, "--format", "json")
    assert proc.returncode == 0, proc.stderr
    doc = json.loads(proc.stdout)
    assert (doc["frame_id"], doc["first_frame"], doc["last_frame"], doc["frames"]) == \
        ("scene-0103/0", "scene-0103/0", "scene-0103/2", 3)
    scenes = [scene_from_json(open(p).read()) for p in paths]
    assert doc["program"] == str(synthesize_window(scenes).program)
    for path, scene in zip(paths, scenes):
        program = tmp_path / "frame.dsl"
        program.write_text(str(frame_program(synthesize_window(scenes).program, scene)))
        assert run_r2s("check", path, str(program)).returncode == 0
    assert_one_line_error(run_r2s("synth", paths[0], paths[0]), 2, "twice")
    assert_one_line_error(run_r2s("synth", paths[0], "-", input="{}"), 2, "standard input")
    assert_one_line_error(run_r2s("synth", *paths, "--strategy", "monolithic"), 2, "monolithic")


def test_a_clip_with_lanes_as_a_user_runs_it(excerpt_frames, tmp_path):
    """`r2s scene` on frames extracted with their maps, then `r2s synth A.json B.json C.json --lanes`: the program
    synthesize_window writes, every statement with a lane clause, each frame's program accepted by
    `r2s check` on its frame; a frame without its road is one line, exit 2."""
    from synth import SynthConfig, frame_program, scene_from_json, synthesize_window

    paths = []
    for k in range(3):
        path = tmp_path / f"f{k}.json"
        proc = run_r2s("scene", str(excerpt_frames), f"scene-0103/{k}", "--out", str(path))
        assert proc.returncode == 0, proc.stderr
        paths.append(str(path))
    proc = run_r2s("synth", *paths, "--lanes")
    assert proc.returncode == 0, proc.stderr
    scenes = [scene_from_json(open(p).read()) for p in paths]
    program = synthesize_window(scenes, SynthConfig(lanes=True)).program
    assert proc.stdout == str(program) and all(st.lane is not None for st in program.statements)
    for path, scene in zip(paths, scenes):
        text = tmp_path / "frame.dsl"
        text.write_text(str(frame_program(program, scene)))
        assert run_r2s("check", path, str(text)).returncode == 0
    bare = tmp_path / "bare.json"
    doc = json.loads(open(paths[1]).read())
    bare.write_text(json.dumps({k: v for k, v in doc.items() if k != "road"}))
    assert_one_line_error(run_r2s("synth", paths[0], str(bare), "--lanes"), 2, "has no road")


def test_a_clip_is_of_one_scene_in_time_order_where_its_frames_say(tmp_path):
    """Issue 35, item 13: frames whose `world` names two scenes (or sources), or frames given out of their
    frame_index order, were synthesized as one clip. Now one line, exit 2, nothing written; frames that do not say
    (no world) are taken as given."""
    log = "adcf7d18-0510-35b0-a2fa-b4cea13a6d76"
    paths = []
    for k in range(3):
        path = tmp_path / f"f{k}.json"
        proc = run_r2s("scene", "data/argoverse2-log-excerpt/frames.parquet", f"{log}/{k}", "--out", str(path))
        assert proc.returncode == 0, proc.stderr
        paths.append(path)
    worlds = [json.loads(p.read_text())["world"] for p in paths]
    assert [(w["source"], w["scene"], w["frame_index"]) for w in worlds] == [("argoverse2", log, k) for k in range(3)]
    out = tmp_path / "out.dsl"
    ok = run_r2s("synth", *map(str, paths), "--out", str(out))
    assert ok.returncode == 0 and out.exists(), ok.stderr
    out.unlink()

    def variant(name: str, **world) -> str:
        doc = json.loads(paths[1].read_text())
        doc["world"].update(world)
        (tmp_path / name).write_text(json.dumps(doc))
        return str(tmp_path / name)

    first, last = str(paths[0]), str(paths[2])
    for clip, says in (
            ([last, first], f"frame '{log}/0' (frame_index 0) comes after frame '{log}/2' (frame_index 2)"),
            ([first, last, str(paths[1])], "comes after"),
            ([first, variant("again.json", frame_index=0)], f"frame '{log}/1' (frame_index 0) comes after"),
            ([first, variant("other.json", scene="another-log")], f"frame '{log}/1' is of scene 'another-log' and "
                                                                    f"frame '{log}/0' of scene '{log}'"),
            ([first, variant("source.json", source="scenarionet")], "is of source 'scenarionet'")):
        assert_one_line_error(run_r2s("synth", *clip, "--out", str(out)), 2, says)
        assert not out.exists()
    unsaid = []  # the frames without their world (nor their road, which needs it), given in reverse
    for path in reversed(paths):
        doc = {k: v for k, v in json.loads(path.read_text()).items() if k not in ("world", "road")}
        (tmp_path / f"unsaid-{path.name}").write_text(json.dumps(doc))
        unsaid.append(str(tmp_path / f"unsaid-{path.name}"))
    taken = run_r2s("synth", *unsaid, "--out", str(out))
    assert taken.returncode == 0 and out.exists(), taken.stderr
