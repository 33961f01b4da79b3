"""r2s simulate's scenario puts every entity on Scenic's road where it stood on the recorded one: the road file is
recentred (its header's offset), Scenic's OpenDRIVE reader does not apply the offset, so places are the world's
less it (docs/scenic.md "Simulated variants"). Checked on the shipped Argoverse 2 log: each entity with a recorded
lane lies in a lane of the network Scenic reads from the file, and its simulated state read back is its world place."""

from __future__ import annotations

import json

import pytest

from pipeline.export.opendrive import export_road
from pipeline.scenes import scene as frame_scene
from pipeline.simulation import _boundaries, _compile, read_program_json, road_offset
from synth.behaviour.track import read_clip
from synth.behaviour.variants import variant_scenic
from synth.config import as_config
from tests.support import ROOT, run_r2s

AV2 = ROOT / "data" / "argoverse2-log-excerpt" / "frames.parquet"
LOG = "adcf7d18-0510-35b0-a2fa-b4cea13a6d76"

pytest.importorskip("scenic")


def test_placed_entities_lie_in_scenics_lanes(tmp_path):
    from scenic.domains.driving.roads import Network

    frames = []
    for k in range(100, 103):
        path = tmp_path / f"f{k}.json"
        path.write_text(frame_scene(str(AV2), f"{LOG}/{k}").to_json())
        frames.append(str(path))
    program = tmp_path / "clip.json"
    proc = run_r2s("synth", *frames, "--behaviours", "--motion", "--lanes", "--format", "json", "--out", str(program))
    assert proc.returncode == 0, proc.stderr
    config = as_config({"motion": True, "lanes": True})
    clip_program, bounds, _ = read_program_json(program.read_text(), str(program))
    scenes = [json.loads(open(f).read()) for f in frames]
    clip = read_clip(scenes)
    xodr = str(tmp_path / "road.xodr")
    export_road(frames[0], None, xodr)
    offset = road_offset(xodr)
    assert offset != (0.0, 0.0)  # the road is recentred: the test means something
    sim = variant_scenic("t", [clip_program.behaviour(t.id) for t in clip.tracks],
                         _boundaries(clip_program, bounds, clip, config, "t"), clip, xodr, config, offset)
    scene, _ = _compile(sim.text).generate(maxIterations=10)
    network = Network.fromFile(xodr)
    first = clip.scenes[0]
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
