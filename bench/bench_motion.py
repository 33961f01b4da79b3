"""Motion (issue 16) against static synthesis on the shared frames. Writes bench/results/motion.json and motion.md.

Frames: every nuScenes-mini keyframe of ../shared/data/nuscenes-mini/scenarionet through `r2s extract
scenarionet` (all categories within 50 m; speeds = |state.velocity|); without ../shared the shipped excerpt
(data/nuscenes-mini-excerpt, 9 keyframes). Each frame is synthesized static and with --motion (default config:
auto, hybrid, z3 certification), one right after the other so both see the same machine load. Reported: program
cost (and how much of it is motion), runtime (ratio within the run), certification, and how many entities the
optimum calls stationary / moving like another / relative / absolute, overall and by kind of road user.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from collections import Counter
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

from common import machine, write_results  # noqa: E402
from realdata import SHARED  # noqa: E402

from extractors.base import ExtractOptions  # noqa: E402
from extractors.categories import ALL  # noqa: E402
from extractors.scenarionet import extract  # noqa: E402
from frames.rows import iter_scenes  # noqa: E402
from synth.config import SynthConfig  # noqa: E402
from synth.parts import MOTION  # noqa: E402
from synth.scene import VEHICLE_CLASSES, Scene  # noqa: E402
from synth.synthesize import synthesize  # noqa: E402

SHARED_PICKLES = SHARED / "data" / "nuscenes-mini" / "scenarionet"
EXCERPT = ROOT / "data" / "nuscenes-mini-excerpt" / "scenarionet"
FAMILIES = {"vehicle": VEHICLE_CLASSES, "pedestrian": frozenset({"Pedestrian", "Animal"})}  # else: static object


def family(etype: str) -> str:
    return next((name for name, types in FAMILIES.items() if etype in types), "static object")


def frames(source: Path) -> list[Scene]:
    import pandas as pd

    rows = [r for frame in extract(str(source), ExtractOptions(categories=ALL)) for r in frame]
    return list(iter_scenes(pd.DataFrame(rows)))


def run(scenes: list[Scene]) -> list[dict]:
    static, motion = SynthConfig(), SynthConfig(motion=True)
    out = []
    for k, scene in enumerate(scenes):
        a = synthesize(scene, static)
        b = synthesize(scene, motion)
        types = {e.id: e.type for e in scene.others}
        kinds = Counter((s.motion.kind, family(types[s.id])) for s in b.program.statements)
        out.append({
            "frame_id": scene.frame_id, "n": len(scene.others),
            "static": {"cost": a.cost, "status": a.status, "certified": a.certified, "runtime_s": a.stats.runtime_s,
                       "smt_queries": a.stats.smt_queries},
            "motion": {"cost": b.cost, "status": b.status, "certified": b.certified, "runtime_s": b.stats.runtime_s,
                       "smt_queries": b.stats.smt_queries,
                       "motion_cost": sum(s.motion.cost for s in b.program.statements),
                       "kinds": [[kind, fam, n] for (kind, fam), n in sorted(kinds.items())]},
        })
        if (k + 1) % 25 == 0:
            print(f"  {k + 1}/{len(scenes)} frames", flush=True)
    return out


def summary(rows: list[dict]) -> dict:
    n = sum(r["n"] for r in rows)
    kinds: Counter = Counter()
    by_family: dict[str, Counter] = {}
    for r in rows:
        for kind, fam, c in r["motion"]["kinds"]:
            kinds[kind] += c
            by_family.setdefault(fam, Counter())[kind] += c
    rt_s, rt_m = (sum(r[k]["runtime_s"] for r in rows) for k in ("static", "motion"))
    ratios = [r["motion"]["runtime_s"] / r["static"]["runtime_s"] for r in rows if r["static"]["runtime_s"] > 0]
    return {
        "frames": len(rows), "entities": n, "max_entities": max(r["n"] for r in rows),
        "optimal": {k: sum(r[k]["status"] == "optimal" for r in rows) for k in ("static", "motion")},
        "certified": {k: sum(r[k]["certified"] for r in rows) for k in ("static", "motion")},
        "mean_cost": {k: statistics.fmean(r[k]["cost"] for r in rows) for k in ("static", "motion")},
        "cost_per_entity": {k: sum(r[k]["cost"] for r in rows) / n for k in ("static", "motion")},
        "motion_cost_per_entity": sum(r["motion"]["motion_cost"] for r in rows) / n,
        # The motion program's positions and headings may cost more than the static optimum where an order that
        # lets speeds ride on one another is worth it: what the joint optimum trades.
        "position_heading_cost_over_static": sum(r["motion"]["cost"] - r["motion"]["motion_cost"] - r["static"]["cost"]
                                                 for r in rows),
        "frames_motion_free": sum(r["motion"]["motion_cost"] == 0 for r in rows),
        "kinds": {k: kinds.get(k, 0) for k in MOTION.kinds},
        "kinds_by_family": {f: {k: c.get(k, 0) for k in MOTION.kinds} for f, c in sorted(by_family.items())},
        "runtime_s": {"static": rt_s, "motion": rt_m, "ratio_total": rt_m / rt_s if rt_s else None,
                      "ratio_median": statistics.median(ratios) if ratios else None,
                      "motion_median_s": statistics.median(r["motion"]["runtime_s"] for r in rows),
                      "motion_max_s": max(r["motion"]["runtime_s"] for r in rows)},
    }


def markdown(doc: dict) -> str:
    s, m = doc["summary"], doc["machine"]
    rt = s["runtime_s"]
    lines = [
        "# Motion against static synthesis", "",
        f"Machine: {m['cpu']} ({m['cores']} cores), commit {m['commit']}, {m['date']}; load average "
        f"{doc['load'][0]:.2f} at the start, {doc['load'][1]:.2f} at the end; total {doc['seconds']:.0f} s.", "",
        f"Frames: {doc['frames_source']}: {s['frames']} keyframes, {s['entities']} entities (up to "
        f"{s['max_entities']} per frame), all categories within 50 m, speeds from ScenarioNet's state.velocity. "
        "Default configuration (auto, hybrid, z3 certification); each frame static then with `--motion`.", "",
        "| | static | motion |", "|---|---:|---:|",
        f"| optimal | {s['optimal']['static']}/{s['frames']} | {s['optimal']['motion']}/{s['frames']} |",
        f"| certified | {s['certified']['static']}/{s['frames']} | {s['certified']['motion']}/{s['frames']} |",
        f"| mean program cost | {s['mean_cost']['static']:.2f} | {s['mean_cost']['motion']:.2f} |",
        f"| cost per entity | {s['cost_per_entity']['static']:.3f} | {s['cost_per_entity']['motion']:.3f} |",
        f"| runtime, all frames | {rt['static']:.1f} s | {rt['motion']:.1f} s |", "",
        f"Motion costs {s['motion_cost_per_entity']:.3f} per entity (a program saying every speed relative to ego "
        f"would cost 1, absolute speeds 2); {s['frames_motion_free']} of {s['frames']} frames say every speed for "
        f"free. The joint optimum spends {s['position_heading_cost_over_static']} more on positions and headings than "
        "the static optimum over all frames (0: the static order never had to change). Runtime, motion over static: "
        f"x{rt['ratio_total']:.2f} in total, median x{rt['ratio_median']:.2f} per frame (median motion frame "
        f"{rt['motion_median_s'] * 1000:.0f} ms, slowest {rt['motion_max_s']:.2f} s).", "",
        "## What the optimum says about speeds", "",
        "| | " + " | ".join(MOTION.kinds) + " | entities |", "|---|" + "---:|" * (len(MOTION.kinds) + 1),
    ]
    total = sum(s["kinds"].values())
    lines.append("| all | " + " | ".join(f"{s['kinds'][k]} ({s['kinds'][k] / total:.0%})" for k in MOTION.kinds)
                 + f" | {total} |")
    for fam, c in s["kinds_by_family"].items():
        lines.append(f"| {fam} | " + " | ".join(str(c[k]) for k in MOTION.kinds) + f" | {sum(c.values())} |")
    lines += ["", "stationary: speed <= 0.5 m/s (no reference); moving like: within 1 m/s of an entity declared "
              "earlier, or of ego; relative speed: the fallback relative to ego (cost 1); absolute speed: cost 2."]
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="one keyframe in five")
    args = ap.parse_args()
    started, load0 = time.perf_counter(), os.getloadavg()[0]
    if SHARED_PICKLES.is_dir():
        source, label = SHARED_PICKLES, "nuScenes-mini through ScenarioNet (../shared)"
    else:
        print(f"bench_motion: {SHARED_PICKLES} not found; using the shipped excerpt", flush=True)
        source, label = EXCERPT, "the shipped nuScenes-mini ScenarioNet excerpt"
    scenes = frames(source)
    if args.quick:
        scenes = scenes[::5]
    print(f"bench_motion: {len(scenes)} frames from {source}", flush=True)
    rows = run(scenes)
    doc = {"machine": machine(), "frames_source": label, "quick": args.quick, "summary": summary(rows),
           "frames": rows, "load": [load0, os.getloadavg()[0]], "seconds": time.perf_counter() - started}
    write_results("motion", doc, markdown(doc))


if __name__ == "__main__":
    main()
