"""Pipeline benchmark (issue 4): every shared nuScenes-mini keyframe, all categories, through `r2s run` end to end.

End to end means as a user runs it: `r2s extract scenarionet ... --categories all`, then `r2s run --jobs 2` from a
fresh process (interpreter start, imports, worker pool start, synthesis with certification, atomic writing), timed
by wall clock. `--jobs 1` runs in the same invocation for the ratio (the machine is shared: compare within a run).
Writes bench/results/pipeline.json and pipeline.md. Without ../shared it measures the shipped keyframes
(data/nuscenes-mini-keyframes, the same 242 frames).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

from common import machine, write_results  # noqa: E402
from realdata import SHARED  # noqa: E402

SCENARIONET = SHARED / "data" / "nuscenes-mini" / "scenarionet"
SHIPPED = ROOT / "data" / "nuscenes-mini-keyframes" / "frames.parquet"
TARGET_S = 60.0


def r2s(*args: str) -> float:
    """Wall-clock seconds of one `r2s` command in a fresh process; a failure stops the benchmark."""
    t = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "pipeline.cli", *args], capture_output=True, text=True, cwd=ROOT)
    elapsed = time.perf_counter() - t
    if proc.returncode != 0:
        raise SystemExit(f"bench_pipeline: r2s {' '.join(args)} failed: {proc.stderr.strip()}")
    return elapsed


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--quick", action="store_true", help="--jobs 2 only (no --jobs 1 ratio)")
    args = ap.parse_args()
    import pandas as pd

    with tempfile.TemporaryDirectory(prefix="r2s-bench-pipeline-") as tmp:
        frames = Path(tmp) / "frames.parquet"
        if SCENARIONET.is_dir():
            source = "shared/data/nuscenes-mini/scenarionet"
            extract_s = r2s("extract", "scenarionet", str(SCENARIONET), "--categories", "all", "--out", str(frames))
        else:
            source, extract_s = str(SHIPPED.relative_to(ROOT)), 0.0
            frames.write_bytes(SHIPPED.read_bytes())
        runs = {}
        for jobs in ((2,) if args.quick else (2, 1)):
            out = Path(tmp) / f"programs-{jobs}.parquet"
            run_s = r2s("run", str(frames), "--out", str(out), "--jobs", str(jobs))
            df = pd.read_parquet(out)
            runs[jobs] = {
                "run_s": run_s, "frames": len(df), "frames_per_s": len(df) / run_s,
                "optimal_share": float((df["status"] == "optimal").mean()),
                "certified_share": float(df["certified"].mean()),
                "max_entities": int(df["n_entities"].max()),
                "frame_runtime_s": {"median": float(df["runtime_s"].median()), "max": float(df["runtime_s"].max())},
                "peak_rss_mb": float(df["peak_rss_mb"].max()), "mean_cost": float(df["cost"].mean()),
            }
            print(f"--jobs {jobs}: {len(df)} frames in {run_s:.1f} s ({len(df) / run_s:.1f} frames/s), "
                  f"{runs[jobs]['optimal_share']:.0%} optimal", flush=True)
    two = runs[2]
    payload = {"machine": machine(), "source": source, "extract_s": extract_s, "runs": runs,
               "end_to_end_s": extract_s + two["run_s"], "target_s": TARGET_S,
               "speedup_2_vs_1": runs[1]["run_s"] / two["run_s"] if 1 in runs else None}
    m = payload["machine"]
    md = [
        "# Pipeline benchmark: every keyframe through `r2s run`", "",
        f"Machine: {m['cpu']} ({m['cores']} cores), Python {m['python']}, {m['date']}, commit {m['commit']}. "
        f"Input: {source}, all categories within 50 m. Wall clock of fresh `r2s` processes.", "",
        "| jobs | frames | max N | run (s) | frames/s | optimal | certified | median frame (s) | max frame (s) | "
        "peak RSS per worker (MB) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for jobs, r in runs.items():
        md.append(f"| {jobs} | {r['frames']} | {r['max_entities']} | {r['run_s']:.1f} | {r['frames_per_s']:.1f} | "
                  f"{r['optimal_share']:.0%} | {r['certified_share']:.0%} | {r['frame_runtime_s']['median']:.3f} | "
                  f"{r['frame_runtime_s']['max']:.2f} | {r['peak_rss_mb']:.0f} |")
    verdict = "within" if payload["end_to_end_s"] < TARGET_S else "OVER"
    md += ["", f"End to end with --jobs 2 (extract {extract_s:.1f} s + run {two['run_s']:.1f} s): "
               f"**{payload['end_to_end_s']:.1f} s**, {verdict} the {TARGET_S:.0f} s target."]
    if payload["speedup_2_vs_1"]:
        md.append(f"--jobs 2 against --jobs 1 in the same invocation: {payload['speedup_2_vs_1']:.2f}x.")
    write_results("pipeline", payload, "\n".join(md) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
