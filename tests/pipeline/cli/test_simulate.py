"""`r2s simulate`: simulated variants of a clip program as frames, as a user runs it on a real clip (the shipped
Argoverse 2 log, 6 frames with its map), every written variant passing the checker again when read back by other
verbs as real processes; the variant draws against an independent brute force; the entities placed in Scenic's
lanes."""

from __future__ import annotations

import dataclasses
import json

import pyarrow.parquet as pq
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pipeline.export.opendrive import export_road, header_frame
from pipeline.scenes import scene as frame_scene
from pipeline.simulation import ATTEMPTS, _boundaries, _compile, read_program_json
from synth.behaviour.check import check_clip
from synth.behaviour.program import ClipProgram, parse_clip_program
from synth.behaviour.synthesize import synthesize_behaviours
from synth.behaviour.track import read_clip
from synth.behaviour.variants import SpeedPlan, feasible, variant_scenic
from synth.config import as_config
from tests.support import ROOT, SHARED, assert_one_line_error, run_r2s
from tests.support.clips import scene_files

AV2 = ROOT / "data" / "argoverse2-log-excerpt" / "frames.parquet"
LOG = "adcf7d18-0510-35b0-a2fa-b4cea13a6d76"
FLAGS = ("--motion", "--lanes")
CONFIG = as_config({"motion": True, "lanes": True})
WAYMO = SHARED / "data" / "waymo" / "sd_waymo_v1.2_1096927972b9efaa.pkl"  # the smallest shared map

pytest.importorskip("scenic")


@pytest.fixture(scope="module")
def clip(tmp_path_factory):
    """Six frames of the log as scene JSON, their clip program (JSON), and one simulation of two variants."""
    out = tmp_path_factory.mktemp("clip")
    frames = []
    for k in range(100, 106):
        path = out / f"f{k}.json"
        path.write_text(frame_scene(str(AV2), f"{LOG}/{k}").to_json())
        frames.append(str(path))
    program = out / "clip.json"
    proc = run_r2s("synth", *frames, "--behaviours", *FLAGS, "--format", "json", "--out", str(program))
    assert proc.returncode == 0, proc.stderr
    sims = out / "sims"
    proc = run_r2s("simulate", str(program), *frames, *FLAGS, "--n", "2", "--seed", "7", "--out", str(sims))
    return frames, program, sims, proc


def test_written_variants_are_frames_the_checker_accepts(clip, tmp_path):
    frames, program, sims, proc = clip
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr.count("r2s simulate: variant ") == 2  # progress, one line per variant
    summary = json.loads((sims / "summary.json").read_text())
    assert summary["asked"] == 2
    assert (summary["written"] + summary["rejected_by_scenic"] + summary["timed_out"]
            + summary["rejected_by_checker"]) == 2
    assert summary["rejected_by_checker"] == 0, summary  # every simulation Scenic accepts is in the program
    written = [v["scene"] for v in summary["variants"] if v["outcome"] == "written"]
    table = pq.read_table(sims / "part-000000.parquet")
    assert sorted(set(table.column("scene").to_pylist())) == sorted(written) and written
    # Each written variant, read back by r2s scene as any user would, passes r2s check with the clip program less
    # the behaviours of entities the simulation could not place (first seen later).
    doc = json.loads(program.read_text())
    full = parse_clip_program(doc["program"])
    kept = ClipProgram(full.program, tuple(b for b in full.behaviours if b.id in summary["simulated"]))
    (tmp_path / "kept.dsl").write_text(str(kept))
    (tmp_path / "c.toml").write_text("motion = true\nlanes = true\n")
    recorded = [json.loads(open(f).read()) for f in frames]
    for name in written:
        paths = []
        for k in range(len(frames)):
            path = tmp_path / f"{name}-{k}.json"
            assert run_r2s("scene", str(sims), f"{name}/{k}", "--out", str(path)).returncode == 0
            paths.append(str(path))
        ok = run_r2s("check", *paths, str(tmp_path / "kept.dsl"), "--config", str(tmp_path / "c.toml"))
        assert ok.returncode == 0, ok.stdout + ok.stderr
        docs = [json.loads(open(p).read()) for p in paths]
        assert [d["world"]["timestamp_us"] for d in docs] == [r["world"]["timestamp_us"] for r in recorded]
        ego_speeds = [d["entities"][0]["speed"] for d in docs]
        assert ego_speeds[0] == pytest.approx(recorded[0]["entities"][0]["speed"], abs=1e-6)
        assert ego_speeds[-1] != pytest.approx(recorded[-1]["entities"][0]["speed"], abs=1e-6)  # a variant moves
    # Other verbs read the output as frames.
    query = run_r2s("query", str(sims), str(ROOT / "data" / "patterns" / "queue-of-three.dsl"),
                    "--out", str(tmp_path / "m.parquet"))
    assert query.returncode == 0 and f"{6 * len(written)} frames scanned" in query.stdout, query.stdout
    batch = run_r2s("run", str(sims), "--motion", "--out", str(tmp_path / "programs"), "--jobs", "1")
    assert batch.returncode == 0, batch.stderr


