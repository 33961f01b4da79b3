"""Shared bits of the benchmark scripts: machine description and result writing."""

from __future__ import annotations

import json
import os
import platform
import subprocess
import time
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results"


def machine() -> dict:
    cpu = ""
    try:
        cpu = next(line.split(":", 1)[1].strip() for line in open("/proc/cpuinfo") if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                                cwd=Path(__file__).parent).stdout.strip()
    except OSError:
        commit = ""
    return {"cpu": cpu, "cores": os.cpu_count(), "python": platform.python_version(),
            "date": time.strftime("%Y-%m-%d %H:%M"), "commit": commit,
            "note": "shared 2-core machine: compare ratios within one run, not absolute times across runs"}


def write_results(name: str, payload: dict, markdown: str) -> None:
    from storage.atomic import write_text_atomic

    RESULTS.mkdir(parents=True, exist_ok=True)
    write_text_atomic(RESULTS / f"{name}.json", json.dumps(payload, indent=1, default=float) + "\n")
    write_text_atomic(RESULTS / f"{name}.md", markdown)
    print(f"wrote {RESULTS / (name + '.json')} and {name}.md")


def best(fn, repeat: int) -> float:
    """The least CPU time of this process over `repeat` calls: on a shared machine, wall time measures the load."""
    times = []
    for _ in range(repeat):
        t = time.process_time()
        fn()
        times.append(time.process_time() - t)
    return min(times)


# A child that runs one r2s command (`python -c R2S_CHILD VERB ARGS...`) and prints its CPU seconds and peak
# resident memory as the JSON line run_child reads.
R2S_CHILD = """
import json, sys, time
from pipeline.cli import main
t = time.process_time()
rc = main(sys.argv[1:])
cpu = time.process_time() - t
hwm = next(int(l.split()[1]) for l in open("/proc/self/status") if l.startswith("VmHWM")) / 1024
print(json.dumps({"rc": rc, "cpu_s": cpu, "peak_rss_mb": hwm}))
"""


def run_child(script: str, cmd: list[str], cwd: Path) -> dict:
    """Run a benchmark's child process (a fresh interpreter: its own peak RSS) that prints one JSON line last;
    returns that record with `wall_s`, the child's wall clock. A failure stops the benchmark with its stderr."""
    t = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=cwd)
    wall = time.perf_counter() - t
    if proc.returncode != 0:
        raise SystemExit(f"{script}: {' '.join(cmd[2:])} failed: {proc.stderr.strip()[-500:]}")
    return {**json.loads(proc.stdout.strip().splitlines()[-1]), "wall_s": wall}


def peak_rss_mb() -> float:
    """This process's peak resident memory (VmHWM, not ru_maxrss: Linux carries that over from a forking parent)."""
    return next(int(line.split()[1]) for line in open("/proc/self/status") if line.startswith("VmHWM")) / 1024
