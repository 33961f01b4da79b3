"""dReal beside z3 in the paper's Pure-SMT mode (`--oracle smt`), issue 28. Needs `make dreal`.

Two sweeps, each frame synthesized with `--oracle smt --solver z3` and then `--solver dreal` (same process, one right
after the other, so both see the same machine load; one warm-up frame first, so library loading is not timed):

1. Table 3's frames: the ablation's one real vehicle frame per N = 5..24 (bench_ablation.one_frame_per_n, from
   ../shared/data; the shipped excerpt without it). Per frame: time, solver questions, time per question; for
   dReal its own calls (what dReal decides and measures) apart from z3's (certification, docs/dsl.md).
2. Every shipped keyframe (data/nuscenes-mini-keyframes) with up to 16 entities: the full sweep of which
   tests/synth/test_dreal.py checks a sample: same optimal cost as z3 on every frame, every program certified.

Table 3 of the paper names the monolithic baseline (this repository's `--strategy monolithic`, one z3 Optimize
problem: bench_ablation.py) "Pure-SMT"; dReal has no part in that one (it cannot optimize the joint formula), so
its row here is the paper's solver where the paper uses it: every relation question of the decoupled search.

Writes bench/results/dreal.json and dreal.md.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

from bench_ablation import N_MAX, N_MIN, QUICK_N_MAX, one_frame_per_n  # noqa: E402
from common import machine, write_results  # noqa: E402

from frames.rows import iter_scenes, read_frames  # noqa: E402
from synth.config import SynthConfig  # noqa: E402
from synth.scene import Scene  # noqa: E402
from synth.smt import SolverUnavailable  # noqa: E402
from synth.smt.dreal_backend import load_dreal  # noqa: E402
from synth.synthesize import synthesize  # noqa: E402

KEYFRAMES = ROOT / "data" / "nuscenes-mini-keyframes" / "frames.parquet"
SWEEP_MAX = 16
TIME_LIMIT_S = 120.0


@dataclass
class DrealClock:
    """dReal's own calls and their time, apart from z3's (both count into the backend's stats)."""

    calls: int = 0
    seconds: float = 0.0

    def install(self, dreal) -> None:
        real = dreal.CheckSatisfiability

        def timed(formula, delta):
            started = time.perf_counter()
            try:
                return real(formula, delta)
            finally:
                self.calls += 1
                self.seconds += time.perf_counter() - started

        dreal.CheckSatisfiability = timed


def measure(scene: Scene, clock: DrealClock) -> dict:
    row = {"frame": scene.frame_id, "n": len(scene.others)}
    for solver in ("z3", "dreal"):
        calls, seconds = clock.calls, clock.seconds
        r = synthesize(scene, SynthConfig(oracle="smt", solver=solver, time_limit=TIME_LIMIT_S))
        s = r.stats
        dreal_calls, dreal_s = clock.calls - calls, clock.seconds - seconds
        row[solver] = {"status": r.status, "cost": r.cost, "certified": r.certified, "runtime_s": s.runtime_s,
                       "smt_s": s.smt_s, "queries": s.smt_queries, "dreal_queries": dreal_calls,
                       "dreal_s": dreal_s, "z3_queries": s.smt_queries - dreal_calls}
    row["agree"] = row["z3"]["status"] == row["dreal"]["status"] == "optimal" and row["z3"]["cost"] == row["dreal"]["cost"]
    return row


def per_query_ms(seconds: float, queries: int) -> float | None:
    return 1000.0 * seconds / queries if queries else None


def _f(v, digits=2) -> str:
    return "–" if v is None else f"{v:.{digits}f}"


def table3_md(rows: list[dict]) -> list[str]:
    md = ["| Task | N | frame | cost z3 | cost dReal | agree | z3: s | z3: queries | z3: ms/query | dReal: s "
          "| dReal: its queries | dReal: ms/query | dReal run: z3 queries (certify) |",
          "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for k, r in enumerate(rows, 1):
        z, d = r["z3"], r["dreal"]
        md.append(f"| Task {k} | {r['n']} | `{r['frame']}` | {z['cost']} | {d['cost']} | {'yes' if r['agree'] else 'NO'} "
                  f"| {z['runtime_s']:.2f} | {z['queries']} | {_f(per_query_ms(z['smt_s'], z['queries']))} "
                  f"| {d['runtime_s']:.2f} | {d['dreal_queries']} | {_f(per_query_ms(d['dreal_s'], d['dreal_queries']))} "
                  f"| {d['z3_queries']} |")
    return md


def sweep_md(rows: list[dict]) -> list[str]:
    by_n = defaultdict(list)
    for r in rows:
        by_n[r["n"]].append(r)
    md = ["| N | frames | same optimum | dReal certified | z3: median s | dReal: median s | z3: ms/query "
          "| dReal: ms per dReal query |", "|---|---|---|---|---|---|---|---|"]
    for n in sorted(by_n):
        rs = by_n[n]
        z_q = sum(r["z3"]["queries"] for r in rs)
        d_q = sum(r["dreal"]["dreal_queries"] for r in rs)
        md.append(f"| {n} | {len(rs)} | {sum(r['agree'] for r in rs)} | {sum(r['dreal']['certified'] for r in rs)} "
                  f"| {statistics.median(r['z3']['runtime_s'] for r in rs):.2f} "
                  f"| {statistics.median(r['dreal']['runtime_s'] for r in rs):.2f} "
                  f"| {_f(per_query_ms(sum(r['z3']['smt_s'] for r in rs), z_q))} "
                  f"| {_f(per_query_ms(sum(r['dreal']['dreal_s'] for r in rs), d_q))} |")
    return md


def totals(rows: list[dict]) -> dict:
    z_q = sum(r["z3"]["queries"] for r in rows)
    d_q = sum(r["dreal"]["dreal_queries"] for r in rows)
    return {"frames": len(rows), "agree": sum(r["agree"] for r in rows),
            "dreal_certified": sum(r["dreal"]["certified"] for r in rows),
            "z3_runtime_s": sum(r["z3"]["runtime_s"] for r in rows),
            "dreal_runtime_s": sum(r["dreal"]["runtime_s"] for r in rows),
            "z3_ms_per_query": per_query_ms(sum(r["z3"]["smt_s"] for r in rows), z_q),
            "dreal_ms_per_dreal_query": per_query_ms(sum(r["dreal"]["dreal_s"] for r in rows), d_q),
            "dreal_queries": d_q, "z3_queries": z_q}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help=f"Table 3's frames up to N = {QUICK_N_MAX} only")
    args = ap.parse_args(argv)
    clock = DrealClock()
    try:
        clock.install(load_dreal())
    except SolverUnavailable as exc:  # not a failure of the bench: `make bench` goes on
        print(f"bench_dreal: skipped: {exc}")
        return 0
    load_before = os.getloadavg()
    frames = one_frame_per_n(range(N_MIN, (QUICK_N_MAX if args.quick else N_MAX) + 1))
    sweep = [s for s in iter_scenes(read_frames(KEYFRAMES)) if len(s.others) <= SWEEP_MAX]
    measure(sweep[0], clock)  # warm-up: imports, z3 and dReal loaded
    t3 = []
    for f in frames:
        t3.append({**measure(f.scene, clock), "source": f.source, "radius": f.radius})
        print(f"table 3 N={f.n}: z3 {t3[-1]['z3']['runtime_s']:.2f} s, dReal {t3[-1]['dreal']['runtime_s']:.2f} s", flush=True)
    sw = []
    for s in sweep:
        sw.append(measure(s, clock))
    load_after = os.getloadavg()
    m = machine()
    t3_tot, sw_tot = totals(t3), totals(sw)
    load = f"load average {load_before[0]:.1f} before, {load_after[0]:.1f} after"
    md = ["# dReal beside z3 in the Pure-SMT mode (`--oracle smt`)", "",
          f"Machine: {m['cpu']} ({m['cores']} cores), Python {m['python']}, {m['date']}, commit {m['commit']}, {load}. "
          f"{m['note']}.", "",
          "Each frame is synthesized with `--oracle smt --solver z3`, then `--solver dreal` (dReal 4.21.6.2 from "
          "`make dreal`, δ = 0.001), in one process, one right after the other. Time = the synthesizer's `runtime_s`; "
          "queries = solver questions (`smt_queries`); ms/query = solver seconds per question. In a dReal run dReal "
          "answers every relation question and measures every distance, z3 certifies the program (docs/dsl.md): "
          "dReal's own questions and time are counted apart. Table 3 of the paper calls its monolithic baseline "
          "Pure-SMT; here that is `--strategy monolithic` (one z3 Optimize problem, [ablation.md](ablation.md)), which "
          "dReal cannot run; this row is the paper's solver in the paper's decoupled search.", "",
          f"## Table 3's frames (one real vehicle frame per N, {frames[0].source if frames else '–'})", "",
          f"Same optimum on **{t3_tot['agree']} of {t3_tot['frames']}** frames; dReal programs certified: "
          f"{t3_tot['dreal_certified']}. Total time z3 {t3_tot['z3_runtime_s']:.1f} s, dReal "
          f"{t3_tot['dreal_runtime_s']:.1f} s; z3 {_f(t3_tot['z3_ms_per_query'], 3)} ms per question, dReal "
          f"{_f(t3_tot['dreal_ms_per_dreal_query'], 3)} ms per question of its own.", ""] + table3_md(t3) + [
          "", f"## Every shipped keyframe with up to {SWEEP_MAX} entities (data/nuscenes-mini-keyframes, all categories)",
          "", f"Same optimum on **{sw_tot['agree']} of {sw_tot['frames']}** frames; dReal programs certified: "
          f"**{sw_tot['dreal_certified']} of {sw_tot['frames']}**. Total time z3 {sw_tot['z3_runtime_s']:.1f} s, dReal "
          f"{sw_tot['dreal_runtime_s']:.1f} s; z3 {_f(sw_tot['z3_ms_per_query'], 3)} ms per question, dReal "
          f"{_f(sw_tot['dreal_ms_per_dreal_query'], 3)} ms per question of its own "
          f"({sw_tot['dreal_queries']:,} dReal questions).", ""] + sweep_md(sw)
    write_results("dreal", {"machine": m, "load_before": load_before, "load_after": load_after,
                            "table3": t3, "table3_totals": t3_tot, "sweep": sw, "sweep_totals": sw_tot},
                  "\n".join(md) + "\n")
    return 0 if t3_tot["agree"] == t3_tot["frames"] and sw_tot["agree"] == sw_tot["frames"] else 1


if __name__ == "__main__":
    sys.exit(main())
