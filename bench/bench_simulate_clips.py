"""`r2s simulate RUN_OUTPUT --frames FRAMES` at scale (issue 38 item 5): simulated clips per minute with --jobs 1 and
--jobs 2. Writes bench/results/simulate_clips.json and .md.

The shipped Argoverse 2 log's first CLIPS seconds (10 Hz, with its map), its clip programs made once by
`r2s run FRAMES --clip 1 --lanes --motion` (CLIPS clips of 1 s), then `r2s simulate` of that output with --n K
--seed 0 into a new folder, once per --jobs, each as a process (what a user runs: the interpreter's start, the check,
the workers' Scenic import and every clip's compile and simulations included). Wall and CPU seconds of the whole
command (CPU: its process and its workers, reaped); clips per minute = clips / wall * 60. The machine is shared (2 cores, other work on it): compare the two rates of
one run, not rates across runs.

    .venv/bin/python bench/bench_simulate_clips.py [--clips 8] [--n 1]
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

import pandas as pd  # noqa: E402
import pyarrow.parquet as pq  # noqa: E402
from common import machine, write_results  # noqa: E402

from frames.maps import maps_dir  # noqa: E402
from frames.rows import write_frames  # noqa: E402

AV2 = ROOT / "data" / "argoverse2-log-excerpt" / "frames.parquet"


def r2s(*args: str) -> tuple[float, float, str]:
    """Wall and CPU seconds of `r2s ARGS` as a process (its workers included: they are its children), and its
    stderr."""
    started, cpu = time.monotonic(), _children_cpu()
    proc = subprocess.run([sys.executable, "-m", "pipeline.cli", *args], cwd=ROOT, capture_output=True, text=True)
    if proc.returncode != 0:
        raise SystemExit(f"r2s {' '.join(args)} failed ({proc.returncode}): {proc.stderr[-400:]}")
    return time.monotonic() - started, _children_cpu() - cpu, proc.stderr


def _children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--clips", type=int, default=8, help="clips of 1 s (the log's first CLIPS seconds)")
    ap.add_argument("--n", type=int, default=1, help="variants per clip")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="bench-simulate-") as tmp:
        root = Path(tmp)
        df = pd.read_parquet(AV2)
        frames = root / "frames.parquet"
        write_frames(df[df.frame_index < 10 * args.clips].reset_index(drop=True), frames)
        shutil.copytree(maps_dir(AV2), maps_dir(frames))
        clips = root / "clips"
        r2s("run", str(frames), "--clip", "1", "--lanes", "--motion", "--jobs", "2", "--out", str(clips))
        n_clips = sum(r["program"] is not None for r in pq.read_table(clips, columns=["program"]).to_pylist())
        runs = []
        for jobs in (1, 2):
            out = root / f"sims-{jobs}"
            load = os.getloadavg()[0]
            wall, cpu, log = r2s("simulate", str(clips), "--frames", str(frames), "--motion", "--n", str(args.n),
                            "--seed", "0", "--jobs", str(jobs), "--out", str(out))
            rows = pq.read_table(out / "_simulations").to_pylist()
            written = sum(r["written"] or 0 for r in rows)
            runs.append({"jobs": jobs, "clips": len(rows), "wall_s": round(wall, 2), "cpu_s": round(cpu, 2),
                         "clips_per_min": round(len(rows) / wall * 60, 2), "variants_written": written,
                         "variants_asked": args.n * len(rows), "load_before": round(load, 2),
                         "load_after": round(os.getloadavg()[0], 2), "summary": log.strip().splitlines()[-1]})
            print(f"--jobs {jobs}: {len(rows)} clips in {wall:.1f} s, {len(rows) / wall * 60:.1f} clips/min, "
                  f"{written} of {args.n * len(rows)} variants written")
    speedup = runs[0]["wall_s"] / runs[1]["wall_s"]
    payload = {"machine": machine(), "clips": n_clips, "clip_s": 1.0, "n": args.n, "runs": runs,
               "speedup_jobs2": round(speedup, 2)}
    lines = [
        "# r2s simulate RUN_OUTPUT at scale", "",
        f"`.venv/bin/python bench/bench_simulate_clips.py --clips {args.clips} --n {args.n}`: the shipped Argoverse 2 "
        f"log's first {args.clips} s as {n_clips} clips of 1 s (`r2s run --clip 1 --lanes --motion`), then `r2s "
        f"simulate` of them with --n {args.n} as a process, wall seconds of the whole command. "
        f"{payload['machine']['note']} ({payload['machine']['cpu']}, {payload['machine']['cores']} cores, "
        f"commit {payload['machine']['commit']}, {payload['machine']['date']}).", "",
        "| --jobs | clips | wall s | CPU s | clips per minute | variants written | load (1 min) before, after |",
        "|---|---|---|---|---|---|---|",
        *(f"| {r['jobs']} | {r['clips']} | {r['wall_s']:.1f} | {r['cpu_s']:.1f} | {r['clips_per_min']:.1f} | "
          f"{r['variants_written']} of "
          f"{r['variants_asked']} | {r['load_before']:.1f}, {r['load_after']:.1f} |" for r in runs), "",
        f"--jobs 2 is x{speedup:.2f} the rate of --jobs 1." + (
            f" The load was above the {payload['machine']['cores']} cores: the workers waited for CPU (CPU s well "
            "under wall s), so this ratio says what the shared machine gave, not what --jobs 2 does on idle cores; "
            "rerun on an idle machine for that." if max(r["load_before"] for r in runs) > payload["machine"]["cores"]
            else ""), "",
    ]
    write_results("simulate_clips", payload, "\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
