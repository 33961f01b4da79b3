"""Every shipped pattern over 10^6 frames (issue 39): `r2s query --events` with default options, each pattern of
data/patterns and data/patterns/lanes, over one replica of a real log that carries its map.

The shipped Argoverse 2 log (data/argoverse2-log-excerpt: 156 frames at 10 Hz, ~42 rows a frame, speeds, lane facts
and its map beside it) is replicated under distinct scene ids to --frames frames (bench_lanes.replicate: copy r's
scene `<scene>~r`, every column kept, ten part files, the one map shared by every copy), so one-frame, temporal and
lane patterns all run over real tracks on a real map. Each pattern runs in a fresh process as the command a user
types (`r2s query FRAMES PATTERN --out F --events`, pipeline.cli's main: no --memory-limit, so the default limit),
timed by wall clock, with its CPU time and peak RSS (VmHWM) and the load average just before and after it. Its
events, and the bindings in them (the sum of the events' frames), must be the copies times those on the log alone
(a check that the replica and the engine agree). Targets: under 60 s and 4 GB each. Writes
bench/results/patterns.json and patterns.md. `--quick`: 100,000 frames, for iterating.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(ROOT))

import pyarrow.parquet as pq  # noqa: E402
from bench_lanes import replicate  # noqa: E402
from common import R2S_CHILD, machine, run_child, write_results  # noqa: E402

LOG = ROOT / "data" / "argoverse2-log-excerpt" / "frames.parquet"
PATTERNS = sorted((ROOT / "data" / "patterns").glob("*.dsl")) + sorted((ROOT / "data" / "patterns" / "lanes").glob("*.dsl"))
TARGET_S, TARGET_MB = 60.0, 4096


def load() -> str:
    return " / ".join(f"{v:.2f}" for v in os.getloadavg())


def run_query(frames: Path, pattern: Path, out_dir: Path) -> dict:
    """One `r2s query --events` in a fresh process; its wall, CPU, peak RSS, events and bindings."""
    out = out_dir / f"{pattern.stem}.parquet"
    before = os.getloadavg()[0]
    rec = run_child("bench_patterns", [sys.executable, "-c", R2S_CHILD, "query", str(frames), str(pattern),
                                       "--out", str(out), "--events"], ROOT)
    table = pq.read_table(out, columns=["n_frames"])
    rec.update(pattern=str(pattern.relative_to(ROOT / "data" / "patterns")), events=table.num_rows,
               bindings=int(sum(table["n_frames"].to_pylist())), load_before=before, load_after=os.getloadavg()[0])
    out.unlink()
    print(f"  {rec['pattern']}: {rec['wall_s']:.1f} s wall, {rec['cpu_s']:.1f} s CPU, {rec['events']:,} events, "
          f"{rec['bindings']:,} bindings, peak RSS {rec['peak_rss_mb']:.0f} MB (load {before:.2f} -> "
          f"{rec['load_after']:.2f})", flush=True)
    return rec


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--frames", type=int, default=1_000_000, help="frames to replicate to (default 1,000,000)")
    ap.add_argument("--quick", action="store_true", help="100,000 frames (for iterating)")
    ap.add_argument("--only", metavar="TEXT", help="only the patterns whose path holds TEXT")
    args = ap.parse_args()
    n_frames = 100_000 if args.quick else args.frames
    patterns = [p for p in PATTERNS if not args.only or args.only in str(p)]
    load_before = load()
    print(f"bench_patterns: load average {load_before}", flush=True)
    runs = []
    with tempfile.TemporaryDirectory(prefix="r2s-bench-patterns-") as tmp:
        tmp = Path(tmp)
        single = {p: run_query(LOG, p, tmp) for p in patterns}  # the log alone: the counts to scale
        frames = tmp / "frames"
        t = time.perf_counter()
        copies, rows = replicate(LOG, n_frames, frames, parts=10)
        n = copies * len(set(pq.read_table(LOG, columns=["frame_id"])["frame_id"].to_pylist()))
        print(f"{n:,} frames ({copies:,} copies of the log), {rows:,} rows ({time.perf_counter() - t:.0f} s to write)",
              flush=True)
        for p in patterns:
            rec = run_query(frames, p, tmp)
            rec.update(n_frames=n, rows=rows, copies=copies,
                       scales=(rec["events"], rec["bindings"]) == (copies * single[p]["events"],
                                                                   copies * single[p]["bindings"]),
                       within_target=rec["wall_s"] < TARGET_S and rec["peak_rss_mb"] < TARGET_MB)
            runs.append(rec)
    payload = {"machine": machine(), "load_before": load_before, "load_after": load(), "target_s": TARGET_S,
               "target_mb": TARGET_MB, "runs": runs,
               "single_log": [{"pattern": r["pattern"], "events": r["events"], "bindings": r["bindings"]}
                              for r in single.values()]}
    write_results("patterns" if not args.quick else "patterns-quick", payload, markdown(payload))
    return 0


def markdown(p: dict) -> str:
    m = p["machine"]
    runs = p["runs"]
    md = [
        f"# Every shipped pattern: `r2s query --events` over {runs[0]['n_frames']:,} replicated real frames", "",
        f"Machine: {m['cpu']} ({m['cores']} cores, shared), Python {m['python']}, {m['date']}, commit {m['commit']}. "
        f"Load average (1 / 5 / 15 min) before: {p['load_before']}, after: {p['load_after']}.", "",
        f"The shipped Argoverse 2 log (156 frames at 10 Hz, with its map) replicated as {runs[0]['copies']:,} distinct "
        f"scenes ({runs[0]['rows']:,} rows, ten part files, one map). Each pattern in a fresh process as "
        "`r2s query FRAMES PATTERN --out F --events` with default options (the default memory limit), one after "
        "another; wall clock including validation of the rows, the lane relations of the map and writing the "
        f"events. Target: under {p['target_s']:.0f} s and {p['target_mb']} MB each. `scales`: the events and the "
        "bindings in them (the sum of the events' frames) are the copies times those on the log alone.", "",
        "| pattern | events | bindings | scales | wall (s) | CPU (s) | peak RSS (MB) | load (1 min) before -> after | "
        "within target |",
        "|---|---:|---:|---|---:|---:|---:|---|---|",
    ]
    for r in runs:
        md.append(f"| {r['pattern']} | {r['events']:,} | {r['bindings']:,} | {r['scales']} | {r['wall_s']:.1f} | "
                  f"{r['cpu_s']:.1f} | {r['peak_rss_mb']:,.0f} | {r['load_before']:.2f} -> {r['load_after']:.2f} | "
                  f"{'yes' if r['within_target'] else '**no**'} |")
    md += ["", f"Every pattern within the target: **{'yes' if all(r['within_target'] for r in runs) else 'no'}**; "
           f"every count scales with the copies: **{'yes' if all(r['scales'] for r in runs) else 'no'}**.", "",
           "Reproduce: `python bench/bench_patterns.py` (`--quick`: 100,000 frames; `--only TEXT`: some patterns).", ""]
    return "\n".join(md)


if __name__ == "__main__":
    sys.exit(main())
