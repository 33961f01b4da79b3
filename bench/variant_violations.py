"""Every checker violation of every simulated variant, per clip and seed (issue 38: why a variant Scenic accepts
is refused). For each clip of bench_behaviours (the shipped AV2 log's 8 s clips; the shared Waymo clips where
present), the clip program is synthesized, its variant scenario (synth.behaviour.variants) compiled once and
simulated for each seed (one simulation each: no second draw) as `r2s simulate` does (pipeline.simulation: rows read back as `r2s scene` reads them,
then `r2s check`'s verdict); each violation is printed, and for a behaviour that does not hold, each of its
segments on the recorded boundaries: which of duration, path, pace fails, with the simulated speeds, headings and
lanes of its samples.

    .venv/bin/python bench/variant_violations.py --only av2 "waymo 1096" --seeds 5
"""

from __future__ import annotations

import argparse
import random
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from bench_behaviours import CONFIG, ROOT, SHARED, extracted, scenes_of  # noqa: E402

from frames.maps import FrameRoads, maps_dir, maps_writer  # noqa: E402
from frames.schema import MAPS_DIR  # noqa: E402
from pipeline.export.opendrive import export_road, header_frame  # noqa: E402
from pipeline.scenes import scene as frame_scene  # noqa: E402
from pipeline.simulation import _compile, _read_back, variant_rows, variant_seed  # noqa: E402
from synth.behaviour.check import check_clip  # noqa: E402
from synth.behaviour.kinds import EPS  # noqa: E402
from synth.behaviour.program import ClipProgram  # noqa: E402
from synth.behaviour.synthesize import synthesize_behaviours  # noqa: E402
from synth.behaviour.track import read_clip  # noqa: E402
from synth.behaviour.variant_lanes import LaneWatch  # noqa: E402
from synth.behaviour.variants import variant_scenic  # noqa: E402
from synth.road.lane_facts import RoadIndex  # noqa: E402
from synth.window.road import window_road  # noqa: E402
from synth.world import road_in_world  # noqa: E402


def clips(work: Path, only: list[str]):
    av2 = ROOT / "data" / "argoverse2-log-excerpt" / "frames.parquet"
    for scene, ids in scenes_of(av2).items():
        for start in range(0, len(ids) - 1, 80):
            part = ids[start:start + 81]
            name = f"av2 {scene[:8]} frames {start}-{start + len(part) - 1}"
            if len(part) >= 41 and any(o in name for o in only):
                yield name, av2, part
    if (SHARED / "waymo").is_dir() and any(o.startswith("waymo") for o in only):
        wy = extracted("scenarionet", SHARED / "waymo", work / "waymo")
        for scene, ids in scenes_of(wy).items():
            if any(o in f"waymo {scene[:8]}" for o in only):
                yield f"waymo {scene[:8]}", wy, ids[:91]


def segments_report(behaviour, sim_track, bounds) -> list[str]:
    """Each segment of the behaviour on the simulated track between its recorded boundaries: what fails."""
    s, out = sim_track.samples, []
    for j, (seg, a, b) in enumerate(zip(behaviour.segments, bounds, bounds[1:])):
        fails = []
        if not seg.duration.contains(s[b].t - s[a].t, EPS):
            fails.append(f"duration {s[b].t - s[a].t:.3f}")
        if seg.path is not None and not seg.path.holds(s, sim_track.steps, a, b):
            fails.append("path")
        if not seg.pace.holds(s, a, b, CONFIG):
            fails.append("pace")
        if fails:
            speeds = " ".join(f"{x.speed:.2f}" for x in s[a:b + 1])
            heads = " ".join(f"{x.heading:.0f}" for x in s[a:b + 1])
            lanes = " ".join(str(x.lane) for x in s[a:b + 1])
            keep = "".join("k" if x else ("L" if lt else "R" if rt else ".") for x, lt, rt in
                           zip(sim_track.steps.keep[a:b], sim_track.steps.left[a:b], sim_track.steps.right[a:b]))
            out.append(f"    segment {j} [{a}..{b}] {seg}: {', '.join(fails)}\n      speeds {speeds}\n"
                       f"      headings {heads}\n      lanes {lanes}\n      steps {keep}")
    return out


def diagnose(name: str, frames: Path, ids: list[str], work: Path, seeds: int) -> tuple[int, int]:
    scenes = [frame_scene(str(frames), fid) for fid in ids]
    clip = read_clip(scenes)
    result = synthesize_behaviours(clip, CONFIG)
    first = work / "first.json"
    first.write_text(scenes[0].to_json())
    xodr = str(work / "road.xodr")
    export_road(str(first), None, xodr)
    bounds = {seg.behaviour.id: seg.boundaries for seg in result.segmented}
    sim = variant_scenic(name, [result.program.behaviour(t.id) for t in clip.tracks],
                         [bounds[t.id] for t in clip.tracks], clip, xodr, CONFIG,
                         (header_frame(xodr) or (0.0, 0.0))[:2])
    world_road = road_in_world(scenes[0].world, window_road(scenes))
    watch = LaneWatch(RoadIndex(world_road), clip.graph, sim.offset, sim.frame_steps, sim.lane_rules)
    scenario = _compile(sim.text, {"r2s_lanes": watch})
    kept = ClipProgram(result.program.program, tuple(result.program.behaviour(i) for i in sim.placed))
    maps = work / "maps"
    (maps / MAPS_DIR).mkdir(parents=True, exist_ok=True)
    with maps_writer(maps / MAPS_DIR / "part-000000.parquet") as w:
        w.add(world_road)
    index, roads = RoadIndex(world_road), FrameRoads(maps_dir(maps))
    simulator = scenario.getSimulator()
    accepted = passed = 0
    for k in range(seeds):
        s = variant_seed(0, k)
        random.seed(s)
        np.random.seed(s)
        started = time.perf_counter()
        scene, _ = scenario.generate(maxIterations=100)
        run = simulator.simulate(scene, maxSteps=sim.steps, maxIterations=1, timestep=sim.timestep)
        if run is None:
            print(f"{name} seed {k}: rejected by Scenic {watch.failure}", flush=True)
            continue
        accepted += 1
        rows = variant_rows(f"v{k}", sim, clip, run.result.records["r2s_states"], index)
        simulated = read_clip([_read_back(f, roads) for f in rows])
        verdict = check_clip(kept, simulated, CONFIG)
        passed += verdict.ok
        print(f"{name} seed {k}: {len(verdict.violations)} violations ({time.perf_counter() - started:.1f} s)",
              flush=True)
        for v in verdict.violations:
            print(f"  {v}")
            behaviour, track = kept.behaviour(v.entity), simulated.track(v.entity)
            if v.part == "behaviour" and behaviour is not None and track is not None:
                print("\n".join(segments_report(behaviour, track, bounds[v.entity])))
    print(f"{name}: Scenic accepts {accepted} of {seeds}, the checker {passed} of those", flush=True)
    return accepted, passed


def main() -> None:
    parser = argparse.ArgumentParser(description="Checker violations of simulated variants (module docstring).")
    parser.add_argument("--only", nargs="+", metavar="NAME", default=["av2"])
    parser.add_argument("--seeds", type=int, default=3)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        for name, frames, ids in clips(work, args.only):
            one = work / name.replace(" ", "_")
            one.mkdir()
            diagnose(name, frames, ids, one, args.seeds)


if __name__ == "__main__":
    main()
