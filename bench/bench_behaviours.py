"""Behaviour programs of clips (issue 38): synthesis cost, the checker on the recording, and replay fidelity of
the dynamic Scenic scenario in Scenic's Newtonian simulator. Writes bench/results/behaviours.json and .md.

Clips: the shipped Argoverse 2 log (10 Hz, with its map) in 8 s clips; the shipped nuScenes excerpt extracted with
its maps (2 Hz keyframes, every scene whole); with ../shared/data, the shared Waymo scenarios (10 Hz, 9.1 s or
about 20 s; each cut to its first 9 s), extracted with their maps. Every clip: `r2s extract ... --categories all`,
then each frame as `r2s scene` gives it (pipeline.scenes.scene), with motion and lanes.

Per clip: frames, tracks, the clip program's cost, CPU seconds of its synthesis (this process's: the first frame's
relational program and every behaviour; the machine is shared, so wall time measures the load), whether the checker accepts the recording, and the replay: the
scenario `clip_scenic` writes on the first frame's road (`r2s export --to openscenario`) compiled and simulated
headless for the clip's length at 0.1 s steps; per actor placed in the first frame and not parked, the distance
between its simulated and recorded position at each of its recorded samples (the simulation step nearest the
sample's time): mean and max over the clip. Targets (issue 38, over 8 s clips): median of the actors' mean
distance <= 1.0 m; 90th percentile of their max <= 3.0 m.

Variants (`r2s simulate`, pipeline.simulation.simulate, as the verb runs it): per clip with a road, K = VARIANTS
variants with seed 0 from the clip program's JSON and its scene files; the share of simulations Scenic accepts
(a scene drawn, no `require always` broken, within TIME_LIMIT_S) and, of those, the share r2sgen's checker accepts
(target: 100%). Event retention (every clip with a written variant): every event of a shipped temporal
pattern (RETENTION_PATTERNS) that `r2s query --events` finds in the recording within the clip, its bound entities
simulated; of the written variants, the share in which `r2s query --events` on the simulated frames finds an event
of the same pattern with the same binding (target: >= 90%).

    .venv/bin/python bench/bench_behaviours.py
    .venv/bin/python bench/bench_behaviours.py --only av2 "waymo 2b3e" ...   # those clips only: behaviours-subset.*
    .venv/bin/python bench/bench_behaviours.py --replay-only   # synthesis, checker and replay, no variants:
                                                               # behaviours-replay.* (with --only: -replay-subset)
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

from common import machine, write_results  # noqa: E402

from pipeline.cli import main as r2s  # noqa: E402
from pipeline.errors import UserError  # noqa: E402
from pipeline.export.opendrive import header_frame  # noqa: E402
from pipeline.query.mining import query  # noqa: E402
from pipeline.scenes import scene as frame_scene  # noqa: E402
from pipeline.simulation import ATTEMPTS, NoVariantWritten, simulate  # noqa: E402
from synth import SynthConfig  # noqa: E402
from synth.behaviour.check import check_clip  # noqa: E402
from synth.behaviour.scenic import clip_scenic  # noqa: E402
from synth.behaviour.synthesize import synthesize_behaviours  # noqa: E402
from synth.behaviour.track import read_clip  # noqa: E402

CONFIG = SynthConfig(motion=True, lanes=True)
CLIP_S = 8.0
SHARED = Path("/work/shared/data")
STEP_S = 0.1
VARIANTS = 5
TIME_LIMIT_S = 120.0
RETENTION_PATTERNS = ("lanes/cut-in-by-lane-change.dsl", "lanes/vehicle-turning-left-in-intersection.dsl",
                      "vehicle-following-ego.dsl", "vehicle-braking-ahead.dsl")


def extracted(source: str, path: Path, out: Path) -> Path:
    if r2s(["extract", source, str(path), "--categories", "all", "--out", str(out)]):
        raise SystemExit(f"bench_behaviours: r2s extract {source} {path} failed")
    return out


def scenes_of(frames: Path) -> dict[str, list[str]]:
    """Each scene's frame ids in frame_index order."""
    import pyarrow.dataset as ds

    table = ds.dataset(str(frames), format="parquet").to_table(columns=["frame_id", "scene", "frame_index"])
    rows = sorted({(s, i, f) for f, s, i in zip(*(table[c].to_pylist() for c in ("frame_id", "scene", "frame_index")))})
    out: dict[str, list[str]] = {}
    for scene, _, fid in rows:
        out.setdefault(scene, []).append(fid)
    return out


