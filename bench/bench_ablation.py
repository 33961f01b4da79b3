"""Ablation of the search strategies in the layout of the paper's Table 3 (tab:all_tasks), issue 6.

One real nuScenes-mini keyframe per vehicle count N = 5..24 (vehicles only), every strategy, oracles smt and hybrid
(one table each): time and peak memory per configuration, TO / OOM marked.

Each configuration runs in its own process, `python -m pipeline.cli synth SCENE.json --format json ...`, under the
pipeline's own --time-limit / --memory-limit, so one configuration's memory or leaked state never reaches the next.
Backstops the pipeline cannot give itself: a hard kill at T + grace (a z3 call that ignores its timeout) and an RSS
watchdog that kills past the memory limit (z3 allocates outside the search's memory polls).

Once a strategy times out (or runs out of memory) at some N for an oracle, every larger N is marked without running
it: the strategies' costs grow with N, and this keeps the whole bench near an hour on 2 cores.

Checks: every configuration that proves optimality on a frame reports the same cost (both oracles); anytime answers
are no cheaper than that cost and their lower bounds no higher. The ratio auto / bfs-cpa is taken within this run.
Results are appended to bench/results/raw/ablation-*.jsonl as they come, so `--resume` continues a killed run.
Writes bench/results/ablation.json and ablation.md.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterable, Iterator
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

from common import RESULTS, machine, write_results  # noqa: E402
from realdata import VEHICLES, available, keyframe_scenes  # noqa: E402

from synth.scene import Scene, scene_from_dict  # noqa: E402

# The paper's column order (Table 3), then ours.
STRATEGIES = ("monolithic", "dfs", "bfs", "dfs-bnb", "dfs-cpa", "dfs-bnb-cpa", "bfs-cpa", "astar", "astar-cpa", "auto")
PAPER_NAMES = {
    "monolithic": "Pure-SMT", "dfs": "DFS-None", "bfs": "BFS-None", "dfs-bnb": "DFS-B&B", "dfs-cpa": "DFS-CPA",
    "dfs-bnb-cpa": "DFS-B&B-CPA", "bfs-cpa": "BFS-CPA", "astar": "A*", "astar-cpa": "A*+CPA", "auto": "auto (ours)",
}
# The paper's Table 3 (7200 s, 8 GB, its own frames): largest N finished, and where it did not.
PAPER_LARGEST = {
    "monolithic": "none (TO at N ≤ 8, OOM from 9)", "dfs": "11 (TO from 12)", "bfs": "10 (OOM from 11)",
    "dfs-bnb": "22 (TO at 13, 15-19, 21, 23, 24)", "dfs-cpa": "23 (OOM at 24)", "dfs-bnb-cpa": "23 (OOM at 24)",
    "bfs-cpa": "24", "astar": "15 (OOM at 13, 14, 16-24)", "astar-cpa": "23 (OOM at 24)", "auto": "not in the paper",
}
ORACLES = ("smt", "hybrid")
N_MIN, N_MAX, QUICK_N_MAX = 5, 24, 12
# Radius 50 m is what the rest of the benches use; a wider one only fills an N that 50 m does not have.
RADII = (50.0, 60.0, 75.0, 100.0)
SHIPPED = ROOT / "tests" / "data" / "nuscenes_mini_frames.json"
RAW = RESULTS / "raw"
POLL_S = 0.05
# The watchdog is a backstop: the pipeline polls its own memory limit, give it the first chance to stop cleanly.
WATCHDOG = 1.1


@dataclass(frozen=True)
class Frame:
    n: int
    scene: Scene
    radius: float
    source: str  # shared | shipped


@dataclass(frozen=True)
class Limits:
    time_s: float
    memory_mb: float
    grace_s: float
    code: Path = ROOT  # the source tree whose `r2s synth` is measured


# ------------------------------------------------------------------------------------------------ frames

def _real_candidates(vehicles_only: bool) -> Iterator[tuple[Scene, float]]:
    for radius in RADII:
        for s in keyframe_scenes(radius, vehicles_only=vehicles_only):
            # The same keyframe at another radius is another scene: say so in its id.
            yield (s if radius == RADII[0] else replace(s, frame_id=f"{s.frame_id}@{radius:g}m")), radius


def _vehicles(raw: dict) -> dict:
    kept = [e for e in raw["entities"] if e["id"] == "ego" or e["type"] in VEHICLES]
    fid = raw["frame_id"]
    if len(kept) < len(raw["entities"]):
        fid += "#vehicles"
    return {"frame_id": fid, "entities": kept}


def _shipped_candidates(vehicles_only: bool) -> Iterator[tuple[Scene, float]]:
    for raw in json.loads(SHIPPED.read_text()):
        yield scene_from_dict(_vehicles(raw) if vehicles_only else raw), RADII[0]


def one_frame_per_n(n_values: Iterable[int], vehicles_only: bool = True) -> list[Frame]:
    """The first frame (in keyframe order, then by widening radius) with exactly N entities, for each N.

    ../shared/data/nuscenes-mini when present, else the shipped excerpt (which covers fewer N).
    """
    wanted = set(n_values)
    source = "shared" if available() else "shipped"
    candidates = _real_candidates(vehicles_only) if source == "shared" else _shipped_candidates(vehicles_only)
    chosen: dict[int, Frame] = {}
    for scene, radius in candidates:
        n = len(scene.others)
        if n in wanted and n not in chosen:
            chosen[n] = Frame(n, scene, radius, source)
        if len(chosen) == len(wanted):
            break
    return [chosen[n] for n in sorted(chosen)]


# ------------------------------------------------------------------------------------------ one process

def frames_in_fresh_process(n_values: Iterable[int], vehicles_only: bool = True) -> list[Frame]:
    """one_frame_per_n in a spawned interpreter, so pandas never enters this process.

    Why: Linux folds a process's resident size at fork into its child's ru_maxrss across exec, so a child
    started from a 110 MB parent reports at least 110 MB peak. A lean parent keeps the children's figures true.
    """
    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as pool:
        return pool.submit(one_frame_per_n, list(n_values), vehicles_only).result()


def _proc_mb(pid: int) -> tuple[float, float]:
    """(current, peak) resident MB of a live process: VmRSS and VmHWM (the peak since its exec)."""
    try:
        with open(f"/proc/{pid}/status") as f:
            fields = dict(line.split(":", 1) for line in f if line.startswith(("VmRSS:", "VmHWM:")))
        return tuple(int(fields.get(k, "0 kB").split()[0]) / 1024.0 for k in ("VmRSS", "VmHWM"))
    except (OSError, ValueError):
        return 0.0, 0.0


def _watch(proc: subprocess.Popen, limits: Limits) -> tuple[str | None, float, float]:
    """Wait for proc; kill it past T + grace or past the memory limit. Returns (killed_for, wall_s, peak_mb)."""
    started, peak = time.perf_counter(), 0.0
    while proc.poll() is None:
        wall = time.perf_counter() - started
        rss, hwm = _proc_mb(proc.pid)
        peak = max(peak, hwm)
        killed = "timeout" if wall > limits.time_s + limits.grace_s else "memout" if rss > limits.memory_mb * WATCHDOG else None
        if killed:
            proc.kill()
            proc.wait()
            return killed, wall, peak
        time.sleep(POLL_S)
    return None, time.perf_counter() - started, peak


def _outcome(doc: dict, limits: Limits) -> str:
    """ok | TO | OOM. A search stopped at the limit is TO even when its anytime answer proves optimal."""
    if doc["status"] == "memout":
        return "OOM"
    if doc["status"] != "optimal" or doc["stats"]["runtime_s"] >= limits.time_s:
        return "TO"
    return "ok"


def run_config(scene_path: Path, strategy: str, oracle: str, limits: Limits, code: Path = ROOT) -> dict:
    """One configuration in its own `r2s synth` process; the record of what happened.

    `python -m` puts its working directory first on sys.path, so `code` decides which source tree is measured.
    """
    cmd = [sys.executable, "-m", "pipeline.cli", "synth", str(scene_path), "--format", "json", "--strategy", strategy,
           "--oracle", oracle, "--time-limit", f"{limits.time_s:g}", "--memory-limit", f"{limits.memory_mb:g}"]
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        proc = subprocess.Popen(cmd, stdout=out, stderr=err, cwd=code, text=True)
        killed, wall, watched_mb = _watch(proc, limits)
        out.seek(0)
        err.seek(0)
        stdout, stderr = out.read(), err.read()
    rec = {"strategy": strategy, "oracle": oracle, "wall_s": wall, "exit": proc.returncode, "killed": killed,
           "watched_peak_mb": watched_mb}
    if killed:
        return rec | {"outcome": "TO" if killed == "timeout" else "OOM", "peak_rss_mb": watched_mb}
    if proc.returncode != 0 or not stdout.strip():
        return rec | {"outcome": "ERR", "error": (stderr.strip().splitlines() or ["no output"])[-1]}
    doc = json.loads(stdout)
    st = doc["stats"]
    return rec | {"outcome": _outcome(doc, limits), "status": doc["status"], "cost": doc["cost"],
                  "lower_bound": doc["lower_bound"], "runtime_s": st["runtime_s"], "search_s": st["search_s"],
                  "smt_queries": st["smt_queries"], "nodes_expanded": st["nodes_expanded"],
                  "peak_rss_mb": max(st["peak_rss_mb"], watched_mb)}


# ------------------------------------------------------------------------------------------ the sweep

def _raw_path(limits: Limits) -> Path:
    return RAW / f"ablation-t{limits.time_s:g}-m{limits.memory_mb:g}.jsonl"


def _load_raw(path: Path) -> dict[tuple[str, str, str], dict]:
    done = {}
    if path.exists():
        for line in path.read_text().splitlines():
            if line.strip():
                r = json.loads(line)
                done[(r["frame_id"], r["strategy"], r["oracle"])] = r
    return done


def _skip_record(frame: Frame, strategy: str, oracle: str, stopped: dict) -> dict:
    return {"frame_id": frame.scene.frame_id, "n": frame.n, "strategy": strategy, "oracle": oracle,
            "outcome": "skipped", "skipped_after": stopped}


def _run_or_reuse(frame: Frame, strategy: str, oracle: str, limits: Limits, done: dict, raw) -> dict:
    key = (frame.scene.frame_id, strategy, oracle)
    if key in done:
        return done[key]
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "scene.json"
        path.write_text(frame.scene.to_json())
        rec = {"frame_id": frame.scene.frame_id, "n": frame.n} | run_config(path, strategy, oracle, limits, limits.code)
    raw.write(json.dumps(rec) + "\n")
    raw.flush()
    return rec


def _progress(rec: dict) -> None:
    if rec["outcome"] == "skipped":
        return
    t = rec.get("runtime_s", rec["wall_s"])
    print(f"{rec['oracle']:>6} N={rec['n']:2d} {rec['strategy']:>12}: {rec['outcome']:>3} {t:8.2f} s "
          f"{rec.get('peak_rss_mb', 0):7.1f} MB cost {rec.get('cost', '-')}", flush=True)


def sweep(frames: list[Frame], strategies, oracles, limits: Limits, resume: bool) -> list[dict]:
    """Every (oracle, frame, strategy) in order of N, skipping past a strategy's first TO / OOM."""
    RAW.mkdir(parents=True, exist_ok=True)
    path = _raw_path(limits)
    done = _load_raw(path) if resume else {}
    records = []
    with open(path, "a" if resume else "w") as raw:
        for oracle in oracles:
            stopped: dict[str, dict] = {}  # strategy -> {"n", "outcome"} of its first TO / OOM
            for frame in frames:
                for strategy in strategies:
                    if strategy in stopped:
                        records.append(_skip_record(frame, strategy, oracle, stopped[strategy]))
                        continue
                    rec = _run_or_reuse(frame, strategy, oracle, limits, done, raw)
                    _progress(rec)
                    records.append(rec)
                    if rec["outcome"] in ("TO", "OOM"):
                        stopped[strategy] = {"n": frame.n, "outcome": rec["outcome"]}
    return records


