"""Start-up time of the r2s command and the synth package: `r2s --help`, `r2s VERB --help` and `import synth`.

Each command is a fresh interpreter run from a tree (the repository here, and with --against REV a temporary git
worktree of that commit, run alternately with this one), best of --repeat runs. Wall time follows the machine's
load; CPU time (user + system of the child) much less, so the comparison is made on CPU time.

    python bench/bench_startup.py --against main --repeat 5
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

from common import machine, write_results  # noqa: E402

COMMANDS = {
    "r2s --help": ["-m", "pipeline.cli", "--help"],
    "r2s run --help": ["-m", "pipeline.cli", "run", "--help"],
    "r2s synth --help": ["-m", "pipeline.cli", "synth", "--help"],
    "r2s extract --help": ["-m", "pipeline.cli", "extract", "--help"],
    "r2s sample --help": ["-m", "pipeline.cli", "sample", "--help"],
    "r2s render --help": ["-m", "pipeline.cli", "render", "--help"],
    "r2s eval-frontend --help": ["-m", "pipeline.cli", "eval-frontend", "--help"],
    "import synth": ["-c", "import synth"],
}


def once(tree: Path, args: list[str]) -> tuple[float, float]:
    """(wall s, CPU s) of one fresh interpreter; -m and -c put the tree first on sys.path."""
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, *args], cwd=tree, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    _, status, usage = os.wait4(proc.pid, 0)
    if status:
        raise SystemExit(f"bench_startup: {' '.join(args)} failed in {tree}")
    return time.perf_counter() - t0, usage.ru_utime + usage.ru_stime


def measure(trees: dict[str, Path], repeat: int) -> dict:
    best = {(c, t): (float("inf"), float("inf")) for c in COMMANDS for t in trees}
    for _ in range(repeat):
        for command, args in COMMANDS.items():
            for name, tree in trees.items():
                wall, cpu = once(tree, args)
                w, c = best[(command, name)]
                best[(command, name)] = (min(w, wall), min(c, cpu))
    return {command: {name: {"wall_ms": round(best[(command, name)][0] * 1000, 1),
                             "cpu_ms": round(best[(command, name)][1] * 1000, 1)} for name in trees}
            for command in COMMANDS}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--against", metavar="REV", help="also time this commit (a temporary git worktree), alternately")
    ap.add_argument("--repeat", type=int, default=5, help="runs of each command per tree; the best counts")
    args = ap.parse_args(argv)
    load_before = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="r2s-startup-") as tmp:
        trees = {"this tree": ROOT}
        if args.against:
            other = Path(tmp) / "against"
            subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(other), args.against],
                           check=True, capture_output=True)
            trees[args.against] = other
        try:
            results = measure(trees, args.repeat)
        finally:
            if args.against:
                subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(other)],
                               capture_output=True)
    payload = {"machine": machine(), "repeat": args.repeat, "against": args.against,
               "load_before": [round(x, 2) for x in load_before], "results": results}
    names = list(trees)
    md = ["# Start-up time: `r2s --help`, `r2s VERB --help`, `import synth`", "",
          f"Best of {args.repeat} fresh interpreters, trees alternated; load average before "
          f"{' / '.join(f'{x:.2f}' for x in load_before)}. CPU time (user + system) is the comparison: wall time "
          "follows the shared machine's load.", "",
          "| command | " + " | ".join(f"{n}: CPU ms | {n}: wall ms" for n in names) + " |",
          "|---|" + "---:|---:|" * len(names)]
    for command, by_tree in results.items():
        md.append(f"| `{command}` | " + " | ".join(f"{by_tree[n]['cpu_ms']:.0f} | {by_tree[n]['wall_ms']:.0f}"
                                                  for n in names) + " |")
    write_results("startup", payload, "\n".join(md) + "\n")
    print("\n".join(md))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
