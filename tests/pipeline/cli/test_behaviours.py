"""`r2s synth A.json B.json ... --behaviours` and `r2s check` on a clip, as a user runs them on real clips (the
shipped Argoverse 2 log with its map, the shipped nuScenes excerpt at 2 Hz), and the clip's Scenic scenario
compiled and simulated headless by Scenic's Newtonian simulator on the road r2s export writes."""

from __future__ import annotations

import json
import math
import re

import pytest

from pipeline.export.opendrive import header_frame
from synth.scene import scene_from_json
from tests.support import ROOT, assert_one_line_error, run_r2s
from tests.support.clips import scene_files

AV2 = ROOT / "data" / "argoverse2-log-excerpt" / "frames.parquet"
LOG = "adcf7d18-0510-35b0-a2fa-b4cea13a6d76"


@pytest.fixture(scope="module")
def av2_clip(tmp_path_factory):
    return scene_files(AV2, [f"{LOG}/{k}" for k in range(100, 112)], tmp_path_factory.mktemp("clip"))


def test_synth_behaviours_then_check_on_the_clip(av2_clip, tmp_path):
    program = tmp_path / "clip.dsl"
    proc = run_r2s("synth", *av2_clip, "--behaviours", "--motion", "--lanes", "--out", str(program))
    assert proc.returncode == 0, proc.stderr
    text = program.read_text()
    assert "behaviour ego " in text and "following lane" in text and "parked" in text
    ok = run_r2s("check", *av2_clip, str(program), "--config", str(_motion_lanes(tmp_path)))
    assert ok.returncode == 0 and ok.stdout.startswith("ok: the program contains the clip"), ok.stdout + ok.stderr
    # One frame short: the last segments' durations no longer fit, and a late entity may vanish: exit 3.
    short = run_r2s("check", *av2_clip[:-3], str(program), "--config", str(_motion_lanes(tmp_path)))
    assert short.returncode == 3 and "behaviour" in short.stdout, short.stdout
    as_json = run_r2s("synth", *av2_clip[:4], "--behaviours", "--format", "json")
    doc = json.loads(as_json.stdout)
    assert doc["frames"] == 4 and doc["cost"] == doc["lower_bound"] and doc["status"] == "optimal"


def _motion_lanes(tmp_path):
    config = tmp_path / "c.toml"
    config.write_text("motion = true\nlanes = true\n")
    return config


def test_a_clip_without_times_is_one_line(av2_clip, tmp_path):
    docs = [json.loads(open(p).read()) for p in av2_clip[:2]]
    paths = []
    for k, doc in enumerate(docs):
        del doc["world"]["timestamp_us"]
        path = tmp_path / f"{k}.json"
        path.write_text(json.dumps(doc))
        paths.append(str(path))
    assert_one_line_error(run_r2s("synth", *paths, "--behaviours"), 2, "has no time")
    assert_one_line_error(run_r2s("synth", av2_clip[1], av2_clip[0], "--behaviours"), 2, "time order")
    bad = tmp_path / "bad.dsl"
    bad.write_text("behaviour ego cruising Range(1, 2) m/s for Range(0, 1) s\n")
    assert_one_line_error(run_r2s("check", *av2_clip[:2], str(bad)), 2, "needs a path")
    assert_one_line_error(run_r2s("synth", *av2_clip[:2], "--behaviours", "--format", "scenic"), 2, "--road")


def test_nuscenes_keyframes_get_a_behaviour_program(excerpt_frames, tmp_path):
    ids = [f"scene-0103/{k}" for k in range(4)]  # the excerpt's longest scene: 4 keyframes at 2 Hz
    clip = scene_files(excerpt_frames, ids, tmp_path)
    program = tmp_path / "clip.dsl"
    proc = run_r2s("synth", *clip, "--behaviours", "--motion", "--lanes", "--out", str(program))
    assert proc.returncode == 0, proc.stderr
    text = program.read_text()
    assert "behaviour ego following lane" in text and "heading Range(" in text  # ego in its lane; pedestrians
    assert run_r2s("check", *clip, str(program), "--config", str(_motion_lanes(tmp_path))).returncode == 0


