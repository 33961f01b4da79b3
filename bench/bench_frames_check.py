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
- run --lanes, rows only: `check(FrameHasher(), road=True)`, the check of a --lanes run before its resume key
  covered the road (issue 35);
- run --lanes: `check(FrameHasher(coverage=Coverage.with_road(map_digests(maps))), road=True)`, what a --lanes run
  checks now: the road columns hashed too, and every map read and digested once.
With --map-per-scene, every copy of the log names a map of its own (a copy of the log's map under another id, as
ScenarioNet / Waymo scenarios each have theirs) instead of all copies naming one map: the map digests' worst case.
Writes bench/results/frames_check.json and frames_check.md (frames_check_maps.* with --map-per-scene). The machine
is shared: the load average is recorded.
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

MODES = (("rules only", None, False), ("run", False, False), ("run --lanes, rows only", True, False),
         ("run --lanes", True, True))


def measure(frames: Path, repeat: int) -> list[dict]:
    from frames.dataset import CHECK_COLUMNS, FramesDataset
    from frames.frame_hash import Coverage, FrameHasher
    from frames.maps import map_digests, maps_dir

    dataset = FramesDataset.open(frames)
    out = []

    def check(road, maps):
        coverage = Coverage.with_road(map_digests(maps_dir(frames))) if maps else Coverage()
        dataset.check(FrameHasher(coverage=coverage), road=road)

    for name, road, maps in MODES:
        part = dataset.parts[0]
        columns = (CHECK_COLUMNS + tuple(c for c in FrameHasher().columns if c in part.columns and c not in CHECK_COLUMNS)
                   if road is None else part.read_columns(road))
        seconds = best(lambda road=road, maps=maps: check(road, maps), repeat)
        out.append({"mode": name, "road": road, "columns": len(columns), "cpu_s": seconds})
        print(f"  {name}: {len(columns)} columns, {seconds:.2f} s", flush=True)
    for r in out:
        r["ratio"] = r["cpu_s"] / out[0]["cpu_s"]
    n_maps = len(map_digests(maps_dir(frames)))
    digest_s = best(lambda: map_digests(maps_dir(frames)), repeat)
    size = sum(f.stat().st_size for f in maps_dir(frames).glob("*.parquet"))
    out.append({"mode": "map digests alone", "maps": n_maps, "maps_mb": size / 2**20, "cpu_s": digest_s,
                "ratio": digest_s / out[0]["cpu_s"]})
    print(f"  map digests alone: {n_maps} maps ({size / 2**20:.1f} MB of Parquet), {digest_s:.2f} s", flush=True)
    return out


def map_per_scene(frames: Path) -> None:
    """Every scene (copy of the log) names a map of its own: the map copied under `<map_id>~<copy>`, one row group
    a map as r2s extract writes them, in 4 files."""
    import duckdb

    from frames.maps import maps_dir

    con = duckdb.connect(config={"threads": os.cpu_count() or 1})
    con.execute("SET enable_progress_bar = false")
    for part in sorted(frames.glob("part-*.parquet")):
        tmp = part.with_name(f".{part.name}.tmp")
        con.execute(f"COPY (SELECT * REPLACE (map_id || '~' || split_part(scene, '~', 2) AS map_id) FROM "
                    f"read_parquet('{part}')) TO '{tmp}' (FORMAT parquet, COMPRESSION zstd, ROW_GROUP_SIZE 122880)")
        tmp.replace(part)
    copies = [r for (r,) in con.execute(f"SELECT DISTINCT split_part(scene, '~', 2) FROM read_parquet('{frames}/*.parquet') "
                                        "ORDER BY 1").fetchall()]
    maps = maps_dir(frames)
    con.execute(f"CREATE TEMP TABLE m AS SELECT * FROM read_parquet('{maps}/*.parquet')")
    for old in maps.glob("*.parquet"):
        old.unlink()
    for p in range(4):
        mine = copies[len(copies) * p // 4: len(copies) * (p + 1) // 4]
        con.execute(f"COPY (SELECT m.* REPLACE (m.map_id || '~' || c.r AS map_id) FROM (SELECT unnest({mine!r}) AS r) c, m "
                    f"ORDER BY c.r) TO '{maps / f'part-{p:03d}.parquet'}' (FORMAT parquet, COMPRESSION zstd)")
    con.close()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=200_000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--map-per-scene", action="store_true")
    args = ap.parse_args()
    load0 = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="r2s-bench-check-") as tmp:
        name, source, path = SOURCES[2] if SOURCES[2][2].exists() else SOURCES[0]
        log = Path(tmp) / "log" / "frames"
        extract(source, path, log)
        frames = Path(tmp) / "replicated"
        copies, rows = replicate(log, args.frames, frames, parts=4)
        if args.map_per_scene:
            map_per_scene(frames)
        from frames.dataset import FramesDataset

        n = FramesDataset.open(frames).check().frames
        print(f"{name}: {n:,} frames ({copies:,} copies), {rows:,} rows", flush=True)
        runs = measure(frames, args.repeat)
    payload = {"machine": machine(), "command": "python bench/bench_frames_check.py " + " ".join(sys.argv[1:]),
               "log": name, "frames": n, "rows": rows, "runs": runs, "load": [load0, os.getloadavg()[0]]}
    write_results("frames_check_maps" if args.map_per_scene else "frames_check", payload, markdown(payload))
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
        if "columns" in r:
            lines.append(f"| {r['mode']} | {r['columns']} | {r['cpu_s']:.2f} s | {r['ratio']:.2f}x |")
    runs = {r["mode"]: r for r in p["runs"]}
    maps, rows_only, lanes = runs["map digests alone"], runs["run --lanes, rows only"], runs["run --lanes"]
    lines += ["", f"The resume key of a --lanes run (road columns and map contents hashed) costs "
              f"{lanes['cpu_s'] / rows_only['cpu_s']:.2f}x the check of the frames' rows alone; of that, reading and "
              f"digesting the {maps['maps']:,} map(s) ({maps['maps_mb']:.1f} MB of Parquet) once takes "
              f"{maps['cpu_s']:.2f} s."]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    sys.exit(main())