def replay(result, scenes, work: Path) -> dict:
    """Simulate the clip's scenario and measure each moving actor's distance to its recording."""
    import scenic

    export = work / "export"
    shutil.rmtree(export, ignore_errors=True)
    first = work / "first.json"
    first.write_text(scenes[0].to_json())
    if r2s(["export", str(first), "--to", "openscenario", "--out", str(export)]):
        raise SystemExit("bench_behaviours: r2s export failed")
    (road,) = export.glob("*.xodr")
    ox, oy, _ = header_frame(str(road)) or (0.0, 0.0, 0.0)
    text = clip_scenic(result, str(road), CONFIG.v_stop, (ox, oy))
    scenario = scenic.scenarioFromString(text, mode2D=True)
    scene, _ = scenario.generate(maxIterations=20)
    steps = round(result.duration_s / STEP_S)
    started = time.perf_counter()
    sim = scenario.getSimulator().simulate(scene, maxSteps=steps, maxIterations=1, timestep=STEP_S)
    wall = time.perf_counter() - started
    if sim is None:
        return {"accepted": False, "sim_s_per_wall_s": None, "actors": []}
    trajectory = sim.result.trajectory
    placed = [t for t in result.clip.tracks if t.from_start]  # the scenario's objects, in its order
    world = {f: s.world for f, s in zip(result.frame_ids, scenes)}
    by_frame = [s.by_id() for s in scenes]
    actors = []
    for index, track in enumerate(placed):
        behaviour = result.program.behaviour(track.id)
        if behaviour.parked:
            continue
        distances = []
        frames = [k for k, s in enumerate(scenes) if track.id == "ego" or track.id in by_frame[k]]
        for k, sample in zip(frames, track.samples):
            e = scenes[k].ego if track.id == "ego" else by_frame[k][track.id]
            x, y = world[result.frame_ids[k]].point(e.x, e.y)
            step = min(round(sample.t / STEP_S), len(trajectory) - 1)
            sx, sy = trajectory[step][index][:2]
            sx, sy = sx + ox, sy + oy  # Scenic's frame is the road file's: back to the world
            distances.append(math.hypot(sx - x, sy - y))
        actors.append({"id": track.id, "type": track.type, "mean_m": statistics.fmean(distances),
                       "max_m": max(distances)})
    return {"accepted": True, "sim_s_per_wall_s": steps * STEP_S / wall, "actors": actors}


def variants(result, scenes, frames: Path, work: Path) -> dict:
    """K simulated variants of the clip (r2s simulate) and their event retention."""
    clip_dir = work / "variants"
    shutil.rmtree(clip_dir, ignore_errors=True)
    clip_dir.mkdir()
    paths = []
    for k, s in enumerate(scenes):
        paths.append(clip_dir / f"f{k:04d}.json")
        paths[-1].write_text(s.to_json())
    program = clip_dir / "clip.json"
    program.write_text(json.dumps(result.to_json_dict()))
    out = clip_dir / "simulated"
    try:
        done = simulate(program, paths, out, n=VARIANTS, seed=0, time_limit=TIME_LIMIT_S, config=CONFIG)
    except UserError as exc:
        return {"variants": None, "why_not": str(exc)}
    except NoVariantWritten as exc:
        done, out = exc.result, None
    counts = done.to_json_dict()
    accepted = VARIANTS - counts["rejected_by_scenic"] - counts["timed_out"]
    row = {"variants": {"asked": VARIANTS, "scenic_accepts": accepted, "checker_accepts": counts["written"],
                        "written": counts["written"], "seconds": dict(done.seconds),
                        "attempts": [v["attempts"] for v in counts["variants"]],
                        "reasons": [v["reason"] for v in counts["variants"] if v["outcome"] != "written"][:3]}}
    if out is not None:
        row["retention"] = retention(frames, scenes, done, out)
    return row