def _clip_scenic(clip: list[str], tmp_path):
    """The clip's road (r2s export of its first frame) and its dynamic Scenic scenario on it (r2s synth
    --behaviours --format scenic --road), as a user makes them."""
    export = tmp_path / "export"
    proc = run_r2s("export", clip[0], "--to", "openscenario", "--out", str(export))
    assert proc.returncode == 0, proc.stderr
    (road,) = export.glob("*.xodr")
    out = tmp_path / "clip.scenic"
    proc = run_r2s("synth", *clip, "--behaviours", "--motion", "--lanes", "--format", "scenic", "--road", str(road),
                   "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    return road, out


def test_the_clip_simulates_headless_near_its_recording(av2_clip, tmp_path):
    scenic = pytest.importorskip("scenic")
    from scenic.core.distributions import RejectionException
    road, out = _clip_scenic(av2_clip, tmp_path)
    text = out.read_text()
    assert "terminate after" in text and "require always ego.speed" in text and "R2sSegments" in text
    scenario = scenic.scenarioFromFile(str(out), mode2D=True)
    scene, _ = scenario.generate(maxIterations=20)
    ox, oy, _ = header_frame(str(road))
    # Placed with the header's offset: every placed car with a recorded lane fact stands on a lane of Scenic's road.
    first = scene_from_json(open(av2_clip[0]).read())
    in_lane = {"ego"} | {e.id for e in first.entities if e.lane is not None}
    names = re.findall(r"^(\S+) = new ", text, re.M)
    network = scene.workspace.network
    cars = [o for name, o in zip(names, scene.objects) if name in in_lane and type(o).__name__ == "Car"]
    off = [name for name, o in zip(names, scene.objects) if o in cars and network.laneAt(o.position) is None]
    assert len(cars) >= 2 and not off, off
    result = scenario.getSimulator().simulate(scene, maxSteps=11, maxIterations=1)
    assert result is not None  # Scenic's requirements held over the simulation
    # Every moving actor after 1.1 s of its behaviour (its replay path by arc length, its segments' timing) is
    # within the 3 m target of where the recording has it.
    moving = set(re.findall(r"^(\S+) = new Car .*R2sSegments", text, re.M))
    last = scene_from_json(open(av2_clip[-1]).read())
    at = {"ego": last.world.point(last.ego.x, last.ego.y)}
    at.update({e.id: last.world.point(e.x, e.y) for e in last.entities})
    checked = 0
    for index, name in enumerate(names):
        if name in moving and name in at:
            x, y = result.result.trajectory[-1][index][:2]
            assert math.hypot(x + ox - at[name][0], y + oy - at[name][1]) < 3.0, name
            checked += 1
    assert checked >= 2
    # The requirements are live: a bound below ego's recorded speed makes Scenic reject every scene (`require
    # always` holds from the first instant on, which sampling already checks).
    tight = re.sub(r"require always ego\.speed <= [0-9.]+", "require always ego.speed <= 0.2", text)
    assert tight != text
    with pytest.raises(RejectionException):
        scenic.scenarioFromString(tight, mode2D=True).generate(maxIterations=5)


def test_a_track_seen_in_the_first_frame_only_simulates(excerpt_frames, tmp_path):
    """nuScenes scene-0796's car9 is in its first keyframe only: its one segment lasts 0 s (`for Range(0, 0) s`).
    The replay divided by that duration (ZeroDivisionError inside Scenic); the segment covers no time, so the car
    has nothing to replay and stops."""
    scenic = pytest.importorskip("scenic")
    clip = scene_files(excerpt_frames, [f"scene-0796/{k}" for k in range(3)], tmp_path)
    _, out = _clip_scenic(clip, tmp_path)
    text = out.read_text()
    assert re.search(r"^car9 = new Car .*R2sSegments\(\[\(0\.0, ", text, re.M)  # a moving car, one 0 s segment
    scenario = scenic.scenarioFromFile(str(out), mode2D=True)
    scene, _ = scenario.generate(maxIterations=20)
    assert scenario.getSimulator().simulate(scene, maxSteps=10, maxIterations=1) is not None