def test_variant_k_does_not_depend_on_k_and_another_seed_draws_other_speeds(clip, tmp_path):
    """(That the same seed writes the same bytes: test_the_python_api_writes_what_the_verb_writes, whose second
    simulation with the fixture's seed is compared byte for byte.)"""
    frames, program, sims, _ = clip
    one = tmp_path / "one"
    assert run_r2s("simulate", str(program), *frames, *FLAGS, "--n", "1", "--seed", "7", "--out",
                   str(one)).returncode == 0
    first = json.loads((sims / "summary.json").read_text())["variants"][0]
    assert json.loads((one / "summary.json").read_text())["variants"][0] == first
    other = tmp_path / "other"
    assert run_r2s("simulate", str(program), *frames, *FLAGS, "--n", "1", "--seed", "8", "--out",
                   str(other)).returncode == 0
    speeds = [pq.read_table(d / "part-000000.parquet").column("speed").to_pylist() for d in (one, other)]
    assert speeds[0] != speeds[1]


def test_no_variant_within_the_time_limit_writes_nothing_and_exits_4(clip, tmp_path):
    frames, program, _, _ = clip
    out = tmp_path / "none"
    proc = run_r2s("simulate", str(program), *frames, *FLAGS, "--n", "1", "--time-limit", "0.001", "--out", str(out))
    assert proc.returncode == 4 and not proc.stdout and "Traceback" not in proc.stderr, proc.stderr
    progress, error = proc.stderr.strip().splitlines()  # one progress line, then the one line of the failure
    assert "timed out" in progress and error.startswith("r2s simulate: no variant written: 1 asked")
    assert not out.exists()


def test_a_simulation_that_breaks_a_requirement_is_drawn_again_up_to_its_attempts(clip, tmp_path, monkeypatch):
    """A requirement every simulation breaks (at its third step; the drawn scene itself obeys it): each variant is
    simulated ATTEMPTS times, then rejected by Scenic with that said, and nothing is written."""
    from pipeline import simulation

    frames, program, _, _ = clip
    real = simulation.variant_scenic

    def broken(*args, **kwargs):
        sim = real(*args, **kwargs)
        return dataclasses.replace(sim, text=sim.text + "require always r2s__now() < 3\n")

    monkeypatch.setattr(simulation, "variant_scenic", broken)
    with pytest.raises(simulation.NoVariantWritten) as raised:
        simulation.simulate(program, frames, tmp_path / "none", n=1, seed=7, config=CONFIG)
    (variant,) = raised.value.result.variants
    assert (variant.outcome, variant.attempts) == ("rejected by Scenic", ATTEMPTS)
    assert variant.reason == f"a requirement failed during each of {ATTEMPTS} simulations"
    assert str(raised.value).startswith("no variant written: 1 asked, 1 rejected by Scenic")
    assert not (tmp_path / "none").exists()


def test_bad_input_is_one_line(clip, tmp_path):
    frames, program, _, _ = clip
    out = str(tmp_path / "out")
    assert_one_line_error(run_r2s("simulate", str(tmp_path / "nope.json"), *frames, "--out", out), 2, "does not exist")
    assert_one_line_error(run_r2s("simulate", frames[0], *frames, "--out", out), 2, "not a behaviour program")
    assert_one_line_error(run_r2s("simulate", str(program), *frames, "--n", "0", "--out", out), 2, "--n")
    assert_one_line_error(run_r2s("simulate", str(program), *frames[:-1], *FLAGS, "--out", out), 2, "not of the")
    text = tmp_path / "clip.dsl"
    text.write_text(json.loads(program.read_text())["program"])
    assert_one_line_error(run_r2s("simulate", str(text), *frames, "--out", out), 2, "not JSON")
    assert not (tmp_path / "out").exists()


