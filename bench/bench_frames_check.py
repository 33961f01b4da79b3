"""What `r2s run`'s up-front check costs now that it decodes every value its workers will read.

The check every run makes before any worker starts (`FramesDataset.check(FrameHasher(), road=...)`) reads, besides
the columns the rules and the frame hash read, every other column the run's workers read (source, scene,
frame_index, timestamp_us, track_id, category, and with `--lanes` the road columns), and checks every value as
decoded (UTF-8, dictionary indices, list offsets), so that a corrupt value refuses the run before a part of it is
written. Measured on the Argoverse 2 log extracted with its map (the shared test log, else the shipped nuScenes
excerpt) replicated to --frames frames (default 200,000) in 4 part files by bench_lanes.replicate (zstd, row groups
of 122,880 rows), in one process, CPU seconds, best of --repeat:
- rules only: `check(FrameHasher())`, the columns the check read before (what `r2s query` still checks);
- run: `check(FrameHasher(), road=False)`, a run without --lanes;
- run --lanes: `check(FrameHasher(), road=True)`.
Writes bench/results/frames_check.json and frames_check.md. The machine is shared: the load average is recorded.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent))

from bench_lanes import SOURCES, extract, replicate  # noqa: E402
from common import best, machine, write_results  # noqa: E402

MODES = (("rules only", None), ("run", False), ("run --lanes", True))


def measure(frames: Path, repeat: int) -> list[dict]:
    from extractors.frame_hash import FrameHasher
    from extractors.frames_dataset import CHECK_COLUMNS, FramesDataset

    dataset = FramesDataset.open(frames)
    out = []
    for name, road in MODES:
        part = dataset.parts[0]
        columns = (CHECK_COLUMNS + tuple(c for c in FrameHasher().columns if c in part.columns and c not in CHECK_COLUMNS)
                   if road is None else part.read_columns(road))
        seconds = best(lambda road=road: dataset.check(FrameHasher(), road=road), repeat)
        out.append({"mode": name, "road": road, "columns": len(columns), "cpu_s": seconds})
        print(f"  {name}: {len(columns)} columns, {seconds:.2f} s", flush=True)
    for r in out:
        r["ratio"] = r["cpu_s"] / out[0]["cpu_s"]
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=200_000)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    load0 = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="r2s-bench-check-") as tmp:
        name, source, path = SOURCES[2] if SOURCES[2][2].exists() else SOURCES[0]
        log = Path(tmp) / "log" / "frames"
        extract(source, path, log)
        frames = Path(tmp) / "replicated"
        copies, rows = replicate(log, args.frames, frames, parts=4)
        from extractors.frames_dataset import FramesDataset

        n = FramesDataset.open(frames).check().frames
        print(f"{name}: {n:,} frames ({copies:,} copies), {rows:,} rows", flush=True)
        runs = measure(frames, args.repeat)
    payload = {"machine": machine(), "command": "python bench/bench_frames_check.py " + " ".join(sys.argv[1:]),
               "log": name, "frames": n, "rows": rows, "runs": runs, "load": [load0, os.getloadavg()[0]]}
    write_results("frames_check", payload, markdown(payload))
    return 0


def markdown(p: dict) -> str:
    m = p["machine"]
    lines = ["# The up-front check of `r2s run`: every value its workers will read", "",
             f"Machine: {m['cpu']}, {m['cores']} cores, Python {m['python']}, commit {m['commit']}, {m['date']}. "
             f"Load average {p['load'][0]:.1f} before, {p['load'][1]:.1f} after. Command: `{p['command']}`.", "",
             f"{p['log']} replicated to {p['frames']:,} frames, {p['rows']:,} rows, in 4 files. CPU seconds of one "
             "process, best of the repeats, the frame hash included (as a run checks).", "",
             "| check | columns read | CPU | vs rules only |", "|---|---|---|---|"]
    for r in p["runs"]:
        lines.append(f"| {r['mode']} | {r['columns']} | {r['cpu_s']:.2f} s | {r['ratio']:.2f}x |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    sys.exit(main())