# ------------------------------------------------------------------------------------------ the checks

def check_frame(recs: list[dict]) -> dict:
    """Cost agreement of the proved-optimal answers on one frame; anytime answers must respect that cost."""
    proved = sorted({r["cost"] for r in recs if r.get("status") == "optimal"})
    out = {"optimal_costs": proved, "agree": "yes" if len(proved) == 1 else "no" if proved else "n/a"}
    if len(proved) == 1:
        c = proved[0]
        bad = [f"{r['strategy']}/{r['oracle']}: cost {r['cost']} lower bound {r['lower_bound']}"
               for r in recs if "cost" in r and (r["cost"] < c or r["lower_bound"] > c)]
        out["bounds_ok"] = "yes" if not bad else "no: " + "; ".join(bad)
        out["cost"] = c
    return out


def ratio_auto_bfs_cpa(recs: list[dict], oracle: str, limits: Limits) -> dict:
    """auto / bfs-cpa run time on one frame, same run; an upper bound when bfs-cpa did not finish."""
    by = {r["strategy"]: r for r in recs if r["oracle"] == oracle}
    a, b = by.get("auto", {}), by.get("bfs-cpa", {})
    if a.get("outcome") != "ok":
        return {"ratio": None}
    if b.get("outcome") == "ok":
        return {"ratio": a["runtime_s"] / b["runtime_s"], "search_ratio": a["search_s"] / max(b["search_s"], 1e-9)}
    if b.get("outcome") in ("TO", "skipped"):
        return {"ratio_at_most": a["runtime_s"] / limits.time_s}
    return {"ratio": None}


