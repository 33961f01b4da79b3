"""`r2s export` of a clip (--clip FILES, FRAMES --scene S) and `--steps T --program P.json`, run as a user runs
them on shipped data: the Argoverse 2 log make demo uses (frames 100..110, entities that appear and leave), and
the nuScenes keyframes (2 Hz). ScenarioNet: MetaDrive's format check with its valid check, every step of every
track against the recorded world poses worked out here from scene JSON's own rule; OpenSCENARIO: ASAM's checker,
and every trajectory read back from the XML; bad input one line, exit 2, nothing written."""

from __future__ import annotations

import json
import math
import pickle
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from pipeline.cli import main as cli_main
from tests.support import ROOT, assert_one_line_error, run_r2s
from tests.support.extract import EXCERPT

from .test_export_openscenario import asam_issues, road_offset

LOG = ROOT / "data" / "argoverse2-log-excerpt" / "frames.parquet"
LOG_ID = "adcf7d18-0510-35b0-a2fa-b4cea13a6d76"
KEYFRAMES = ROOT / "data" / "nuscenes-mini-keyframes" / "frames.parquet"
CLIP = range(100, 111)


def _ok(res):
    assert res.returncode == 0, res.stderr
    return res


@pytest.fixture(scope="module")
def clip(tmp_path_factory) -> list[Path]:
    """Frames 100..110 of the shipped AV2 log as scene JSON (r2s scene), and their clip program beside them.
    The first scene is a real `r2s scene` process; the other ten run the same verb in this process
    (pipeline.cli.main), saving ten interpreter start-ups: this file is about export, not scene."""
    root = tmp_path_factory.mktemp("clip")
    files = []
    for k in CLIP:
        files.append(root / f"f{k}.json")
        args = ("scene", str(LOG), f"{LOG_ID}/{k}", "--out", str(files[-1]))
        if k == CLIP[0]:
            _ok(run_r2s(*args))
        else:
            assert cli_main(list(args)) == 0, args
    _ok(run_r2s("synth", *map(str, files), "--behaviours", "--motion", "--lanes", "--format", "json",
                "--out", str(root / "clip.json")))
    return files


def world_place(scene: dict, e: dict) -> tuple[float, float, float]:
    """docs/formats.md's rule: (x, y) of the ego frame at (X + x sin h + y cos h, Y - x cos h + y sin h), the
    heading θ at the world yaw h + θ (radians here)."""
    w = scene["world"]
    h = math.radians(w["heading"])
    return (w["x"] + e["x"] * math.sin(h) + e["y"] * math.cos(h), w["y"] - e["x"] * math.cos(h) + e["y"] * math.sin(h),
            math.radians(w["heading"] + e["heading"]))


def _gap(a: float, b: float) -> float:
    return abs(math.remainder(a - b, math.tau))


def recorded_tracks(files: list[Path]) -> tuple[list[float], dict[str, dict[int, tuple]]]:
    """The clip's times (s after the first) and each entity's (x, y, yaw, speed) by frame, from the files."""
    scenes = [json.loads(f.read_text()) for f in files]
    t0 = scenes[0]["world"]["timestamp_us"]
    tracks: dict[str, dict[int, tuple]] = {}
    for k, s in enumerate(scenes):
        for e in s["entities"]:
            tracks.setdefault(e["id"], {})[k] = (*world_place(s, e), e.get("speed") or 0.0)
    return [(s["world"]["timestamp_us"] - t0) / 1e6 for s in scenes], tracks


def _scenario(db: Path) -> dict:
    (name,) = [p for p in db.iterdir() if p.name.startswith("sd_")]
    return pickle.loads(name.read_bytes())