@functools.cache
def recorded_events(frames: str, name: str):
    """`r2s query --events` of a shipped pattern on a recording (once per recording: every clip of it reads it)."""
    return query(frames, (ROOT / "data" / "patterns" / name).read_text(), events=True)


def retention(frames: Path, scenes, done, out: Path) -> list[dict]:
    """Each recorded event of RETENTION_PATTERNS within the clip, its entities simulated: in how many written
    variants the same pattern finds the same binding."""
    ids = {s.frame_id for s in scenes}
    written = [v["scene"] for v in done.to_json_dict()["variants"] if v["outcome"] == "written"]
    rows = []
    for name in RETENTION_PATTERNS:
        text = (ROOT / "data" / "patterns" / name).read_text()
        recorded = recorded_events(str(frames), name)
        simulated = query(str(out), text, events=True)
        for _, event in recorded.iterrows():
            binding = dict(event["binding"])
            if event["first_frame"] not in ids or event["last_frame"] not in ids:
                continue
            if not set(binding.values()) <= set(done.simulated):
                rows.append({"pattern": name, "binding": binding, "simulated": False})
                continue
            found = {e["scene"] for _, e in simulated.iterrows() if dict(e["binding"]) == binding}
            rows.append({"pattern": name, "binding": binding, "simulated": True, "variants": len(written),
                         "retained": len(found & set(written))})
    return rows


def measure(name: str, frames: Path, ids: list[str], work: Path, replay_only: bool = False) -> dict:
    scenes = [frame_scene(str(frames), fid) for fid in ids]
    clip = read_clip(scenes)
    cpu = time.process_time()
    result = synthesize_behaviours(clip, CONFIG)
    cpu = time.process_time() - cpu
    ok = check_clip(result.program, clip, CONFIG).ok
    segments = [len(b.segments) for b in result.program.behaviours]
    row = {"clip": name, "frames": len(ids), "seconds": round(clip.duration, 2), "tracks": len(clip.tracks),
           "cost": result.cost, "relational_cost": result.first.cost, "synth_cpu_s": cpu,
           "behaviours_wall_s": result.behaviours_s,
           "checker_accepts": ok, "parked": segments.count(0), "max_segments": max(segments)}
    row.update(replay(result, scenes, work))
    if not replay_only:
        row.update(variants(result, scenes, frames, work))
    print(f"{name}: {row['tracks']} tracks, {row['frames']} frames, synthesis {cpu:.2f} CPU s, "
          f"checker {'ok' if ok else 'REFUSES'}", flush=True)
    return row


def clips(work: Path):
    av2 = ROOT / "data" / "argoverse2-log-excerpt" / "frames.parquet"
    for scene, ids in scenes_of(av2).items():
        for start in range(0, len(ids) - 1, 80):
            part = ids[start:start + 81]
            if len(part) >= 41:
                yield f"av2 {scene[:8]} frames {start}-{start + len(part) - 1}", av2, part
    nus = extracted("scenarionet", ROOT / "data" / "nuscenes-mini-excerpt" / "scenarionet", work / "nus")
    for scene, ids in scenes_of(nus).items():
        yield f"nuScenes {scene} (2 Hz)", nus, ids
    waymo = SHARED / "waymo"
    if waymo.is_dir():
        wy = extracted("scenarionet", waymo, work / "waymo")
        for scene, ids in scenes_of(wy).items():
            yield f"waymo {scene[:8]}", wy, ids[:91]


