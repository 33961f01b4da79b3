"""What hashing every frame's rows costs `r2s run` (issue 22: a stored program is reused only for the same rows).

The shipped nuScenes-mini keyframes (242 frames, 4 to 141 entities) replicated to 10^5 and 10^6 frames under
distinct ids, in row groups of 64,000 rows as the extractors write them. Measured in one process, best of
`--repeat`:
1. the coordinator: `FramesDataset.check()` (the streaming check every run makes) against `check(FrameHasher())`
   (the same pass, also reading the hashed columns and hashing every frame), and the memory the content index
   keeps (16 bytes a frame, besides the 16 of the frame-id index);
2. the workers: hashing the rows of a chunk of 32 frames (ChunkTask.read) against reading them alone, per frame.
Times are CPU seconds of the process (the machine is shared: wall time would measure the others' load, which is
recorded). Writes bench/results/frame_hash.json and frame_hash.md.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from bench_scale import replicate_frames  # noqa: E402
from common import best, machine, write_results  # noqa: E402


def coordinator(path: Path, repeat: int) -> dict:
    from frames.dataset import FramesDataset
    from frames.frame_hash import FrameHasher

    dataset = FramesDataset.open(path)
    plain = best(lambda: dataset.check(), repeat)
    keys = {}

    def hashed():
        hasher = FrameHasher()
        dataset.check(hasher)
        keys["index"] = hasher.keys()

    with_hash = best(hashed, repeat)
    n = len(keys["index"])
    return {"frames": n, "rows": dataset.rows, "check_s": plain, "check_and_hash_s": with_hash,
            "hash_s": with_hash - plain, "hash_us_per_frame": 1e6 * (with_hash - plain) / n,
            "extra_pct": 100 * (with_hash - plain) / plain, "index_mb": keys["index"].nbytes / 2**20}


def workers(path: Path, repeat: int, chunks: int = 200, size: int = 32) -> dict:
    from frames.dataset import FramesDataset
    from pipeline.batch.task import ChunkTask
    from storage.parquet import read_rows
    from synth.config import SynthConfig

    dataset = FramesDataset.open(path)
    part = dataset.parts[0]
    every = []
    for runs in dataset.runs():
        every += [(str(f), int(s), int(n)) for f, s, n in zip(runs.ids, runs.starts, runs.lengths)]
        if len(every) >= chunks * size:
            break
    tasks = [ChunkTask(f"c{c}", "", part.path, tuple(every[c * size: (c + 1) * size]), part.columns, SynthConfig()) for c in range(chunks)]

    def read_only():
        for t in tasks:
            read_rows(t.url, t.path, t.frames[0][1], t.frames[-1][1] + t.frames[-1][2], t.columns)

    def read_and_hash():
        for t in tasks:
            t.read()

    plain, hashed = best(read_only, repeat), best(read_and_hash, repeat)
    n = chunks * size
    return {"frames": n, "chunk_size": size, "read_us_per_frame": 1e6 * plain / n,
            "read_and_hash_us_per_frame": 1e6 * hashed / n, "hash_us_per_frame": 1e6 * (hashed - plain) / n}


def markdown(p: dict) -> str:
    lines = ["# Frame hashes: what `r2s run` pays to reuse a program only for the same rows", "",
             f"Machine: {p['machine']['cpu']}, {p['machine']['cores']} cores, Python {p['machine']['python']}, "
             f"commit {p['machine']['commit']}, {p['machine']['date']}. Load average {p['load'][0]:.1f} before, {p['load'][1]:.1f} after. "
             f"Command: `{p['command']}`.", "",
             "CPU seconds of one process, best of the repeats.", "",
             "| frames | rows | check | check + hash | hash per frame | extra | content index |",
             "|---|---|---|---|---|---|---|"]
    for r in p["coordinator"]:
        lines.append(f"| {r['frames']:,} | {r['rows']:,} | {r['check_s']:.2f} s | {r['check_and_hash_s']:.2f} s | "
                     f"{r['hash_us_per_frame']:.2f} us | {r['extra_pct']:.0f}% | {r['index_mb']:.1f} MB |")
    w = p["workers"]
    lines += ["", f"Workers: reading a chunk of {w['chunk_size']} frames costs {w['read_us_per_frame']:.1f} us a "
              f"frame, hashing its rows {w['hash_us_per_frame']:.1f} us more (a frame's synthesis takes "
              "milliseconds to seconds).", ""]
    return "\n".join(lines)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="100000,1000000")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--tmp", default=None)
    args = ap.parse_args()
    load0 = os.getloadavg()[0]
    payload = {"machine": machine(), "command": "python bench/bench_frame_hash.py " + " ".join(sys.argv[1:]),
               "coordinator": []}
    with tempfile.TemporaryDirectory(prefix="r2s-bench-hash-", dir=args.tmp) as tmp:
        for n in (int(s) for s in args.sizes.split(",")):
            path = Path(tmp) / f"frames-{n}.parquet"
            replicate_frames(n, path)
            r = coordinator(path, args.repeat)
            print(f"{r['frames']:,} frames: check {r['check_s']:.2f} s, with hashing {r['check_and_hash_s']:.2f} s "
                  f"({r['hash_us_per_frame']:.2f} us a frame, +{r['extra_pct']:.0f}%), index {r['index_mb']:.1f} MB",
                  flush=True)
            payload["coordinator"].append(r)
            if "workers" not in payload:
                payload["workers"] = workers(path, args.repeat)
            path.unlink()
    payload["load"] = [load0, os.getloadavg()[0]]
    write_results("frame_hash", payload, markdown(payload))
    return 0


if __name__ == "__main__":
    sys.exit(main())