def test_a_clip_to_scenarionet_is_every_step_of_every_track(clip, metadrive_format_check, tmp_path):
    _ok(run_r2s("export", *map(str, clip), "--clip", "--to", "scenarionet", "--out", str(tmp_path / "db")))
    sd = _scenario(tmp_path / "db")
    metadrive_format_check(sd, check_self_type=True, valid_check=True)
    times, tracks = recorded_tracks(clip)
    assert sd["length"] == len(clip) and np.allclose(sd["metadata"]["ts"], times, atol=1e-12, rtol=0)
    assert set(sd["tracks"]) == set(tracks) and sd["metadata"]["r2sgen"]["clip"]["frames"] == len(clip)
    absent = 0
    for tid, by_frame in tracks.items():
        state = sd["tracks"][tid]["state"]
        for k in range(len(clip)):
            if k not in by_frame:
                absent += 1
                assert not state["valid"][k] and not state["position"][k].any() and not state["velocity"][k].any()
                continue
            x, y, yaw, speed = by_frame[k]
            assert state["valid"][k]
            assert math.hypot(state["position"][k][0] - x, state["position"][k][1] - y) < 1e-6
            assert _gap(state["heading"][k], yaw) < 1e-9
            assert state["velocity"][k] == pytest.approx([speed * math.cos(yaw), speed * math.sin(yaw)], abs=1e-9)
    assert absent > 0  # the clip has entities that appear or leave: their steps are not valid
    # and r2s extract scenarionet reads it back: a frame per step at the clip's times, each track where it was
    back = tmp_path / "back.parquet"
    _ok(run_r2s("extract", "scenarionet", str(tmp_path / "db"), "--radius", "1000", "--out", str(back)))
    rows = pq.read_table(back).to_pylist()
    assert sorted({r["timestamp_us"] for r in rows}) == [round(t * 1e6) for t in times]
    assert len(rows) == sum(len(by_frame) for by_frame in tracks.values())
    for r in rows:
        x, y, yaw, _ = tracks[r["track_id"]][r["frame_index"]]
        assert math.hypot(r["map_x"] - x, r["map_y"] - y) < 1e-6 and _gap(math.radians(r["map_heading"]), yaw) < 1e-9


def _trajectories(xosc: Path) -> dict[str, dict]:
    """Each entity's start (Init: WorldPosition or LanePosition's foot is not read: only its path), its path's
    vertices (time, x, y, h) and its speed pieces (start time, duration, target), read from the XML."""
    root = ET.parse(xosc).getroot()
    out: dict[str, dict] = {o.get("name"): {"path": [], "speeds": [], "arrives": None, "leaves": None,
                                            "in_init": False} for o in root.iter("ScenarioObject")}
    for private in root.find("Storyboard/Init/Actions").iter("Private"):
        out[private.get("entityRef")]["in_init"] = private.find(".//TeleportAction") is not None
    for gone in root.find("Storyboard/Init/Actions").iter("EntityAction"):
        assert gone.find("DeleteEntityAction") is not None and not out[gone.get("entityRef")]["in_init"]
    for group in root.iter("ManeuverGroup"):
        eid = group.find("Actors/EntityRef").get("entityRef")
        for event in group.iter("Event"):
            start = float(event.find(".//SimulationTimeCondition").get("value"))
            added = event.find(".//AddEntityAction/Position/WorldPosition")
            if added is not None:
                out[eid]["arrives"] = (start, *(float(added.get(a)) for a in "xyh"))
            if event.find(".//DeleteEntityAction") is not None:
                out[eid]["leaves"] = start
            poly = event.find(".//FollowTrajectoryAction//Polyline")
            if poly is not None:
                out[eid]["path"] = [(float(v.get("time")), *(float(v.find("Position/WorldPosition").get(a))
                                                            for a in "xyh")) for v in poly.findall("Vertex")]
                assert event.find(".//TimeReference/None") is not None
            speed = event.find(".//SpeedAction")
            if speed is not None:
                out[eid]["speeds"].append((start, float(speed.find("SpeedActionDynamics").get("value")),
                                           float(speed.find(".//AbsoluteTargetSpeed").get("value"))))
    return out


