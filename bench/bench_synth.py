"""Synthesizer core benchmark (issue 2): `auto` on every real keyframe, and its speed-up over the paper's BFS-CPA.

1. Scale: every nuScenes-mini keyframe, all categories within 50 m (up to 141 entities), strategy auto, oracle
   hybrid (the default): proved-optimal share, search / total time, SMT queries and seconds per frame, memory.
2. Ratio: vehicle-only keyframes, one per N, auto vs bfs-cpa in this same process, same oracle, equal cost
   required; bfs-cpa under a time limit (TO when it runs out).
Writes bench/results/synth.json and synth.md.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from collections import defaultdict

sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parent))

from common import machine, write_results  # noqa: E402
from realdata import available, keyframe_scenes  # noqa: E402

from synth.config import SynthConfig  # noqa: E402
from synth.search.budget import peak_rss_mb  # noqa: E402
from synth.synthesize import synthesize  # noqa: E402


def pct(values, q):
    v = sorted(values)
    return v[min(len(v) - 1, int(round(q * (len(v) - 1))))]


def scale(scenes) -> dict:
    rows = []
    for s in scenes:
        r = synthesize(s)
        rows.append({"frame_id": s.frame_id, "n": r.n_entities, "status": r.status, "cost": r.cost,
                     "lower_bound": r.lower_bound, "search_s": r.stats.search_s, "runtime_s": r.stats.runtime_s,
                     "smt_queries": r.stats.smt_queries, "smt_s": r.stats.smt_s, "certified": r.certified})
    search = [r["search_s"] for r in rows]
    n_total = sum(r["n"] for r in rows)
    return {
        "frames": len(rows),
        "max_entities": max(r["n"] for r in rows),
        "optimal_share": sum(r["status"] == "optimal" for r in rows) / len(rows),
        "certified_share": sum(r["certified"] for r in rows) / len(rows),
        "search_s": {"median": statistics.median(search), "p95": pct(search, 0.95), "max": max(search)},
        "runtime_s": {"median": statistics.median(r["runtime_s"] for r in rows),
                      "max": max(r["runtime_s"] for r in rows), "total": sum(r["runtime_s"] for r in rows)},
        "smt_queries_per_entity": sum(r["smt_queries"] for r in rows) / n_total,
        "smt_queries_per_entity_range": [min(r["smt_queries"] / r["n"] for r in rows if r["n"]),
                                         max(r["smt_queries"] / r["n"] for r in rows if r["n"])],
        "smt_s_per_frame": {"median": statistics.median(r["smt_s"] for r in rows), "max": max(r["smt_s"] for r in rows)},
        "peak_rss_mb": peak_rss_mb(),
        "rows": rows,
    }


def ratio(scenes, limit: float, n_min: int, n_max: int) -> list[dict]:
    by_n = defaultdict(list)
    for s in scenes:
        by_n[len(s.others)].append(s)
    out = []
    for n in sorted(k for k in by_n if n_min <= k <= n_max):
        s = by_n[n][0]
        cfg = SynthConfig(oracle="closed-form")
        a = synthesize(s, cfg)
        b = synthesize(s, cfg.with_(strategy="bfs-cpa", time_limit=limit))
        row = {"n": n, "frame_id": s.frame_id, "auto_search_s": a.stats.search_s, "auto_cost": a.cost,
               "bfs_cpa_search_s": b.stats.search_s, "bfs_cpa_status": b.status, "bfs_cpa_cost": b.cost}
        if b.status == "optimal":
            assert a.cost == b.cost, (s.frame_id, a.cost, b.cost)
            row["speedup"] = b.stats.search_s / max(a.stats.search_s, 1e-9)
        else:
            row["speedup_at_least"] = limit / max(a.stats.search_s, 1e-9)
        out.append(row)
        print(f"N={n:3d} auto {a.stats.search_s*1e3:8.2f} ms  bfs-cpa {b.stats.search_s:8.2f} s ({b.status})  "
              f"x{row.get('speedup', row.get('speedup_at_least', 0)):,.0f}", flush=True)
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--bfs-limit", type=float, default=120.0, help="seconds per bfs-cpa frame (default 120)")
    ap.add_argument("--max-n", type=int, default=23, help="largest vehicle count for the ratio (default 23)")
    args = ap.parse_args()
    if not available():
        print("bench_synth: ../shared/data/nuscenes-mini not found; nothing to measure (set R2S_SHARED)")
        return 0
    import networkx  # noqa: F401  (warm the lazy import so it is not charged to the first frame)

    t = time.time()
    all_scenes = keyframe_scenes()
    sc = scale(all_scenes)
    print(f"scale: {sc['frames']} frames, optimal {sc['optimal_share']:.0%}, median search {sc['search_s']['median']*1e3:.2f} ms, "
          f"max {sc['search_s']['max']*1e3:.1f} ms, peak {sc['peak_rss_mb']:.0f} MB", flush=True)
    rt = ratio(keyframe_scenes(vehicles_only=True), args.bfs_limit, 5, args.max_n)
    payload = {"machine": machine(), "scale": sc, "ratio_vs_bfs_cpa": rt, "wall_s": time.time() - t}
    md = ["# Synthesizer core benchmark", "", f"Machine: {payload['machine']['cpu']} ({payload['machine']['cores']} cores), "
          f"Python {payload['machine']['python']}, {payload['machine']['date']}, commit {payload['machine']['commit']}.", "",
          "## auto on every nuScenes-mini keyframe (all categories within 50 m, hybrid oracle)", "",
          "| frames | max N | proved optimal | certified | median search | p95 search | max search | median total | SMT queries / entity | peak RSS |",
          "|---|---|---|---|---|---|---|---|---|---|",
          f"| {sc['frames']} | {sc['max_entities']} | {sc['optimal_share']:.0%} | {sc['certified_share']:.0%} | "
          f"{sc['search_s']['median']*1e3:.2f} ms | {sc['search_s']['p95']*1e3:.2f} ms | {sc['search_s']['max']*1e3:.1f} ms | "
          f"{sc['runtime_s']['median']*1e3:.0f} ms | {sc['smt_queries_per_entity']:.2f} | {sc['peak_rss_mb']:.0f} MB |", "",
          "## auto vs the paper's BFS-CPA (vehicles only, one frame per N, same process, closed-form oracle)", "",
          "| N | auto search | bfs-cpa search | speed-up | cost |", "|---|---|---|---|---|"]
    for r in rt:
        sp = f"{r['speedup']:,.0f}x" if "speedup" in r else f">= {r['speedup_at_least']:,.0f}x (TO {args.bfs_limit:.0f} s)"
        md.append(f"| {r['n']} | {r['auto_search_s']*1e3:.2f} ms | {r['bfs_cpa_search_s']:.2f} s ({r['bfs_cpa_status']}) | {sp} | {r['auto_cost']} |")
    write_results("synth", payload, "\n".join(md) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
