"""Synthesizer core benchmark (issues 2 and 18): time per frame of certified synthesis, before and after, and
`auto`'s speed-up over the paper's BFS-CPA.

1. Before / after (issue 18). Frame sets (bench/workloads.py): all 242 shipped nuScenes-mini keyframes (all
   categories within 50 m), Waymo-like ScenarioNet frames (real nuScenes tracks in the Waymo converter's layout,
   needs ../shared) and dense crowds (tests/support/crowds.py). Each set is synthesized with the default configuration
   (auto, hybrid oracle, z3: certified) by this tree ("after") and by a frozen checkout of the baseline commit
   ("before", `git archive` into a temporary folder), each in its own warmed process (bench/synth_worker.py),
   frame by frame in turn (so both see the same load on a shared machine). Per frame: wall time and its split into relation oracle, search, Alg. 4
   (references and Range values), certification and Scenic rendering; A* nodes and solver queries. Reported:
   median / p95 / max per set and side, frames over 0.5 s, the speed-up, and whether every frame's output (DSL,
   Scenic, JSON without timings, certified) is byte-identical.
2. Where the time goes: a cProfile of each tree on a sample of every set, its own time summed by kind of code.
3. Ratio (skipped by --quick): vehicle-only keyframes, one per N, auto vs bfs-cpa in this process, same oracle,
   equal cost required; bfs-cpa under a time limit (TO when it runs out).
Writes bench/results/synth.json and synth.md, with the machine, commits and the load average seen.
"""

from __future__ import annotations

import argparse
import json
import os
import pstats
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

import workloads  # noqa: E402
from common import machine, write_results  # noqa: E402
from realdata import keyframe_scenes  # noqa: E402

# The last main commit before issue 18's changes (the core as it stood when the issue was filed).
BASELINE = "169f18e"
# Issue 18's steps as they landed on main, each timed as a tree of its own beside before and after (--steps).
STEPS = {
    "parts refactor (i16)": "23888fc",
    "+ interval certification, exact Range values": "4250af5",
    "+ incremental A*, closed-source bound": "c4b629b",
    "+ Alg. 4 nearest witness, centring, rendering": "047684b",
    "+ packed search state": "2887f4e",
}
STAGES = ("oracle_s", "search_s", "ranges_s", "certify_s", "render_s")
STAGE_NAMES = {"oracle_s": "relation oracle", "search_s": "search", "ranges_s": "Alg. 4 + Range values",
               "certify_s": "certification", "render_s": "Scenic rendering"}
SLOW_S = 0.5


def pct(values, q):
    v = sorted(values)
    return v[min(len(v) - 1, int(round(q * (len(v) - 1))))]


def summary(values) -> dict:
    values = list(values)
    return {"median": statistics.median(values), "p95": pct(values, 0.95), "max": max(values),
            "total": sum(values)}


# ------------------------------------------------------------------------------------------ before / after

def frozen_tree(commit: str, into: Path) -> Path:
    """The repository at `commit`, as files (git archive), for the worker to import."""
    tree = into / f"r2sgen-{commit}"
    tree.mkdir()
    archive = subprocess.run(["git", "archive", "--format=tar", commit], cwd=ROOT, capture_output=True, check=True)
    subprocess.run(["tar", "-x", "-C", str(tree)], input=archive.stdout, check=True)
    return tree


def snapshot_tree(into: Path) -> Path:
    """This tree's packages as they are now (edits made while the benchmark runs do not leak into it)."""
    tree = into / "r2sgen-after"
    for pkg in ("synth", "extractors", "pipeline"):
        shutil.copytree(ROOT / pkg, tree / pkg, ignore=shutil.ignore_patterns("__pycache__"))
    return tree


def tree_state() -> str:
    """'' when the working tree matches its commit, else '+ uncommitted changes'."""
    dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=ROOT, capture_output=True,
                           text=True).stdout.strip()
    return " + uncommitted changes" if dirty else ""


class Worker:
    """A synth_worker.py process timing one tree, fed one frame at a time."""

    def __init__(self, code: Path, config: dict, profile: Path | None = None):
        cmd = [sys.executable, str(HERE / "synth_worker.py"), "--code", str(code), "--config", json.dumps(config)]
        if profile is not None:
            cmd += ["--profile", str(profile)]
        self.proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                                     cwd=tempfile.gettempdir())

    def run(self, item: dict) -> dict:
        self.proc.stdin.write(json.dumps(item) + "\n")
        self.proc.stdin.flush()
        line = self.proc.stdout.readline()
        if not line:
            raise RuntimeError(f"synth worker died on {item['scene']['frame_id']} (exit {self.proc.wait()})")
        return json.loads(line)

    def close(self) -> None:
        self.proc.stdin.close()
        if self.proc.wait() != 0:
            raise RuntimeError(f"synth worker exited {self.proc.returncode}")