def test_a_clip_to_openscenario_passes_asam_and_its_paths_and_speeds_read_back(clip, tmp_path):
    _ok(run_r2s("export", *map(str, clip), "--clip", "--to", "openscenario", "--out", str(tmp_path / "osc")))
    (xosc,) = (tmp_path / "osc").glob("*.xosc")
    (xodr,) = (tmp_path / "osc").glob("*.xodr")
    assert asam_issues(xosc) == [] and asam_issues(xodr) == []
    ox, oy = road_offset(xodr)
    times, tracks = recorded_tracks(clip)
    back = _trajectories(xosc)
    assert set(back) == set(tracks)
    moving = 0
    for tid, by_frame in tracks.items():
        b = back[tid]
        ks = sorted(by_frame)
        # there from its first frame to its last: placed at the start or added at its first pose just before its
        # time, removed just after its last
        assert b["in_init"] == (ks[0] == 0) and (b["arrives"] is None) == (ks[0] == 0)
        if b["arrives"] is not None:
            t, x, y, h = b["arrives"]
            rx, ry, ryaw, _ = by_frame[ks[0]]
            assert times[ks[0]] - 0.002 < t < times[ks[0]] and math.hypot(x + ox - rx, y + oy - ry) < 1e-6
        assert (b["leaves"] is None) == (ks[-1] == len(clip) - 1)
        if b["leaves"] is not None:
            assert times[ks[-1]] < b["leaves"] < times[ks[-1]] + 0.002
        if not b["path"]:
            continue
        moving += 1
        assert [t for t, *_ in b["path"]] == pytest.approx([times[k] for k in ks], abs=1e-9)
        for (_, x, y, h), k in zip(b["path"], ks):
            rx, ry, ryaw, _ = by_frame[k]
            assert math.hypot(x + ox - rx, y + oy - ry) < 1e-6 and _gap(h, ryaw) < 1e-9
        # the speed profile: linear over each step to the recorded speed at its end, where it changes
        first = times[ks[0]]
        pieces = [(times[a], times[b_] - times[a], by_frame[b_][3]) for a, b_ in zip(ks, ks[1:])
                  if by_frame[b_][3] != by_frame[a][3]]
        got = [p for p in b["speeds"] if not (p[0] == pytest.approx(first, abs=1e-6) and p[1] == 0)] \
            if first > 0 else b["speeds"]
        assert [(round(s, 6), round(d, 6), v) for s, d, v in got] == \
            [(round(max(0.0, s - 1e-9), 6), round(d, 6), pytest.approx(v, abs=1e-9)) for s, d, v in pieces]
    assert moving > 10
    assert any(b["arrives"] for b in back.values()) and any(b["leaves"] is not None for b in back.values())


@pytest.fixture(scope="module")
def excerpt(tmp_path_factory) -> Path:
    """The shipped nuScenes excerpt (ScenarioNet, 2 Hz keyframes with world poses and a map) as frames."""
    frames = tmp_path_factory.mktemp("excerpt") / "frames.parquet"
    _ok(run_r2s("extract", "scenarionet", str(EXCERPT / "scenarionet"), "--categories", "all", "--out", str(frames)))
    return frames


def test_frames_scene_is_the_clip_of_its_frames(excerpt, metadrive_format_check, tmp_path):
    """FRAMES --scene S (nuScenes at 2 Hz): every frame of S in time order, as r2s scene gives them."""
    scene = "scene-0103"
    _ok(run_r2s("export", str(excerpt), "--scene", scene, "--to", "scenarionet", "--out", str(tmp_path / "a")))
    sd = _scenario(tmp_path / "a")
    n = sd["length"]
    files = []
    for k in range(n):
        files.append(tmp_path / f"f{k}.json")
        # In process (the clip fixture runs r2s scene as a real process): 4 interpreter start-ups fewer.
        assert cli_main(["scene", str(excerpt), f"{scene}/{k}", "--out", str(files[-1])]) == 0, k
    _ok(run_r2s("export", *map(str, files), "--clip", "--to", "scenarionet", "--out", str(tmp_path / "b")))
    again = _scenario(tmp_path / "b")
    metadrive_format_check(sd, check_self_type=True, valid_check=True)
    assert n == 4 and sd["metadata"]["ts"].tolist() == [0.0, 0.5, 1.0, 1.5]  # 2 Hz, all of the scene's frames
    assert sd["tracks"].keys() == again["tracks"].keys()
    for tid, t in sd["tracks"].items():
        for key, v in t["state"].items():
            assert np.array_equal(v, again["tracks"][tid]["state"][key]), (tid, key)


