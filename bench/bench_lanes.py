"""Lanes benchmark (issue 24): synthesis with `--lanes` against without, and lane patterns in `r2s query` at scale.

1. Synthesis: every frame of recordings extracted with their maps (the shipped nuScenes excerpt; with
   ../shared/data, its nuScenes-mini ScenarioNet scenes and the Argoverse 2 test log), each as the scene `r2s scene`
   writes (its road within 50 m of ego, frames.maps.FrameRoads), synthesized with the default configuration
   and with lanes on, the two in turn in one warmed process: median and slowest wall time of `synthesize`, and
   their ratio (target: with lanes at most 2x).
2. Queries: the Argoverse 2 log extracted with its map (the shared test log, else the shipped nuScenes excerpt)
   replicated under distinct scene ids to --frames frames (default 200,000; the map shared by every copy), each
   shipped lane pattern (data/patterns/lanes) in a fresh process through pipeline.query.mining.query_frames, wall
   clock and peak RSS (target: under 20 s); the matching frames must be the copies times those of the log alone.

Writes bench/results/lanes.json and lanes.md. The machine is shared: the load average is recorded.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(ROOT))

from common import machine, peak_rss_mb, run_child, write_results  # noqa: E402

SHARED = Path("/work/shared/data")
SOURCES = [
    ("nuScenes excerpt (shipped)", "scenarionet", ROOT / "data" / "nuscenes-mini-excerpt" / "scenarionet"),
    ("nuScenes-mini (ScenarioNet)", "scenarionet", SHARED / "nuscenes-mini" / "scenarionet"),
    ("Argoverse 2 test log", "argoverse2",
     SHARED / "argoverse2" / "test_data" / "sensor_dataset_logs" / "adcf7d18-0510-35b0-a2fa-b4cea13a6d76"),
    ("Waymo (12 scenarios, ScenarioNet; every 10th step)", "scenarionet", SHARED / "waymo"),
]
EXTRACT_ARGS = {SOURCES[3][0]: ["--every", "10"]}  # Waymo: 10 Hz, 1,306 frames in all; every 10th keeps 140
PATTERNS = sorted((ROOT / "data" / "patterns" / "lanes").glob("*.dsl"))
SYNTH_TARGET, QUERY_TARGET_S = 2.0, 20.0


def load() -> str:
    return " / ".join(f"{v:.2f}" for v in os.getloadavg())


def extract(source: str, path: Path, out: Path, *extra: str) -> None:
    from pipeline.cli import main as r2s

    code = r2s(["extract", source, str(path), "--categories", "all", "--out", str(out), *extra])
    if code:
        raise SystemExit(f"bench_lanes: r2s extract {source} {path} failed ({code})")


def scenes_of(frames: Path) -> list:
    import pandas as pd

    from frames.maps import FrameRoads, maps_dir
    from frames.rows import frame_to_scene

    roads = FrameRoads(maps_dir(frames))
    out = []
    for _, rows in pd.read_parquet(frames).groupby("frame_id", sort=False):
        road, _ = roads.road(rows)
        out.append(frame_to_scene(rows, road))
    return out


def synthesis(name: str, scenes: list) -> dict:
    from synth import synthesize
    from synth.config import SynthConfig

    plain, lanes = SynthConfig(), SynthConfig(lanes=True)
    synthesize(scenes[0], plain), synthesize(scenes[0], lanes)  # warm: imports, z3
    times: dict[str, list[float]] = {"plain": [], "lanes": []}
    costs: dict[str, list[int]] = {"plain": [], "lanes": []}
    for scene in scenes:
        for key, config in (("plain", plain), ("lanes", lanes)):
            t = time.perf_counter()
            result = synthesize(scene, config)
            times[key].append(time.perf_counter() - t)
            costs[key].append(result.cost)
    rec = {"frames": len(scenes), "max_entities": max(len(s.others) for s in scenes), "name": name}
    for key in times:
        rec[key] = {"median_ms": 1e3 * statistics.median(times[key]), "max_ms": 1e3 * max(times[key]),
                    "total_s": sum(times[key]), "median_cost": statistics.median(costs[key])}
    rec["ratio_median"] = rec["lanes"]["median_ms"] / rec["plain"]["median_ms"]
    rec["ratio_max"] = rec["lanes"]["max_ms"] / rec["plain"]["max_ms"]
    print(f"  {name}: {len(scenes)} frames, median {rec['plain']['median_ms']:.1f} -> {rec['lanes']['median_ms']:.1f} ms "
          f"({rec['ratio_median']:.2f}x), slowest {rec['plain']['max_ms']:.1f} -> {rec['lanes']['max_ms']:.1f} ms "
          f"({rec['ratio_max']:.2f}x)", flush=True)
    return rec


def replicate(log: Path, n_frames: int, out: Path, parts: int) -> tuple[int, int]:
    """n_frames frames: copies of the log's frames (a frames file or dataset), each copy a scene of its own naming
    the same map: every column kept (lane facts, speed, world pose), the maps copied beside them."""
    import duckdb

    from frames.maps import maps_dir

    con = duckdb.connect(config={"threads": os.cpu_count() or 1})
    con.execute("SET enable_progress_bar = false")
    con.execute(f"CREATE TEMP TABLE base AS SELECT *, file_index * 1099511627776 + file_row_number AS rn "
                f"FROM read_parquet('{log if log.is_file() else log / '*.parquet'}', file_row_number = true)")
    per = con.execute("SELECT count(DISTINCT frame_id) FROM base").fetchall()[0][0]
    copies = max(1, n_frames // per)
    cols = [c for (c,) in con.execute("SELECT column_name FROM (DESCRIBE base)").fetchall()
            if c not in ("frame_id", "scene", "rn", "file_index", "file_row_number")]
    out.mkdir(parents=True, exist_ok=True)
    for p in range(parts):
        lo, hi = copies * p // parts, copies * (p + 1) // parts
        con.execute(
            f"COPY (SELECT scene || '~' || r || '/' || frame_index AS frame_id, scene || '~' || r AS scene, "
            f"{', '.join(cols)} FROM range({lo}, {hi}) t(r), base ORDER BY r, rn) "
            f"TO '{out / f'part-{p:03d}.parquet'}' (FORMAT parquet, COMPRESSION zstd, ROW_GROUP_SIZE 122880)")
    rows = con.execute(f"SELECT count(*) FROM read_parquet('{out}/*.parquet')").fetchall()[0][0]
    con.close()
    shutil.copytree(maps_dir(log), maps_dir(out))
    return copies, int(rows)


def one(frames: str, pattern: str) -> None:
    """Child process: one query; prints its summary and peak RSS as JSON."""
    from pipeline.query.mining import query_frames
    from synth.patterns.one_frame import parse_pattern

    with tempfile.TemporaryDirectory(prefix="r2s-bench-lanes-out-") as tmp:
        s = query_frames(frames, parse_pattern(Path(pattern).read_text()), Path(tmp) / "out.parquet",
                         log=lambda m: None)
    print(json.dumps({"frames": s.frames_scanned, "matched": s.frames_matched, "query_s": s.seconds,
                      "peak_rss_mb": peak_rss_mb()}))


def run_query(frames: Path, pattern: Path) -> dict:
    rec = run_child("bench_lanes", [sys.executable, str(Path(__file__).resolve()), "--one", str(frames),
                                    str(pattern)], ROOT)
    rec["pattern"] = pattern.name
    print(f"  {pattern.name} on {rec['frames']:,} frames: {rec['wall_s']:.1f} s wall, {rec['matched']:,} frames "
          f"matched, peak RSS {rec['peak_rss_mb']:.0f} MB", flush=True)
    return rec


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--frames", type=int, default=200_000, help="frames to replicate to (default 200,000)")
    ap.add_argument("--synthesis-only", action="store_true",
                    help="run part 1 only; the query table of bench/results/lanes.json is kept as it was measured")
    ap.add_argument("--queries-only", action="store_true",
                    help="run part 2 only; the synthesis table of bench/results/lanes.json is kept as it was measured")
    ap.add_argument("--only", metavar="TEXT",
                    help="with --synthesis-only: only the recordings whose name holds TEXT (e.g. Waymo); the other "
                         "rows of the synthesis table are kept as they were measured")
    ap.add_argument("--one", nargs=2, metavar=("FRAMES", "PATTERN"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.one:
        one(*args.one)
        return 0
    load_before = load()
    print(f"bench_lanes: load average {load_before}", flush=True)
    synth_runs, query_runs = [], []
    with tempfile.TemporaryDirectory(prefix="r2s-bench-lanes-") as tmp:
        extracted = {}
        for name, source, path in SOURCES:
            if args.queries_only and name != SOURCES[2][0] and (name != SOURCES[0][0] or SOURCES[2][2].exists()):
                continue  # the query log only
            if args.only and args.synthesis_only and args.only not in name:
                continue
            if not path.exists():
                print(f"  {name}: not here ({path}), skipped", flush=True)
                continue
            extracted[name] = Path(tmp) / f"{len(extracted)}-{source}" / "frames"
            extract(source, path, extracted[name], *EXTRACT_ARGS.get(name, ()))
            if not args.queries_only:
                synth_runs.append(synthesis(name, scenes_of(extracted[name])))
        if args.synthesis_only:
            previous = HERE / "results" / "lanes.json"
            payload = json.loads(previous.read_text()) if previous.exists() else {
                "machine": machine(), "load_before": load_before, "load_after": load(), "queries": [],
                "query_target_s": QUERY_TARGET_S, "query_log": ""}
            if args.only:  # the rows not measured now, as they were, each with the run that measured it
                kept = payload.get("synthesis_run") or {k: payload[k] for k in ("machine", "load_before", "load_after")}
                synth_runs = [{"run": kept, **r} for r in payload.get("synthesis", []) if args.only not in r["name"]
                              ] + synth_runs
            payload.update(synth_target=SYNTH_TARGET, synthesis=synth_runs,
                           synthesis_run={"machine": machine(), "load_before": load_before, "load_after": load()})
            write_results("lanes", payload, markdown(payload))
            return 0
        log = extracted.get(SOURCES[2][0]) or extracted[SOURCES[0][0]]
        single = {p.name: run_query(log, p) for p in PATTERNS}
        frames = Path(tmp) / "replicated"
        t = time.perf_counter()
        copies, rows = replicate(log, args.frames, frames, parts=4)
        n = copies * single[PATTERNS[0].name]["frames"]
        print(f"{n:,} frames ({copies:,} copies), {rows:,} rows ({time.perf_counter() - t:.0f} s to write)", flush=True)
        for p in PATTERNS:
            rec = run_query(frames, p)
            rec.update(n_frames=n, rows=rows, copies=copies, scales=rec["matched"] == copies * single[p.name]["matched"])
            query_runs.append(rec)
    payload = {"machine": machine(), "load_before": load_before, "load_after": load(), "synth_target": SYNTH_TARGET,
               "query_target_s": QUERY_TARGET_S, "synthesis": synth_runs, "queries": query_runs,
               "query_log": str(log.parent.name)}
    if args.queries_only:  # the synthesis table as it was measured, with its own provenance
        previous = json.loads((HERE / "results" / "lanes.json").read_text())
        payload.update(synthesis=previous["synthesis"], synthesis_run=previous.get("synthesis_run") or {
            k: previous[k] for k in ("machine", "load_before", "load_after")})
    write_results("lanes", payload, markdown(payload))
    return 0


def markdown(p: dict) -> str:
    md = [
        "# Lanes: synthesis with `--lanes` and lane patterns in `r2s query`", "",
        "## Synthesis per frame, without and with lanes", "",
        provenance(p.get("synthesis_run", p)), "",
        "Every frame as `r2s scene` writes it (its road within 50 m of ego); default configuration (strategy auto, "
        f"oracle hybrid), then with lanes on, in turn in one warmed process. Target: at most {p['synth_target']:.0f}x.",
        "",
        "| frames | N max | median | median with lanes | ratio | slowest | slowest with lanes | ratio | median cost "
        "(without / with) |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in p["synthesis"]:
        md.append(f"| {r['name']} ({r['frames']}) | {r['max_entities']} | {r['plain']['median_ms']:.1f} ms | "
                  f"{r['lanes']['median_ms']:.1f} ms | {r['ratio_median']:.2f}x | {r['plain']['max_ms']:.1f} ms | "
                  f"{r['lanes']['max_ms']:.1f} ms | {r['ratio_max']:.2f}x | {r['plain']['median_cost']:g} / "
                  f"{r['lanes']['median_cost']:g} |")
    earlier = [r for r in p["synthesis"] if "run" in r]
    if earlier:
        md += ["", "Rows measured by an earlier run (`--synthesis-only --only TEXT` measured the others): " + "; ".join(
            f"{r['name']}: {provenance(r['run'])}" for r in earlier)]
    md += ["", "## Lane patterns at scale", "", provenance(p), "",
           "The log with its map replicated as distinct scenes (four part files, one map shared by every copy); each "
           "shipped lane pattern (data/patterns/lanes) in a fresh process, wall clock including the validation of "
           f"the rows, the lane relations of the map and writing the output. Target: under {p['query_target_s']:.0f} "
           "s. `scales`: the matching frames are the copies times those of the log alone.", "",
           "| frames | rows | pattern | wall (s) | frames matched | scales | peak RSS (MB) |",
           "|---:|---:|---|---:|---:|---|---:|"]
    for r in p["queries"]:
        md.append(f"| {r['n_frames']:,} | {r['rows']:,} | {r['pattern']} | {r['wall_s']:.1f} | {r['matched']:,} | "
                  f"{r['scales']} | {r['peak_rss_mb']:.0f} |")
    md += ["", "Reproduce: `python bench/bench_lanes.py` (`--frames N` for another size; `--synthesis-only` for the "
           "first table alone, `--queries-only` for the second).", ""]
    return "\n".join(md)


def provenance(run: dict) -> str:
    """Where and when a table was measured (the two tables may come from different runs: --synthesis-only)."""
    m = run["machine"]
    return (f"Machine: {m['cpu']} ({m['cores']} cores), Python {m['python']}, {m['date']}, commit {m['commit']}. "
            f"Load average (1 / 5 / 15 min) before: {run['load_before']}, after: {run['load_after']} (shared "
            "machine: compare the two sides of one run, not runs).")


if __name__ == "__main__":
    sys.exit(main())