def summarize(frames: list[Frame], records: list[dict], oracles, limits: Limits) -> list[dict]:
    rows = []
    for f in frames:
        recs = [r for r in records if r["frame_id"] == f.scene.frame_id]
        row = {"n": f.n, "frame_id": f.scene.frame_id, "radius_m": f.radius, **check_frame(recs),
               "auto_over_bfs_cpa": {o: ratio_auto_bfs_cpa(recs, o, limits) for o in oracles}}
        rows.append(row)
    return rows


# ------------------------------------------------------------------------------------------ markdown

def _cell(r: dict) -> tuple[str, str]:
    """(time, memory) cells in the paper's style: TO keeps its memory, OOM keeps its time."""
    o = r["outcome"]
    if o == "skipped":
        return f"{r['skipped_after']['outcome']}*", "–"
    mem = f"{r['peak_rss_mb']:.1f}" if "peak_rss_mb" in r else "–"
    t = f"{r.get('runtime_s', r['wall_s']):.2f}"
    return {"ok": (t, mem), "TO": ("TO", mem), "OOM": (t, "OOM")}.get(o, ("ERR", "ERR"))


def _ratio_text(d: dict) -> str:
    if d.get("ratio") is not None:
        return f"{d['ratio']:.3g}"
    if "ratio_at_most" in d:
        return f"≤ {d['ratio_at_most']:.3g}"
    return "–"