def recheck(sims, program, n_frames: int) -> list[str]:
    """Every written variant read back from the frames written (as `r2s scene` reads them) and checked here, in
    this process, against the clip program less the entities not simulated: each one's violations (none: [])."""
    summary = json.loads((sims / "summary.json").read_text())
    doc = json.loads(program.read_text())
    full = parse_clip_program(doc["program"])
    kept = ClipProgram(full.program, tuple(b for b in full.behaviours if b.id in summary["simulated"]))
    out = []
    for v in summary["variants"]:
        if v["outcome"] == "written":
            scenes = [frame_scene(str(sims), f"{v['scene']}/{k}") for k in range(n_frames)]
            out.extend(f"{v['scene']}: {x}" for x in check_clip(kept, scenes, CONFIG).violations)
    return out


def test_every_variant_scenic_accepts_passes_the_checker_on_a_clip_that_turns_faster_than_a_car_steers(tmp_path):
    """Frames 95-125 of the log (3 s): car20's segments are `heading` Ranges whose recorded headings turn faster
    than a Newtonian car steers at its speed (the variants that steered were refused there, every one); each
    moving entity now moves along its recorded places and headings. Several seeds (variant k's seed is S's and
    k's), every simulation Scenic accepts is written, and each written one passes the checker read back here."""
    frames = scene_files(AV2, [f"{LOG}/{k}" for k in range(95, 126)], tmp_path)
    program = tmp_path / "clip.json"  # as r2s synth ... --behaviours --format json writes it (here in process)
    result = synthesize_behaviours(read_clip([json.loads(open(f).read()) for f in frames]), CONFIG)
    program.write_text(json.dumps(result.to_json_dict()))
    assert "heading Range" in str(result.program)  # the case steering could not follow
    sims = tmp_path / "sims"
    proc = run_r2s("simulate", str(program), *frames, *FLAGS, "--n", "3", "--seed", "1", "--out", str(sims))
    assert proc.returncode == 0, proc.stderr
    summary = json.loads((sims / "summary.json").read_text())
    assert summary["rejected_by_checker"] == 0 and summary["written"] + summary["rejected_by_scenic"] == 3, summary
    assert summary["written"] >= 2 and all(1 <= v["attempts"] <= ATTEMPTS for v in summary["variants"])
    assert recheck(sims, program, len(frames)) == []
    speeds = pq.read_table(sims / "part-000000.parquet").column("speed").to_pylist()
    recorded = [e["speed"] for f in frames for e in json.loads(open(f).read())["entities"]]
    assert sorted(speeds) != sorted(recorded)[:len(speeds)]  # the variants move at other speeds


def test_every_variant_scenic_accepts_passes_the_checker_on_a_shared_waymo_clip(tmp_path):
    """The smallest shared Waymo scenario's first second (skipped without ../shared), through the Python API: its
    first frame's program has pedestrian2 `moving like` car5, a parked car at 0.4 m/s (the variants that started
    parked entities at 0 m/s were refused there), and a car at walking pace following its lane."""
    from pipeline import simulate

    if not WAYMO.exists():
        pytest.skip(f"{WAYMO} is not here")
    (tmp_path / "in").mkdir()
    (tmp_path / "in" / WAYMO.name).symlink_to(WAYMO)
    extracted = tmp_path / "f.parquet"
    assert run_r2s("extract", "scenarionet", str(tmp_path / "in"), "--categories", "all", "--out",
                   str(extracted)).returncode == 0
    ids = sorted(pq.read_table(extracted, columns=["frame_id", "frame_index"]).to_pylist(),
                 key=lambda r: r["frame_index"])
    ids = list(dict.fromkeys(r["frame_id"] for r in ids))[:11]
    frames = scene_files(extracted, ids, tmp_path)
    result = synthesize_behaviours(read_clip([json.loads(open(f).read()) for f in frames]), CONFIG)
    assert "moving like" in str(result.program.program) and "parked" in str(result.program)
    program = tmp_path / "clip.json"
    program.write_text(json.dumps(result.to_json_dict()))
    sims = tmp_path / "sims"
    done = simulate(program, frames, sims, n=2, seed=3, config=CONFIG)
    assert done.count("rejected by the checker") == 0 and done.written >= 1, done.line()
    assert recheck(sims, program, len(frames)) == []


