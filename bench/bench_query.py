"""Query benchmark (issue 17): `r2s query` over 200,000 and 1,000,000 frames, against plain Python backtracking.

The 242 shipped nuScenes-mini keyframes (data/nuscenes-mini-keyframes, up to 141 entities, ~41 rows a frame) are
replicated under distinct frame ids, rows in their original order: 200,000 frames (8.3 M rows) in one file, and
1,000,000 frames (41 M rows) as a dataset of ten part files. Each query runs in a fresh process through
pipeline.query.mining.query_frames (what `r2s query` runs, minus argument parsing), timed by wall clock, with its peak RSS.
The two-name pattern of the target is data/patterns/pedestrian-beside-vehicle.dsl; the one- and three-name shipped
patterns run at 200,000 frames too. The baseline is synth.patterns.one_frame.matches (backtracking, each statement checked by
synth.semantics as soon as its name is bound) on frames read with pandas and built into scenes, over a subset,
extrapolated linearly; its matches are checked against the engine's on that subset. Writes bench/results/query.json
and query.md. The machine is shared: the load average is recorded before and after.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

from common import machine, peak_rss_mb, run_child, write_results  # noqa: E402

from synth.patterns.temporal import is_temporal  # noqa: E402

KEYFRAMES = ROOT / "data" / "nuscenes-mini-keyframes" / "frames.parquet"
PATTERNS = ROOT / "data" / "patterns"
TWO_NAMES = PATTERNS / "pedestrian-beside-vehicle.dsl"
TARGET_S = 20.0
# The shipped one-frame patterns (the temporal ones: bench/bench_temporal.py).
ONE_FRAME_PATTERNS = [p for p in sorted(PATTERNS.glob("*.dsl")) if not is_temporal(p.read_text())]


def load() -> str:
    return " / ".join(f"{v:.2f}" for v in os.getloadavg())


def replicate(n_frames: int, out: Path, parts: int = 1) -> int:
    """n_frames frames: the keyframes again and again, copy r's frame ids suffixed `~r`; rows keep their order."""
    import duckdb

    con = duckdb.connect(config={"threads": os.cpu_count() or 1})
    con.execute("SET enable_progress_bar = false")  # duckdb 2.0 refuses it as a connect-time option
    con.execute(f"CREATE TEMP TABLE base AS SELECT *, file_row_number AS rn, "
                f"dense_rank() OVER (ORDER BY frame_ord) - 1 AS fno FROM (SELECT *, min(file_row_number) OVER "
                f"(PARTITION BY frame_id) AS frame_ord FROM read_parquet('{KEYFRAMES}', file_row_number = true))")
    per = con.execute("SELECT count(DISTINCT frame_id) FROM base").fetchall()[0][0]
    reps = -(-n_frames // per)
    cols = ("source, scene, frame_index, timestamp_us, entity_id, track_id, type, category, x, y, heading, "
            "length, width, is_ego")
    if parts > 1:
        out.mkdir(parents=True, exist_ok=True)
    for p in range(parts):
        lo, hi = reps * p // parts, reps * (p + 1) // parts
        target = out / f"part-{p:03d}.parquet" if parts > 1 else out
        con.execute(
            f"COPY (SELECT CASE WHEN r = 0 THEN frame_id ELSE frame_id || '~' || r END AS frame_id, {cols} "
            f"FROM range({lo}, {hi}) t(r), base WHERE r * {per} + fno < {n_frames} ORDER BY r, rn) "
            f"TO '{target}' (FORMAT parquet, COMPRESSION zstd, ROW_GROUP_SIZE 122880)")
    rows = con.execute(f"SELECT count(*) FROM read_parquet('{out}{'/*.parquet' if parts > 1 else ''}')").fetchall()[0][0]
    con.close()
    return int(rows)


def one(frames: str, pattern: str, threads: int | None, memory_mb: int | None) -> None:
    """Child process: one query; prints its summary and peak RSS as JSON."""
    from pipeline.query.mining import query_frames
    from synth.patterns.one_frame import parse_pattern

    with tempfile.TemporaryDirectory(prefix="r2s-bench-query-out-") as tmp:
        s = query_frames(frames, parse_pattern(Path(pattern).read_text()), Path(tmp) / "matches.parquet",
                         threads=threads, memory_limit_mb=memory_mb, log=lambda m: None)
    rss = peak_rss_mb()
    print(json.dumps({"frames": s.frames_scanned, "matched": s.frames_matched, "bindings": s.bindings,
                      "checked_exactly": s.checked_exactly, "query_s": s.seconds, "peak_rss_mb": rss}))


def run_query(frames: Path, pattern: Path, threads: int | None = None, memory_mb: int | None = None) -> dict:
    cmd = [sys.executable, str(Path(__file__).resolve()), "--one", str(frames), str(pattern)]
    cmd += ["--threads", str(threads)] if threads else []
    cmd += ["--memory-limit", str(memory_mb)] if memory_mb else []
    rec = run_child("bench_query", cmd, ROOT)
    wall = rec["wall_s"]
    rec.update(pattern=pattern.name, threads=threads, memory_limit_mb=memory_mb)
    print(f"  {pattern.name} on {rec['frames']:,} frames: {wall:.1f} s wall ({rec['query_s']:.1f} s in query), "
          f"{rec['matched']:,} frames matched, {rec['bindings']:,} bindings, {rec['checked_exactly']} checked "
          f"exactly, peak RSS {rec['peak_rss_mb']:.0f} MB", flush=True)
    return rec


def python_baseline(frames: Path, pattern: Path) -> dict:
    """Plain Python: read the frames with pandas, build scenes, backtrack with synth.patterns.one_frame.matches."""
    from frames.rows import iter_scenes, read_frames
    from synth.patterns.one_frame import matches, parse_pattern

    pat = parse_pattern(pattern.read_text())
    t0 = time.perf_counter()
    scenes = list(iter_scenes(read_frames(frames)))
    t1 = time.perf_counter()
    found = {s.frame_id: [tuple(b.values()) for b in matches(pat, s)] for s in scenes}
    t2 = time.perf_counter()
    return {"frames": len(scenes), "read_and_build_s": t1 - t0, "match_s": t2 - t1, "total_s": t2 - t0,
            "found": {k: v for k, v in found.items() if v}}


def engine_bindings(frames: Path, pattern: Path) -> dict:
    import pyarrow.parquet as pq

    from pipeline.query.mining import query_frames
    from synth.patterns.one_frame import parse_pattern

    pat = parse_pattern(pattern.read_text())
    with tempfile.TemporaryDirectory(prefix="r2s-bench-query-out-") as tmp:
        out = Path(tmp) / "all.parquet"
        query_frames(frames, pat, out, all_bindings=True, log=lambda m: None)
        got: dict[str, list] = {}
        for row in pq.read_table(out).to_pylist():
            got.setdefault(row["frame_id"], []).append(tuple(row["binding"][n] for n in pat.names))
    return got


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--quick", action="store_true", help="20,000 frames and a 2,000-frame baseline only")
    ap.add_argument("--one", nargs=2, metavar=("FRAMES", "PATTERN"), help=argparse.SUPPRESS)
    ap.add_argument("--threads", type=int, help=argparse.SUPPRESS)
    ap.add_argument("--memory-limit", type=int, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.one:
        one(*args.one, args.threads, args.memory_limit)
        return 0
    sizes = (20_000,) if args.quick else (200_000, 1_000_000)
    subset = 2_000 if args.quick else 10_000
    load_before = load()
    print(f"bench_query: load average {load_before}", flush=True)
    runs, baseline = [], {}
    with tempfile.TemporaryDirectory(prefix="r2s-bench-query-") as tmp:
        tmp = Path(tmp)
        small = tmp / "subset.parquet"
        replicate(subset, small)
        base = python_baseline(small, TWO_NAMES)
        engine = engine_bindings(small, TWO_NAMES)
        agree = engine == base.pop("found")
        baseline = {**base, "pattern": TWO_NAMES.name, "agrees_with_engine": agree,
                    "per_frame_ms": 1000 * base["total_s"] / base["frames"]}
        print(f"  python baseline on {base['frames']:,} frames: {base['total_s']:.1f} s "
              f"({base['read_and_build_s']:.1f} s reading and building scenes, {base['match_s']:.1f} s matching); "
              f"same matches as the engine: {agree}", flush=True)
        for n in sizes:
            frames = tmp / (f"frames-{n}" + ("" if n >= 1_000_000 else ".parquet"))
            t = time.perf_counter()
            rows = replicate(n, frames, parts=10 if n >= 1_000_000 else 1)
            print(f"{n:,} frames, {rows:,} rows ({time.perf_counter() - t:.0f} s to write)", flush=True)
            patterns = [TWO_NAMES] if n >= 1_000_000 else ONE_FRAME_PATTERNS
            for p in patterns:
                runs.append({"n_frames": n, "rows": rows, **run_query(frames, p)})
            if n >= 1_000_000 or args.quick:
                runs.append({"n_frames": n, "rows": rows, **run_query(frames, TWO_NAMES, memory_mb=1024)})
            frames.unlink() if frames.is_file() else None
    load_after = load()
    two = {r["n_frames"]: r for r in runs if r["pattern"] == TWO_NAMES.name and r["memory_limit_mb"] is None}
    n0 = min(two)
    payload = {"machine": machine(), "load_before": load_before, "load_after": load_after, "target_s": TARGET_S,
               "target_frames": 200_000, "runs": runs, "python_baseline": baseline,
               "python_extrapolated_s": {n: baseline["per_frame_ms"] * n / 1000 for n in two},
               "speedup_vs_python": {n: baseline["per_frame_ms"] * n / 1000 / r["wall_s"] for n, r in two.items()},
               "target_met": two[n0]["wall_s"] < TARGET_S if n0 == 200_000 else None}
    write_results("query", payload, markdown(payload))
    return 0


def markdown(p: dict) -> str:
    m = p["machine"]
    b = p["python_baseline"]
    md = [
        "# Query benchmark: `r2s query` over replicated real frames", "",
        f"Machine: {m['cpu']} ({m['cores']} cores), Python {m['python']}, {m['date']}, commit {m['commit']}. "
        f"Load average (1 / 5 / 15 min) before: {p['load_before']}, after: {p['load_after']}.", "",
        "The 242 shipped nuScenes-mini keyframes replicated under distinct ids (rows in their order); each query in a "
        "fresh process, wall clock including validation of the rows and writing matches.parquet; all threads.", "",
        "| frames | rows | pattern (names) | memory limit | wall (s) | frames matched | bindings | checked exactly | "
        "peak RSS (MB) |",
        "|---:|---:|---|---:|---:|---:|---:|---:|---:|",
    ]
    for r in p["runs"]:
        names = len([line for line in (PATTERNS / r["pattern"]).read_text().splitlines()
                     if line.strip() and not line.startswith("#")])
        md.append(f"| {r['n_frames']:,} | {r['rows']:,} | {r['pattern']} ({names}) | "
                  f"{str(r['memory_limit_mb']) + ' MB' if r['memory_limit_mb'] else 'default'} | {r['wall_s']:.1f} | "
                  f"{r['matched']:,} | {r['bindings']:,} | {r['checked_exactly']} | {r['peak_rss_mb']:.0f} |")
    md += ["", f"Plain Python backtracking (synth.patterns.one_frame.matches, frames read with pandas and built into scenes) on "
           f"{b['frames']:,} frames of the two-name pattern: {b['total_s']:.1f} s ({b['read_and_build_s']:.1f} s "
           f"reading and building scenes, {b['match_s']:.1f} s matching), {b['per_frame_ms']:.2f} ms a frame; same "
           f"matches as the engine: **{b['agrees_with_engine']}**.", ""]
    for n, s in p["python_extrapolated_s"].items():
        md.append(f"- {int(n):,} frames: Python ~{s:.0f} s (extrapolated), engine {s / p['speedup_vs_python'][n]:.1f} s: "
                  f"**{p['speedup_vs_python'][n]:.0f}x**.")
    if p["target_met"] is not None:
        md += ["", f"Target: 200,000 frames for a two-name pattern in under {p['target_s']:.0f} s: "
               f"**{'met' if p['target_met'] else 'NOT met'}**."]
    return "\n".join(md) + "\n"


if __name__ == "__main__":
    sys.exit(main())