def oracle_table(oracle: str, rows: list[dict], records: list[dict], strategies) -> list[str]:
    head = ["Task", "N", "frame", "cost", "agree"] + [f"{PAPER_NAMES[s]} {u}" for s in strategies for u in ("s", "MB")]
    md = [_md_row(head), "|" + "---|" * len(head)]
    for row in rows:
        # Task k has N = k + 4 in the paper; keep that pairing even when a frame for some N is missing.
        cells = [f"Task {row['n'] - N_MIN + 1}", str(row["n"]), f"`{row['frame_id']}`", str(row.get("cost", "–")),
                 row["agree"]]
        by = {r["strategy"]: r for r in records if r["frame_id"] == row["frame_id"] and r["oracle"] == oracle}
        for s in strategies:
            cells.extend(_cell(by[s]) if s in by else ("–", "–"))
        md.append(_md_row(cells))
    return md


def _md_row(cells: list[str]) -> str:
    return "| " + " | ".join(cells) + " |"


def ratio_table(rows: list[dict], oracles) -> list[str]:
    """auto / BFS-CPA per N: total run time and search time, per oracle."""
    head = ["N"] + [f"{o}: {k}" for o in oracles for k in ("run time", "search")]
    md = [_md_row(head), "|" + "---|" * len(head)]
    for row in rows:
        cells = [str(row["n"])]
        for o in oracles:
            d = row["auto_over_bfs_cpa"][o]
            cells += [_ratio_text(d), f"{d['search_ratio']:.3g}" if "search_ratio" in d else "–"]
        md.append(_md_row(cells))
    return md