def test_placed_entities_lie_in_scenics_lanes(clip, tmp_path):
    """The road file is recentred (its header's offset) and Scenic's OpenDRIVE reader does not apply the offset, so
    the scenario places every entity at its world place less it: each entity with a recorded lane lies in a lane of
    the network Scenic reads from the file, and its place plus the offset is its world place."""
    from scenic.domains.driving.roads import Network

    frames, program, _, _ = clip
    config = as_config({"motion": True, "lanes": True})
    clip_program, bounds, _ = read_program_json(program.read_text(), str(program))
    scenes = [json.loads(open(f).read()) for f in frames]
    recorded = read_clip(scenes)
    xodr = str(tmp_path / "road.xodr")
    export_road(frames[0], None, xodr)
    offset = header_frame(xodr)[:2]
    assert offset != (0.0, 0.0)  # the road is recentred: the test means something
    sim = variant_scenic("t", [clip_program.behaviour(t.id) for t in recorded.tracks],
                         _boundaries(clip_program, bounds, recorded, config, "t"), recorded, xodr, config, offset)
    scene, _ = _compile(sim.text).generate(maxIterations=10)
    network = Network.fromFile(xodr)
    first = recorded.scenes[0]
    by_id = first.by_id()
    laned = 0
    for name, obj in zip(sim.placed, scene.objects):
        e = first.ego if name == "ego" else by_id[name]
        x, y = first.world.point(e.x, e.y)
        assert obj.position.x + offset[0] == pytest.approx(x, abs=1e-5)
        assert obj.position.y + offset[1] == pytest.approx(y, abs=1e-5)
        if e.lane is not None and e.type in ("Car", "Truck", "Bus"):
            laned += 1
            assert network.laneAt(obj.position) is not None, f"{name} is off Scenic's lanes at {obj.position}"
    assert laned >= 3


@st.composite
def plans(draw):
    """A SpeedPlan as speed_plan writes them (boxes around the recorded speeds, rises and falls of at least DV
    between neighbours that the recorded speeds obey) and a draw q in the boxes."""
    m = draw(st.integers(1, 5))
    r = [draw(st.floats(0, 20)) for _ in range(m + 1)]
    lo = [max(0.0, x - draw(st.floats(0, 3))) for x in r]
    hi = [x + draw(st.floats(0, 3)) for x in r]
    lo[0] = hi[0] = r[0]
    rows = []
    for j in range(m):
        if r[j + 1] - r[j] >= 1.0 and draw(st.booleans()):
            rows.append((j, 1.0, j + 1, -1.0, -1.0))
        elif r[j] - r[j + 1] >= 1.0 and draw(st.booleans()):
            rows.append((j + 1, 1.0, j, -1.0, -1.0))
    q = [draw(st.floats(a, b)) for a, b in zip(lo, hi)]
    return SpeedPlan(tuple(r), tuple(lo), tuple(hi), tuple(rows)), q, draw(st.floats(0, 1))


@settings(max_examples=300, deadline=None)
@given(plans())
def test_every_draw_obeys_its_plan_and_goes_as_far_as_it_may(case):
    plan, q, f = case
    u = feasible(plan.recorded, plan.lo, plan.hi, plan.rows, q, f)
    assert plan.holds(u, 1e-9)
    far = feasible(plan.recorded, plan.lo, plan.hi, plan.rows, q, 1.0)
    assert plan.holds(far, 1e-9)
    # Brute force: the furthest point of the segment from r toward q that obeys the plan, on a fine grid.
    r = plan.recorded
    grid = [k / 1000 for k in range(1001)]
    best = max(t for t in grid if plan.holds([a + t * (b - a) for a, b in zip(r, q)], 1e-9))
    reached = max((abs(a - x) / abs(b - x) for a, b, x in zip(far, q, r) if abs(b - x) > 1e-6), default=1.0)
    assert reached >= best - 1e-6


def test_the_python_api_writes_what_the_verb_writes(clip, tmp_path):
    from pipeline import simulate

    frames, program, sims, _ = clip
    result = simulate(program, frames, tmp_path / "api", n=2, seed=7, config={"motion": True, "lanes": True})
    assert result.to_json_dict() == json.loads((sims / "summary.json").read_text())
    # the same seed writes the same bytes (and the API what the verb writes)
    for name in ("part-000000.parquet", "summary.json", "_maps/part-000000.parquet"):
        assert (tmp_path / "api" / name).read_bytes() == (sims / name).read_bytes(), name
    assert set(result.seconds) >= {"road", "compile", "simulate", "check", "write"}
