"""Temporal patterns and events benchmark (issue 25): `r2s query` with three shipped temporal patterns (one of each
kind: a sequence with `within`, a behaviour, `for at least` then a step), and `--events` of a one-frame pattern,
over 1,000,000 frames.

The shipped Argoverse 2 log (data/argoverse2-log-excerpt: 156 frames at 10 Hz, ~42 rows a frame, speeds and
timestamps) is replicated under distinct scene ids (copy r's scene is `<scene>~r`, its frame ids
`<scene>~r/<index>`, its timestamps unchanged), rows in their original order, as a dataset of ten part files: so
every copy is a scene of its own, and steps, durations and behaviours run over real tracks. Each query runs in a
fresh process through pipeline.query.mining.query_frames (what `r2s query` runs, minus argument parsing), timed by
wall clock, with its peak RSS (VmHWM); the count of events or matching frames must be the copies times the count on
the log alone (a check that the replication and the engine agree). Writes bench/results/temporal.json and
temporal.md. The machine is shared: the load average is recorded before and after.
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

LOG = ROOT / "data" / "argoverse2-log-excerpt" / "frames.parquet"
PATTERNS = ROOT / "data" / "patterns"
# A sequence with `within`, a step with a behaviour, a step `for at least` then another: one of each kind.
TEMPORAL = ("cut-in-from-right.dsl", "vehicle-braking-ahead.dsl", "stopped-vehicle-starts-moving.dsl")
EVENTS_OF = "queue-of-three.dsl"  # a one-frame pattern (three names), grouped into events
TARGET_S, TARGET_MB = 60.0, 4096
MEMORY_MB = 3072  # DuckDB's limit for the 10^6-frame queries (it spills beyond): the machine is shared


def load() -> str:
    return " / ".join(f"{v:.2f}" for v in os.getloadavg())


def replicate(n_frames: int, out: Path, parts: int) -> tuple[int, int]:
    """n_frames frames: copies of the log, each a scene of its own; returns (copies, rows)."""
    import duckdb

    con = duckdb.connect(config={"threads": os.cpu_count() or 1})
    con.execute("SET enable_progress_bar = false")
    con.execute(f"CREATE TEMP TABLE base AS SELECT * , file_row_number AS rn FROM read_parquet('{LOG}', "
                "file_row_number = true)")
    per = con.execute("SELECT count(DISTINCT frame_id) FROM base").fetchall()[0][0]
    copies = n_frames // per
    cols = ("source, frame_index, timestamp_us, entity_id, track_id, type, category, x, y, heading, length, width, "
            "is_ego, speed")
    out.mkdir(parents=True, exist_ok=True)
    for p in range(parts):
        lo, hi = copies * p // parts, copies * (p + 1) // parts
        con.execute(
            f"COPY (SELECT scene || '~' || r || '/' || frame_index AS frame_id, scene || '~' || r AS scene, {cols} "
            f"FROM range({lo}, {hi}) t(r), base ORDER BY r, rn) "
            f"TO '{out / f'part-{p:03d}.parquet'}' (FORMAT parquet, COMPRESSION zstd, ROW_GROUP_SIZE 122880)")
    rows = con.execute(f"SELECT count(*) FROM read_parquet('{out}/*.parquet')").fetchall()[0][0]
    con.close()
    return copies, int(rows)


def one(frames: str, pattern: str, events: bool, memory_mb: int | None) -> None:
    """Child process: one query; prints its summary and peak RSS as JSON."""
    from pipeline.query.mining import query_frames
    from synth.patterns.temporal import parse_query_pattern

    with tempfile.TemporaryDirectory(prefix="r2s-bench-temporal-out-") as tmp:
        s = query_frames(frames, parse_query_pattern(Path(pattern).read_text()), Path(tmp) / "out.parquet",
                         events=events, memory_limit_mb=memory_mb, log=lambda m: None)
    rss = peak_rss_mb()
    print(json.dumps({"frames": s.frames_scanned, "matched": s.frames_matched, "events": s.events,
                      "query_s": s.seconds, "peak_rss_mb": rss}))


def run_query(frames: Path, pattern: str, events: bool, memory_mb: int | None = None) -> dict:
    cmd = [sys.executable, str(Path(__file__).resolve()), "--one", str(frames), str(PATTERNS / pattern)]
    cmd += ["--events"] if events else []
    cmd += ["--memory-limit", str(memory_mb)] if memory_mb else []
    rec = run_child("bench_temporal", cmd, ROOT)
    wall = rec["wall_s"]
    rec.update(pattern=pattern, output="events" if events else "matches", memory_limit_mb=memory_mb)
    found = rec["events"] if events else rec["matched"]
    print(f"  {pattern} ({rec['output']}) on {rec['frames']:,} frames: {wall:.1f} s wall, {found:,} "
          f"{rec['output'] if events else 'frames matched'}, peak RSS {rec['peak_rss_mb']:.0f} MB", flush=True)
    return rec


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--frames", type=int, default=1_000_000, help="frames to replicate to (default 1,000,000)")
    ap.add_argument("--one", nargs=2, metavar=("FRAMES", "PATTERN"), help=argparse.SUPPRESS)
    ap.add_argument("--events", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--memory-limit", type=int, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.one:
        one(*args.one, args.events, args.memory_limit)
        return 0
    load_before = load()
    print(f"bench_temporal: load average {load_before}", flush=True)
    jobs = [(p, True) for p in TEMPORAL] + [(TEMPORAL[0], False), (EVENTS_OF, True)]
    single = {(p, e): run_query(LOG, p, e) for p, e in jobs}  # the log alone: the counts to scale
    runs = []
    with tempfile.TemporaryDirectory(prefix="r2s-bench-temporal-") as tmp:
        frames = Path(tmp) / "frames"
        t = time.perf_counter()
        copies, rows = replicate(args.frames, frames, parts=10)
        n = copies * single[jobs[0]]["frames"]
        print(f"{n:,} frames ({copies:,} copies of the log), {rows:,} rows ({time.perf_counter() - t:.0f} s to write)",
              flush=True)
        for p, e in jobs:
            rec = run_query(frames, p, e, MEMORY_MB)
            key = "events" if e else "matched"
            rec["scales"] = rec[key] == copies * single[(p, e)][key]
            runs.append({"n_frames": n, "rows": rows, "copies": copies, **rec})
    payload = {"machine": machine(), "load_before": load_before, "load_after": load(), "target_s": TARGET_S,
               "target_mb": TARGET_MB, "runs": runs,
               "single_log": [{"pattern": p, "output": "events" if e else "matches", **r} for (p, e), r in single.items()]}
    write_results("temporal", payload, markdown(payload))
    return 0


def markdown(p: dict) -> str:
    m = p["machine"]
    md = [
        "# Temporal patterns and events: `r2s query` over 1,000,000 replicated real frames", "",
        f"Machine: {m['cpu']} ({m['cores']} cores), Python {m['python']}, {m['date']}, commit {m['commit']}. "
        f"Load average (1 / 5 / 15 min) before: {p['load_before']}, after: {p['load_after']}.", "",
        "The shipped Argoverse 2 log (156 frames at 10 Hz) replicated as distinct scenes (ten part files); each query "
        "in a fresh process, wall clock including validation of the rows and writing the output; all threads; the "
        f"large queries with `--memory-limit {MEMORY_MB}`. "
        f"Target: under {p['target_s']:.0f} s and {p['target_mb']} MB. `scales`: the count is the copies times the "
        "count on the log alone.", "",
        "| frames | rows | pattern | output | memory limit | wall (s) | found | scales | peak RSS (MB) |",
        "|---:|---:|---|---|---:|---:|---:|---|---:|",
    ]
    for r in p["runs"]:
        found = r["events"] if r["output"] == "events" else r["matched"]
        md.append(f"| {r['n_frames']:,} | {r['rows']:,} | {r['pattern']} | {r['output']} | "
                  f"{str(r['memory_limit_mb']) + ' MB' if r['memory_limit_mb'] else 'default'} | {r['wall_s']:.1f} | "
                  f"{found:,} | {r.get('scales', '')} | {r['peak_rss_mb']:.0f} |")
    md += ["", "Reproduce: `python bench/bench_temporal.py` (about a quarter of an hour on 2 cores).", ""]
    return "\n".join(md)


if __name__ == "__main__":
    sys.exit(main())