def _skips_legend(records: list[dict], oracle: str) -> str:
    firsts = {}
    for r in records:
        if r["oracle"] == oracle and r["outcome"] == "skipped":
            firsts.setdefault(r["strategy"], r["skipped_after"])
    if not firsts:
        return "No configuration was skipped."
    parts = [f"{PAPER_NAMES[s]} after {v['outcome']} at N={v['n']}" for s, v in firsts.items()]
    return "Skipped: " + "; ".join(parts) + "."


SKIP_CAVEAT = ("Larger N are not run after a strategy's first stop, so a later success (as the paper's DFS-B&B "
               "at N = 14, 20, 22) cannot show here.")


def _largest_finished(records: list[dict], strategy: str, oracle: str) -> str:
    mine = [r for r in records if r["strategy"] == strategy and r["oracle"] == oracle]
    ok = [r["n"] for r in mine if r["outcome"] == "ok"]
    failed = [r for r in mine if r["outcome"] in ("TO", "OOM", "ERR")]
    return (str(max(ok)) if ok else "none") + (f" ({failed[0]['outcome']} at {failed[0]['n']})" if failed else "")


def largest_table(records: list[dict], strategies, oracles) -> list[str]:
    """Per strategy: the largest N it finished here, per oracle, beside the paper's."""
    md = [_md_row(["strategy"] + [f"here, oracle {o}" for o in oracles] + ["paper (Table 3)"]),
          "|" + "---|" * (len(oracles) + 2)]
    for s in strategies:
        md.append(_md_row([PAPER_NAMES[s]] + [_largest_finished(records, s, o) for o in oracles] + [PAPER_LARGEST[s]]))
    return md


def markdown(payload: dict, records: list[dict], strategies) -> str:
    m, lim = payload["machine"], payload["limits"]
    md = ["# Ablation of search strategies (layout of the paper's Table 3, tab:all_tasks)", "",
          f"Machine: {m['cpu']} ({m['cores']} cores), Python {m['python']}, {m['date']}, commit {m['commit']}. "
          f"{m['note']}.", "",
          f"Frames: {payload['frames_note']}. Limits per configuration: {lim['time_s']:g} s "
          f"(hard kill at {lim['time_s'] + lim['grace_s']:g} s) and {lim['memory_mb']:g} MB resident "
          f"(the paper: 7200 s and 8 GB). Each configuration runs alone in its own `r2s synth` process, one at a time. "
          f"Code measured: {payload['code']}.",
          "", "Legend: time = the synthesizer's run time inside its process (s; process start-up excluded), "
          "MB = peak resident memory. TO = did not finish within the time limit (its memory is shown); "
          "OOM = passed the memory limit (the time it took is shown). "
          "TO\\* / OOM\\* = not run: TO (skipped after TO at N=k) — once a strategy times out or runs out of memory at "
          "N=k, every larger N of that strategy and oracle is marked without running it. cost = the optimal cost "
          "every finished configuration reports; agree = all proved-optimal answers on the frame (both oracles) "
          "have that cost.", "", f"Largest N finished (and where a strategy first stopped). {SKIP_CAVEAT}", ""]
    md += largest_table(records, strategies, payload["oracles"]) + [""]
    for oracle in payload["oracles"]:
        md += [f"## Oracle `{oracle}`", "", _skips_legend(records, oracle), ""]
        md += oracle_table(oracle, payload["rows"], records, strategies) + [""]
    if "auto" in strategies and "bfs-cpa" in strategies:
        md += ["## auto / BFS-CPA, same run", "", "Ratio of auto's time to BFS-CPA's on the same frame (below 1: auto is "
               "faster). Run time is the whole synthesis (auto builds the full relation table first); search is the "
               "order search alone. ≤: BFS-CPA did not finish, so the ratio is at most auto / limit.", ""]
        md += ratio_table(payload["rows"], payload["oracles"]) + [""]
    md += [f"Cost agreement over all frames: **{payload['agree']}**. Wall time of the configurations run: "
           f"{payload['configs_wall_s'] / 60:.1f} min.", ""]
    return "\n".join(md)


# ------------------------------------------------------------------------------------------ main