def run_sides(items: list[dict], trees: dict[str, Path], config: dict,
              profiles: dict[str, Path] | None = None) -> dict[str, list[dict]]:
    """Every frame through one worker per tree, in turn (the order alternating frame by frame), so that both
    trees see the same load on a shared machine."""
    workers = {side: Worker(code, config, (profiles or {}).get(side)) for side, code in trees.items()}
    out: dict[str, list[dict]] = {side: [] for side in trees}
    try:
        for i, item in enumerate(items):
            sides = list(trees) if i % 2 == 0 else list(reversed(trees))
            for side in sides:
                out[side].append(workers[side].run(item))
    finally:
        for w in workers.values():
            w.close()
    return out


def side_summary(rows: list[dict]) -> dict:
    out = {"frames": len(rows), "max_n": max(r["n"] for r in rows), "wall_s": summary(r["wall_s"] for r in rows),
           "over_0_5_s": sum(r["wall_s"] > SLOW_S for r in rows),
           "certified_share": sum(r["certified"] for r in rows) / len(rows),
           "optimal_share": sum(r["status"] == "optimal" for r in rows) / len(rows),
           "nodes_expanded": summary(r["nodes_expanded"] for r in rows),
           "smt_queries": summary(r["smt_queries"] for r in rows)}
    for k in STAGES + ("smt_s",):
        out[k] = summary(r[k] for r in rows)
    return out


ROW_KEYS = ("wall_s",) + STAGES + ("smt_s", "smt_queries", "nodes_expanded")


def frame_rows(sides: dict[str, list[dict]]) -> list[dict]:
    """Per frame: id, N, cost, and each side's time, stages, solver queries and nodes (programs left out)."""
    return [{"frame_id": b["frame_id"], "n": b["n"], "cost": b["cost"],
             **{f"{side}_{k}": r[k] for side, r in (("before", b), ("after", a)) for k in ROW_KEYS}}
            for b, a in zip(sides["before"], sides["after"])]


def compare(before: list[dict], after: list[dict]) -> dict:
    keys = ("frame_id", "status", "cost", "lower_bound", "certified", "program", "scenic_sha256", "json_sha256")
    differ = [b["frame_id"] for b, a in zip(before, after) if any(b[k] != a[k] for k in keys)]
    assert [b["frame_id"] for b in before] == [a["frame_id"] for a in after]
    bw, aw = summary(r["wall_s"] for r in before), summary(r["wall_s"] for r in after)
    return {"identical": len(before) - len(differ), "differ": differ,
            "speedup_median": bw["median"] / aw["median"], "speedup_total": bw["total"] / aw["total"],
            "speedup_max": bw["max"] / aw["max"]}


# ------------------------------------------------------------------------------------------ profile

PROFILE_KINDS = (
    ("z3 solving (check)", lambda f, fn: "/z3/" in f and fn.startswith(("Z3_solver_check", "Z3_optimize_check"))),
    ("z3 formula building (Python API)", lambda f, fn: "/z3/" in f),
    ("search (synth/search)", lambda f, fn: "/synth/search/" in f),
    ("Scenic rendering and collision rule", lambda f, fn: any(m in f for m in ("emit_scenic", "collision_rule",
                                                                                "overlap", "parameters"))),
    ("relation tables (numpy)", lambda f, fn: "numpy" in f or "relations" in f or "tables" in f),
    ("fractions / exact arithmetic", lambda f, fn: "fractions" in f or "geometry" in f),
)


def profile_kinds(path: Path) -> dict:
    """Own time (tottime) of every function, summed by kind of code, in seconds."""
    st = pstats.Stats(str(path))
    out: dict[str, float] = defaultdict(float)
    for (filename, _line, fn), (_cc, _nc, tt, _ct, _callers) in st.stats.items():
        kind = next((k for k, match in PROFILE_KINDS if match(filename, fn)), "other Python")
        out[kind] += tt
    out["total"] = sum(v for k, v in out.items())
    top = sorted(st.stats.items(), key=lambda kv: -kv[1][2])[:12]
    out_top = [{"function": f"{Path(f).name}:{line}({fn})", "tottime_s": v[2], "calls": v[1]}
               for (f, line, fn), v in top]
    return {"kinds": dict(out), "top": out_top}


# ------------------------------------------------------------------------------------------ ratio vs BFS-CPA

def ratio(scenes, limit: float, n_min: int, n_max: int) -> list[dict]:
    from synth.config import SynthConfig
    from synth.synthesize import synthesize

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


# ------------------------------------------------------------------------------------------ report