def cost_row(work: Path) -> dict | None:
    """Synthesis CPU on the most crowded shared Waymo clip, extracted within 300 m (every track of the scenario
    near ego: the issue's target is a 9 s, 100-track clip in under 5 s), without simulating it."""
    src = SHARED / "waymo" / "sd_waymo_v1.2_7e21cb7ea347ecaa.pkl"
    if not src.is_file():
        return None
    one = work / "crowded"
    one.mkdir()
    shutil.copy(src, one / src.name)
    out = work / "crowded-frames"
    if r2s(["extract", "scenarionet", str(one), "--categories", "all", "--radius", "300", "--out", str(out)]):
        raise SystemExit("bench_behaviours: r2s extract of the crowded Waymo clip failed")
    ((scene, ids),) = scenes_of(out).items()
    clip = read_clip([frame_scene(str(out), fid) for fid in ids[:91]])
    cpu = time.process_time()
    result = synthesize_behaviours(clip, CONFIG)
    cpu = time.process_time() - cpu
    return {"clip": f"waymo {scene[:8]} within 300 m", "frames": len(clip.scenes), "seconds": round(clip.duration, 2),
            "tracks": len(clip.tracks), "synth_cpu_s": cpu, "checker_accepts": check_clip(result.program, clip, CONFIG).ok}


def percentile(values: list[float], q: float) -> float:
    values = sorted(values)
    k = (len(values) - 1) * q
    lo, hi = math.floor(k), math.ceil(k)
    return values[lo] + (values[hi] - values[lo]) * (k - lo)


