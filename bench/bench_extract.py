"""Extraction throughput per source: frames per second through each extractor, written to bench/results/extract.*.

- scenarionet: all six shared nuScenes-mini scenes (../shared; target: under 10 s for all of them), plus the
  shipped excerpt.
- nuscenes: the shipped 13-table excerpt through nuscenes-devkit (the devkit import is timed separately).
- argoverse2: the shared Argoverse 2 logs (or the shipped test excerpt without ../shared).
- mcap / rosbag: files written from the excerpt's real nuScenes values by the tests' fixture writers, in each
  layout (SceneUpdate protobuf, ROS 2 Detection3DArray, ROS 1 MarkerArray, ROS 2 sqlite3 / mcap bags).
Each measurement runs the extractor to the end (rows built, not written) and takes the best of --repeat runs.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(ROOT))  # tests.support

from common import machine, write_results  # noqa: E402
from realdata import SHARED  # noqa: E402

from extractors.categories import ALL  # noqa: E402
from extractors.registry import source as source_of  # noqa: E402

EXCERPT = ROOT / "data" / "nuscenes-mini-excerpt"


def measure(source: str, path: Path, repeat: int, **opts) -> dict:
    extract = source_of(source).extract
    options = source_of(source).options(categories=ALL, **opts)
    best, frames, rows = float("inf"), 0, 0
    for _ in range(repeat):
        t = time.perf_counter()
        out = list(extract(str(path), options))
        best = min(best, time.perf_counter() - t)
        frames, rows = len(out), sum(len(f) for f in out)
    return {"source": source, "input": str(path.relative_to(path.anchor)) if path.is_absolute() else str(path),
            "frames": frames, "rows": rows, "seconds": round(best, 4), "frames_per_s": round(frames / best, 1)}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()

    from tests.support import logs as fx

    results = []
    shared_sn = SHARED / "data" / "nuscenes-mini" / "scenarionet"
    if shared_sn.is_dir():
        with tempfile.TemporaryDirectory() as tmp:  # the whole command, imports and Parquet writing included
            t = time.perf_counter()
            subprocess.run([sys.executable, "-m", "pipeline.cli", "extract", "scenarionet", str(shared_sn), "--out",
                            f"{tmp}/f.parquet", "--categories", "all"], check=True, cwd=ROOT, capture_output=True)
            cli_s = time.perf_counter() - t
        results.append({**measure("scenarionet", shared_sn, args.repeat), "label": "six shared nuScenes-mini scenes",
                        "cli_wall_s": round(cli_s, 2)})
    results.append({**measure("scenarionet", EXCERPT / "scenarionet", args.repeat), "label": "excerpt"})

    t = time.perf_counter()
    import nuscenes.nuscenes  # noqa: F401
    devkit_import_s = time.perf_counter() - t
    results.append({**measure("nuscenes", EXCERPT, args.repeat), "label": "excerpt (13 tables)",
                    "devkit_import_s": round(devkit_import_s, 2)})

    av2 = SHARED / "data" / "argoverse2"
    av2 = av2 if av2.is_dir() else ROOT / "tests" / "data" / "argoverse2"
    results.append({**measure("argoverse2", av2, args.repeat), "label": "logs"})

    # one log holding the excerpt's scenes one after another (each scene's clock starts at zero: shift them apart)
    samples = [replace(s, t_ns=s.t_ns + i * 10**11) for i, scene in enumerate(fx.scenes().values()) for s in scene]
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        fx.write_foxglove_protobuf(tmp / "pb.mcap", samples)
        results.append({**measure("mcap", tmp / "pb.mcap", args.repeat), "label": "foxglove.SceneUpdate protobuf"})
        fx.write_ros2_mcap(tmp / "ros2.mcap", samples)
        results.append({**measure("mcap", tmp / "ros2.mcap", args.repeat, topics=("/detections",)),
                        "label": "ROS 2 Detection3DArray (base_link)"})
        fx.write_rosbag1(tmp / "r1.bag", samples)
        results.append({**measure("rosbag", tmp / "r1.bag", args.repeat, pose_topic="/odom"),
                        "label": "ROS 1 MarkerArray + Odometry"})
        for storage in ("sqlite3", "mcap"):
            fx.write_rosbag2(tmp / storage, samples, storage)
            results.append({**measure("rosbag", tmp / storage, args.repeat), "label": f"ROS 2 bag ({storage})"})

    md = ["# Extraction throughput", "", "| source | input | frames | rows | s (best) | frames/s |",
          "|---|---|---|---|---|---|"]
    md += [f"| {r['source']} | {r['label']} | {r['frames']} | {r['rows']} | {r['seconds']} | {r['frames_per_s']} |"
           for r in results]
    sn = next((r for r in results if r.get("label") == "six shared nuScenes-mini scenes"), None)
    if sn:
        md += ["", f"All six shared scenes through scenarionet: {sn['seconds']} s in process, {sn['cli_wall_s']} s as "
               "`r2s extract scenarionet ... --categories all` (imports and writing included; target < 10 s)."]
    for r in results:
        print(f"{r['source']:12s} {r['label']:40s} {r['frames']:5d} frames {r['seconds']:8.3f} s "
              f"{r['frames_per_s']:9.1f} frames/s")
    write_results("extract", {"machine": machine(), "results": results}, "\n".join(md) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