def frames_note(frames: list[Frame], vehicles_only: bool = True) -> str:
    """Where the frames come from and how each N was picked, for the tables' headers."""
    if not frames:
        return "none"
    wide = [f"N={f.n} at {f.radius:g} m" for f in frames if f.radius != RADII[0]]
    src = ("nuScenes v1.0-mini keyframes (../shared/data/nuscenes-mini/keyframes.csv)" if frames[0].source == "shared"
           else "the shipped nuScenes-mini excerpt (tests/data/nuscenes_mini_frames.json)")
    what = "vehicles" if vehicles_only else "entities of any category"
    note = f"{src}, the first keyframe with exactly N {what} within {RADII[0]:g} m of ego"
    return note + (f" ({', '.join(wide)}: no keyframe has that N within {RADII[0]:g} m)" if wide else "")


def _limits_dict(limits: Limits) -> dict:
    return {"time_s": limits.time_s, "memory_mb": limits.memory_mb, "grace_s": limits.grace_s}


def _code_note(code: Path) -> str:
    """Which code was measured: this checkout (possibly with uncommitted edits) or a snapshot of a commit."""
    if code == ROOT:
        dirty = subprocess.run(["git", "status", "--porcelain", "--", "synth", "pipeline"], capture_output=True,
                               text=True, cwd=ROOT).stdout.strip()
        return "this checkout" + (" (with uncommitted edits in synth/ or pipeline/)" if dirty else "")
    stamp = code / "COMMIT"
    return f"snapshot {code}" + (f" of commit {stamp.read_text().strip()}" if stamp.exists() else "")


def parse_args(argv=None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--time-limit", type=float, help="seconds per configuration (default 120; --quick 10)")
    ap.add_argument("--memory-limit", type=float, default=4096.0, help="MB resident per configuration (default 4096)")
    ap.add_argument("--grace", type=float, default=30.0, help="seconds past the time limit before a hard kill")
    ap.add_argument("--quick", action="store_true", help=f"development: N <= {QUICK_N_MAX}, 10 s")
    ap.add_argument("--max-n", type=int, help=f"largest N (default {N_MAX})")
    ap.add_argument("--strategies", default=",".join(STRATEGIES), help="comma-separated subset")
    ap.add_argument("--oracles", default=",".join(ORACLES), help="comma-separated subset (default smt,hybrid)")
    ap.add_argument("--resume", action="store_true", help="reuse the raw records of an interrupted run")
    ap.add_argument("--code", type=Path, default=ROOT, help="source tree to measure (default: this checkout); e.g. "
                    "`git archive HEAD | tar -x -C DIR`, so edits in a shared checkout cannot change a long run")
    args = ap.parse_args(argv)
    args.time_limit = args.time_limit or (10.0 if args.quick else 120.0)
    args.max_n = args.max_n or (QUICK_N_MAX if args.quick else N_MAX)
    args.strategies = [s for s in STRATEGIES if s in args.strategies.split(",")]
    args.oracles = [o for o in ORACLES if o in args.oracles.split(",")]
    return args


def main(argv=None) -> int:
    args = parse_args(argv)
    limits = Limits(args.time_limit, args.memory_limit, args.grace, args.code.resolve())
    frames = frames_in_fresh_process(range(N_MIN, args.max_n + 1), vehicles_only=True)
    started = time.time()
    records = sweep(frames, args.strategies, args.oracles, limits, args.resume)
    rows = summarize(frames, records, args.oracles, limits)
    bad = [r for r in rows if r["agree"] == "no" or not r.get("bounds_ok", "yes").startswith("yes")]
    payload = {"machine": machine(), "code": _code_note(limits.code), "limits": _limits_dict(limits), "quick": args.quick, "oracles": args.oracles,
               "strategies": args.strategies, "frames_note": frames_note(frames),
               "agree": "yes" if not bad else "NO", "rows": rows, "records": records,
               "wall_s": time.time() - started,
               # Summed per configuration, so a resumed run still reports what the whole bench cost.
               "configs_wall_s": sum(r.get("wall_s", 0.0) for r in records)}
    # Development runs stay out of the committed results (raw/ is gitignored).
    write_results("raw/ablation-quick" if args.quick else "ablation", payload, markdown(payload, records, args.strategies))
    for r in bad:  # keep the measurements, then fail loudly: a strategy disagreeing on cost is a bug
        print(f"bench_ablation: DISAGREEMENT on {r['frame_id']}: {r}", file=sys.stderr)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