def variant_lines(rows: list[dict]) -> list[str]:
    """The Variants section: per clip, simulations Scenic accepts and variants the checker accepts; retention."""
    done = [r for r in rows if r.get("variants")]
    lines = ["## Variants (r2s simulate)", "",
             f"{VARIANTS} variants per clip, seed 0, --time-limit {TIME_LIMIT_S:g} s; Scenic draws another scene when a "
             f"simulation breaks a requirement (up to {ATTEMPTS} per variant); the checker reads each variant back "
             "from the frames written. Clips without a road are not simulated.", "",
             "| clip | Scenic accepts | simulations drawn (most for one variant) | checker accepts (of those) | "
             "first reason not written | seconds (compile, simulate, check) |",
             "|---|---|---|---|---|---|"]
    for r in done:
        v = r["variants"]
        sec = v["seconds"]
        tries = v.get("attempts") or [1]
        lines.append(f"| {r['clip']} | {v['scenic_accepts']} of {v['asked']} | {sum(tries)} ({max(tries)}) | "
                     f"{v['checker_accepts']} of "
                     f"{v['scenic_accepts']} | {(v['reasons'] or [''])[0][:160]} | {sec.get('compile', 0):.1f}, "
                     f"{sec.get('simulate', 0):.1f}, {sec.get('check', 0):.1f} |")
    asked = sum(r["variants"]["asked"] for r in done)
    scenic_ok = sum(r["variants"]["scenic_accepts"] for r in done)
    checker_ok = sum(r["variants"]["checker_accepts"] for r in done)
    drawn = sum(sum(r["variants"].get("attempts") or [1]) for r in done)
    lines += ["", f"Over {len(done)} clips: Scenic accepts a simulation of {scenic_ok} of {asked} variants "
              f"({100 * scenic_ok / max(asked, 1):.0f}%), {scenic_ok} of the {drawn} simulations drawn "
              f"({100 * scenic_ok / max(drawn, 1):.0f}%); the checker accepts {checker_ok} of those "
              f"({100 * checker_ok / max(scenic_ok, 1):.0f}%, target 100%).", ""]
    events = [e for r in done for e in r.get("retention", [])]
    if events:
        lines += ["Event retention (same pattern, same binding, in a written variant):", "",
                  "| clip | pattern | binding | retained |", "|---|---|---|---|"]
        for r in done:
            for e in r.get("retention", []):
                kept = f"{e['retained']} of {e['variants']}" if e["simulated"] else "not simulated (first seen later)"
                lines.append(f"| {r['clip']} | {e['pattern']} | {e['binding']} | {kept} |")
        sim = [e for e in events if e["simulated"]]
        kept, of = sum(e["retained"] for e in sim), sum(e["variants"] for e in sim)
        lines += ["", f"Retained in {kept} of {of} (event, written variant) pairs "
                  f"({100 * kept / max(of, 1):.0f}%, target >= 90%).", ""]
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description="Behaviour programs of clips (module docstring).")
    parser.add_argument("--only", nargs="+", metavar="NAME",
                        help="only the clips whose name contains one of these (results in behaviours-subset.*)")
    parser.add_argument("--replay-only", action="store_true",
                        help="synthesis, checker and replay only, no variants (results in behaviours-replay*.*)")
    args = parser.parse_args()
    only = args.only
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        for name, frames, ids in clips(work):
            if only is None or any(o in name for o in only):
                rows.append(measure(name, frames, ids, work, args.replay_only))
        crowded = cost_row(work) if only is None and not args.replay_only else None
    actors = [a for r in rows for a in r["actors"] if r["seconds"] >= CLIP_S - 0.5]
    summary = {"actors_8s": len(actors),
               "median_mean_m": statistics.median(a["mean_m"] for a in actors) if actors else None,
               "p90_max_m": percentile([a["max_m"] for a in actors], 0.9) if actors else None,
               "checker_accepts_all": all(r["checker_accepts"] for r in rows),
               "scenic_accepts": sum(r["accepted"] for r in rows), "clips": len(rows)}
    lines = ["# Behaviour programs of clips (issue 38)", "",
             "`.venv/bin/python bench/bench_behaviours.py`: module docstring. Replay: each segment simulated with its "
             "recorded parameters in Scenic's Newtonian simulator; distances per actor placed in the first frame and "
             "not parked.", "",
             "| clip | frames | s | tracks | parked | most segments | cost | synthesis CPU s | checker | Scenic | "
             "sim s / wall s | actors | median mean m | max max m |", "|---|" + "---|" * 13]
    for r in rows:
        means = [a["mean_m"] for a in r["actors"]]
        lines.append(f"| {r['clip']} | {r['frames']} | {r['seconds']} | {r['tracks']} | {r['parked']} | "
                     f"{r['max_segments']} | {r['cost']} | {r['synth_cpu_s']:.2f} | "
                     f"{'ok' if r['checker_accepts'] else 'refuses'} | {'ok' if r['accepted'] else 'rejects'} | "
                     f"{r['sim_s_per_wall_s'] or 0:.1f} | {len(means)} | "
                     f"{statistics.median(means) if means else 0:.2f} | "
                     f"{max((a['max_m'] for a in r['actors']), default=0):.2f} |")
    lines += ["", f"Over the {summary['actors_8s']} moving actors of clips of about 8 s or more: median of their "
              f"mean distance {summary['median_mean_m'] or 0:.2f} m (target <= 1.0), 90th percentile of their max "
              f"{summary['p90_max_m'] or 0:.2f} m (target <= 3.0). The checker accepts every recording: "
              f"{summary['checker_accepts_all']}. Scenic accepts {summary['scenic_accepts']} of {summary['clips']} "
              "simulations.", ""]
    if not args.replay_only:
        lines += variant_lines(rows)
    if crowded is not None:
        lines += [f"Cost: {crowded['clip']}, {crowded['tracks']} tracks over {crowded['frames']} frames "
                  f"({crowded['seconds']} s): synthesis {crowded['synth_cpu_s']:.2f} CPU s (target: under 5 s for "
                  f"100 tracks over 9 s); the checker accepts the recording: {crowded['checker_accepts']}.", ""]
    name = "behaviours" + ("-replay" if args.replay_only else "") + ("" if only is None else "-subset")
    write_results(name, {"machine": machine(), "summary": summary, "clips": rows, "crowded": crowded},
                  "\n".join(lines))


if __name__ == "__main__":
    main()
