"""What `r2s export` costs per variant, and that its memory does not grow with the number of variants (issue 27).

One recorded frame with its road and world pose (scene-0103/0 of the shipped ScenarioNet excerpt: 21 entities, 17
map features within 50 m), 5 variants sampled from its motion program, copied to N variant files (N in --sizes,
default 1,000 and 10,000), exported with `r2s export --to scenarionet` and `--to openscenario` (the default one
step per scenario) in a fresh interpreter each: its CPU seconds (the machine is shared: wall time measures the
others' load too, which is recorded), wall seconds, peak resident memory (VmHWM) and the output's size. Writes
bench/results/export.json and export.md.

    .venv/bin/python bench/bench_export.py [--sizes 1000,10000]
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

from common import R2S_CHILD, machine, run_child, write_results  # noqa: E402


def r2s(*args: str, cwd: Path) -> None:
    proc = subprocess.run([sys.executable, "-m", "pipeline.cli", *args], capture_output=True, text=True, cwd=cwd)
    if proc.returncode != 0:
        raise SystemExit(f"r2s {' '.join(args)} failed: {proc.stderr.strip()}")


def inputs(work: Path) -> tuple[Path, list[Path]]:
    r2s("extract", "scenarionet", str(ROOT / "data/nuscenes-mini-excerpt/scenarionet"), "--out", "excerpt", cwd=work)
    r2s("scene", "excerpt", "scene-0103/0", "--out", "scene.json", cwd=work)
    r2s("synth", "scene.json", "--motion", "--format", "scenic", "--out", "scene.scenic", cwd=work)
    r2s("sample", "scene.scenic", "--n", "5", "--seed", "0", "--out", "variants", cwd=work)
    return work / "scene.json", sorted((work / "variants").glob("*.json"))


def size_mb(path: Path) -> float:
    return sum(f.stat().st_size for f in path.iterdir()) / 2**20


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="1000,10000")
    args = ap.parse_args()
    sizes = [int(s) for s in args.sizes.split(",")]
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench-export-") as tmp:
        work = Path(tmp)
        scene, samples = inputs(work)
        for n in sizes:
            folder = work / f"variants-{n}"
            folder.mkdir()
            for k in range(n):
                shutil.copyfile(samples[k % len(samples)], folder / f"sample_{k:06d}.json")
            for to in ("scenarionet", "openscenario"):
                out = work / f"out-{to}-{n}"
                load = os.getloadavg()[0]
                rec = run_child("bench_export.py", [sys.executable, "-c", R2S_CHILD, "export", str(scene), str(folder),
                                                   "--to", to, "--out", str(out)], ROOT)
                rows.append({"target": to, "variants": n, "scenarios": n + 1, **rec, "load": load,
                             "cpu_ms_per_scenario": 1e3 * rec["cpu_s"] / (n + 1),
                             "wall_ms_per_scenario": 1e3 * rec["wall_s"] / (n + 1), "output_mb": size_mb(out)})
                print(rows[-1], flush=True)
                shutil.rmtree(out)
            shutil.rmtree(folder)
    info = machine()
    write_results("export", {"machine": info, "rows": rows}, markdown(info, rows))


def markdown(info: dict, rows: list[dict]) -> str:
    lines = ["# r2s export: time per variant and memory", "",
             f"Machine: {info['cpu']}, {info['cores']} cores, Python {info['python']}; commit {info['commit']}, "
             f"{info['date']}. {info['note']}.", "",
             "One recorded frame (scene-0103/0 of the shipped ScenarioNet excerpt: 21 entities, its road and world "
             "pose) and N variant files (5 sampled variants, copied), exported in a fresh interpreter: "
             "`.venv/bin/python bench/bench_export.py`. CPU and wall milliseconds per scenario (N + 1: the frame "
             "too), the process's peak resident memory, the output's size, the 1-minute load when it started.", "",
             "| target | variants | CPU ms / scenario | wall ms / scenario | peak RSS MB | output MB | load |",
             "|---|---|---|---|---|---|---|"]
    lines += [f"| {r['target']} | {r['variants']:,} | {r['cpu_ms_per_scenario']:.2f} | {r['wall_ms_per_scenario']:.2f} "
              f"| {r['peak_rss_mb']:.0f} | {r['output_mb']:.1f} | {r['load']:.1f} |" for r in rows]
    growth = []
    for to in ("scenarionet", "openscenario"):
        mine = sorted((r for r in rows if r["target"] == to), key=lambda r: r["variants"])
        if len(mine) >= 2:
            a, b = mine[0], mine[-1]
            per = (b["peak_rss_mb"] - a["peak_rss_mb"]) * 2**20 / (b["variants"] - a["variants"])
            growth.append(f"{to} {a['peak_rss_mb']:.0f} -> {b['peak_rss_mb']:.0f} MB from {a['variants']:,} to "
                          f"{b['variants']:,} variants ({per:.0f} bytes a variant)")
    lines += ["", "Memory does not grow with the scenarios: each is built, written and dropped, and the ScenarioNet "
              "summary and mapping are written item by item (pipeline/export/scenarionet.py). What grows is the "
              "list of variant file names and the set of scenario names: " + "; ".join(growth) + "."]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()