def _two_scenes(tmp_path: Path) -> list[str]:
    a, b = tmp_path / "a.json", tmp_path / "b.json"
    _ok(run_r2s("scene", str(LOG), f"{LOG_ID}/100", "--out", str(a)))
    _ok(run_r2s("scene", str(KEYFRAMES), "scene-0103/1", "--out", str(b)))
    return [str(a), str(b)]


@pytest.mark.parametrize("case", ["two scenes", "unordered", "one frame", "unknown scene", "steps", "clip and scene",
                                  "program of another clip", "not a clip program"])
def test_bad_clips_are_one_line_exit_2_and_nothing_written(case, clip, tmp_path):
    out = tmp_path / "out"
    args = {
        "two scenes": lambda: [*_two_scenes(tmp_path), "--clip"],
        "unordered": lambda: [str(clip[1]), str(clip[0]), str(clip[2]), "--clip"],
        "one frame": lambda: [str(clip[0]), "--clip"],
        "unknown scene": lambda: [str(LOG), "--scene", "scene-9999"],
        "steps": lambda: [*map(str, clip[:3]), "--clip", "--steps", "5"],
        "clip and scene": lambda: [str(LOG), "--clip", "--scene", LOG_ID],
        "program of another clip": lambda: [str(clip[1]), "--steps", "5", "--program",
                                            str(clip[0].with_name("clip.json"))],
        "not a clip program": lambda: _not_a_program(clip, tmp_path),
    }[case]()
    res = run_r2s("export", *args, "--to", "scenarionet", "--out", str(out))
    assert_one_line_error(res, 2)
    assert not out.exists()


def _not_a_program(clip, tmp_path):
    bad = tmp_path / "p.json"
    bad.write_text('{"program": "x"}')
    return [str(clip[0]), "--steps", "5", "--program", str(bad)]


def test_a_simulated_variant_exports_as_its_frames(clip, metadrive_format_check, tmp_path):
    """r2s simulate's output is a frames dataset: FRAMES --scene SCENE-sim000 is the simulated clip, every step of
    every simulated track at the world place the simulation wrote (its frames' map_x, map_y, map_heading)."""
    sim = tmp_path / "sim"
    _ok(run_r2s("simulate", str(clip[0].with_name("clip.json")), *map(str, clip), "--motion", "--lanes", "--n", "1",
                "--seed", "0", "--time-limit", "60", "--out", str(sim)))
    name = f"{LOG_ID}-sim000"
    _ok(run_r2s("export", str(sim), "--scene", name, "--to", "scenarionet", "--out", str(tmp_path / "db")))
    _ok(run_r2s("export", str(sim), "--scene", name, "--to", "openscenario", "--out", str(tmp_path / "osc")))
    sd = _scenario(tmp_path / "db")
    metadrive_format_check(sd, check_self_type=True, valid_check=True)
    rows = pq.read_table(sim / "part-000000.parquet").to_pylist()
    assert {r["entity_id"] for r in rows} == set(sd["tracks"]) and sd["length"] == len(clip)
    for r in rows:
        state = sd["tracks"][r["entity_id"]]["state"]
        k = r["frame_index"]
        assert state["valid"][k]
        assert math.hypot(state["position"][k][0] - r["map_x"], state["position"][k][1] - r["map_y"]) < 1e-6
        assert _gap(state["heading"][k], math.radians(r["map_heading"])) < 1e-9
    assert sum(state["valid"].sum() for state in (t["state"] for t in sd["tracks"].values())) == len(rows)
    for f in (tmp_path / "osc").iterdir():
        assert asam_issues(f) == [], f.name