def ms(v: float) -> str:
    return f"{v * 1e3:,.1f} ms" if v < 10 else f"{v:,.1f} s"


def markdown(payload: dict, args) -> str:
    m = payload["machine"]
    md = ["# Synthesizer core benchmark", "",
          f"Machine: {m['cpu']} ({m['cores']} cores), Python {m['python']}, {m['date']}, commit {m['commit']}; "
          f"load average {payload['load_before'][0]:.2f} at the start, {payload['load_after'][0]:.2f} at the end "
          "(shared machine: compare the two sides of one run, not runs).", "",
          "## Certified synthesis per frame, before and after (issue 18)", "",
          f"Default configuration (strategy auto, oracle hybrid, solver z3: every program certified). **before**: "
          f"commit {payload['baseline']} (frozen checkout); **after**: commit {m['commit']}{payload['tree']}. Each in its "
          "own warmed process, the two fed the same frame in turn; wall time of `synthesize` per frame.", "",
          "| frames | N max | side | median | p95 | max | > 0.5 s | certified | max A* nodes | median solver queries |",
          "|---|---|---|---|---|---|---|---|---|---|"]
    for name, s in payload["sets"].items():
        for side in ("before", "after"):
            x = s[side]
            md.append(f"| {name} ({x['frames']}) | {x['max_n']} | {side} | {ms(x['wall_s']['median'])} | "
                      f"{ms(x['wall_s']['p95'])} | {ms(x['wall_s']['max'])} | {x['over_0_5_s']} | "
                      f"{x['certified_share']:.0%} | {x['nodes_expanded']['max']:,.0f} | "
                      f"{x['smt_queries']['median']:.0f} |")
    md += ["", "| frames | speed-up (median) | speed-up (total time) | speed-up (slowest frame) | byte-identical output |",
           "|---|---|---|---|---|"]
    for name, s in payload["sets"].items():
        c = s["compare"]
        md.append(f"| {name} | {c['speedup_median']:.1f}x | {c['speedup_total']:.1f}x | {c['speedup_max']:.1f}x | "
                  f"{c['identical']} of {s['before']['frames']} |")
    md += ["", "### Where the time goes, stage by stage (median / max per frame)", "",
           "| frames | side | " + " | ".join(STAGE_NAMES[k] for k in STAGES) + " | solver (in the first three) |",
           "|---|---|" + "---|" * (len(STAGES) + 1)]
    for name, s in payload["sets"].items():
        for side in ("before", "after"):
            x = s[side]
            cells = [f"{ms(x[k]['median'])} / {ms(x[k]['max'])}" for k in STAGES + ("smt_s",)]
            md.append(f"| {name} | {side} | " + " | ".join(cells) + " |")
    if any(s.get("steps") for s in payload["sets"].values()):
        md += ["", "### Step by step (each landed step as a tree of its own, all fed the same frames in turn)", "",
               "Median per frame, and the stages a step moved (median).", "",
               "| frames | tree | median | total | relation oracle | search | Alg. 4 + Range values | certification "
               "| Scenic rendering |", "|---|---|---|---|---|---|---|---|---|"]
        for name, s in payload["sets"].items():
            chain = [(f"before ({payload['baseline']})", s["before"])]
            chain += [(f"{label} ({STEPS[label]})", x) for label, x in s.get("steps", {}).items()]
            chain += [(f"after ({m['commit']})", s["after"])]
            for label, x in chain:
                md.append(f"| {name} | {label} | {ms(x['wall_s']['median'])} | {x['wall_s']['total']:.1f} s | "
                          + " | ".join(ms(x[k]["median"]) for k in STAGES) + " |")
    if payload.get("profile"):
        md += ["", "### Profile (cProfile, own time by kind of code, share of the profiled run)", "",
               f"On {payload['profile_frames']} frames (every set, evenly spaced).", "",
               "| kind of code | before | after |", "|---|---|---|"]
        kinds = sorted({k for p in payload["profile"].values() for k in p["kinds"] if k != "total"},
                       key=lambda k: -payload["profile"]["before"]["kinds"].get(k, 0.0))
        for k in kinds:
            cells = []
            for side in ("before", "after"):
                p = payload["profile"][side]["kinds"]
                cells.append(f"{p.get(k, 0.0) / p['total']:.0%} ({p.get(k, 0.0):.2f} s)")
            md.append(f"| {k} | " + " | ".join(cells) + " |")
        tot = [payload["profile"][s]["kinds"]["total"] for s in ("before", "after")]
        md.append(f"| total | {tot[0]:.2f} s | {tot[1]:.2f} s |")
        md += ["", "Heaviest functions before (own time):", ""]
        md += [f"- `{t['function']}`: {t['tottime_s']:.2f} s, {t['calls']:,} calls"
               for t in payload["profile"]["before"]["top"][:8]]
    rt = payload.get("ratio_vs_bfs_cpa")
    if rt:
        md += ["", "## auto vs the paper's BFS-CPA (vehicles only, one frame per N, same process, closed-form oracle)",
               "", "| N | auto search | bfs-cpa search | speed-up | cost |", "|---|---|---|---|---|"]
        for r in rt:
            sp = (f"{r['speedup']:,.0f}x" if "speedup" in r
                  else f">= {r['speedup_at_least']:,.0f}x (TO {args.bfs_limit:.0f} s)")
            md.append(f"| {r['n']} | {r['auto_search_s']*1e3:.2f} ms | {r['bfs_cpa_search_s']:.2f} s "
                      f"({r['bfs_cpa_status']}) | {sp} | {r['auto_cost']} |")
    return "\n".join(md) + "\n"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--baseline", default=BASELINE, help=f"the 'before' commit (default {BASELINE})")
    ap.add_argument("--crowds", type=int, default=32, help="crowd frames (seeds 0..N-1; default 32)")
    ap.add_argument("--waymo-every", type=int, default=10, help="Waymo-like frames: one every K 10 Hz steps")
    ap.add_argument("--profile-every", type=int, default=8, help="profile one frame in K of every set (0: none)")
    ap.add_argument("--bfs-limit", type=float, default=120.0, help="seconds per bfs-cpa frame (default 120)")
    ap.add_argument("--max-n", type=int, default=23, help="largest vehicle count for the ratio (default 23)")
    ap.add_argument("--steps", action="store_true",
                    help="also time the tree after each landed step of issue 18 (STEPS), fed the same frames in turn")
    ap.add_argument("--quick", action="store_true", help="8 crowds, every 40th Waymo-like step, no BFS-CPA ratio")
    args = ap.parse_args()
    if args.quick:
        args.crowds, args.waymo_every = min(args.crowds, 8), max(args.waymo_every, 40)
    t0 = time.time()
    load_before = os.getloadavg()
    sets = {"nuScenes-mini keyframes": workloads.keyframes()}
    waymo = workloads.waymo_like(args.waymo_every)
    if waymo:
        sets["Waymo-like (ScenarioNet)"] = waymo
    else:
        print(f"bench_synth: {workloads.SCENARIONET} not found: no Waymo-like frames (set R2S_SHARED)")
    sets["crowds"] = workloads.crowds(args.crowds)
    payload: dict = {"machine": machine(), "tree": tree_state(), "baseline": args.baseline, "load_before": load_before,
                     "sets": {}}
    with tempfile.TemporaryDirectory(prefix="bench_synth_") as tmp:
        tmp = Path(tmp)
        before_tree = frozen_tree(args.baseline, tmp)
        after_tree = snapshot_tree(tmp)
        steps = {label: frozen_tree(commit, tmp) for label, commit in STEPS.items()} if args.steps else {}
        trees = {"before": before_tree, **steps, "after": after_tree}
        sample = []
        for name, scenes in sets.items():
            items = [{"set": name, "scene": sc} for sc in scenes]
            if args.profile_every:
                sample += items[::args.profile_every]
            t = time.time()
            sides = run_sides(items, trees, {})
            print(f"{name}: {len(items)} frames, both sides, in {time.time() - t:.1f} s", flush=True)
            payload["sets"][name] = {"before": side_summary(sides["before"]), "after": side_summary(sides["after"]),
                                     "compare": compare(sides["before"], sides["after"]), "frames": frame_rows(sides),
                                     "steps": {label: side_summary(sides[label]) for label in steps}}
            c = payload["sets"][name]["compare"]
            print(f"{name}: median x{c['speedup_median']:.1f}, total x{c['speedup_total']:.1f}, "
                  f"identical {c['identical']}/{len(items)}", flush=True)
        if sample:
            payload["profile_frames"] = len(sample)
            ends = {"before": before_tree, "after": after_tree}
            profiles = {side: tmp / f"profile-{side}.pstats" for side in ends}
            run_sides(sample, ends, {}, profiles)
            payload["profile"] = {side: profile_kinds(path) for side, path in profiles.items()}
    if not args.quick and workloads.SCENARIONET.is_dir():
        payload["ratio_vs_bfs_cpa"] = ratio(keyframe_scenes(vehicles_only=True), args.bfs_limit, 5, args.max_n)
    payload["load_after"] = os.getloadavg()
    payload["wall_s"] = time.time() - t0
    write_results("synth", payload, markdown(payload, args))
    return 0


if __name__ == "__main__":
    sys.exit(main())
