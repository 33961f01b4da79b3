"""Window programs (issue 25) against single-frame programs on the shipped scenes. Writes bench/results/window.json
and window.md.

Frames: the shipped nuScenes-mini keyframes (data/nuscenes-mini-keyframes: 6 scenes at 2 Hz) and the shipped
Argoverse 2 log excerpt (data/argoverse2-log-excerpt: one log at 10 Hz). Each scene is tiled into windows of 1 s
and of 2 s (synth.window.program.tile: consecutive, not overlapping, no gap limit) and each window synthesized with the
default configuration (auto, hybrid, z3 certification, frame by frame); every frame is also synthesized alone.
With lanes (`--lanes`): the same recordings extracted with their maps (the shipped files carry none), from
../shared/data (nuScenes-mini through ScenarioNet: the same 242 keyframes; the Argoverse 2 log: the same 156
frames), each frame with the road `r2s scene` gives it (frames.maps.FrameRoads); without ../shared/data, the
shipped nuScenes excerpt with its maps (data/nuscenes-mini-excerpt) stands in.
Reported per dataset and window: CPU time per window (this process's: z3 runs in it) against the CPU time of
its frames alone (CPU seconds, not wall clock: the machine is shared), the window's cost
against its frames' own optima, and how long programs stay the same (the share of consecutive windows of a scene
whose programs are identical, as text).

    .venv/bin/python bench/bench_window.py
"""

from __future__ import annotations

import os
import re
import statistics
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

from common import machine, write_results  # noqa: E402

from frames.rows import frame_to_scene  # noqa: E402
from synth import SynthConfig, synthesize, synthesize_window, tile  # noqa: E402
from synth.window.program import check_window  # noqa: E402

DATASETS = {
    "nuScenes-mini keyframes (2 Hz)": ROOT / "data" / "nuscenes-mini-keyframes" / "frames.parquet",
    "Argoverse 2 log excerpt (10 Hz)": ROOT / "data" / "argoverse2-log-excerpt" / "frames.parquet",
}
SHARED = Path("/work/shared/data")
LANE_SOURCES = {  # name: (r2s extract source, input), the recordings above with their maps
    "nuScenes-mini keyframes (2 Hz), --lanes": ("scenarionet", SHARED / "nuscenes-mini" / "scenarionet"),
    "Argoverse 2 log excerpt (10 Hz), --lanes": (
        "argoverse2", SHARED / "argoverse2" / "test_data" / "sensor_dataset_logs" / "adcf7d18-0510-35b0-a2fa-b4cea13a6d76"),
}
SHIPPED_LANES = {"nuScenes excerpt (shipped, 2 Hz), --lanes": ("scenarionet", ROOT / "data" / "nuscenes-mini-excerpt"
                                                                 / "scenarionet")}
WINDOWS_S = (1.0, 2.0)


def extracted(source: str, path: Path, out: Path) -> Path:
    """The recording extracted with its maps (a frames dataset with _maps/ beside), as `r2s extract` writes it."""
    from pipeline.cli import main as r2s

    if r2s(["extract", source, str(path), "--categories", "all", "--out", str(out)]):
        raise SystemExit(f"bench_window: r2s extract {source} {path} failed")
    return out


def scenes_of(path: Path, roads: bool = False):
    """(scene name, [(timestamp_us, Scene)] in frame order) for each scene of a frames file or dataset (with
    `roads`: each frame with the road r2s scene gives it, from the maps beside the frames)."""
    import pandas as pd

    from frames.maps import FrameRoads, maps_dir

    found = FrameRoads(maps_dir(path)) if roads else None
    df = pd.read_parquet(path)
    for name, rows in df.groupby("scene", sort=True):
        rows = rows.sort_values(["frame_index"], kind="stable")
        frames = [(int(g.timestamp_us.iloc[0]), frame_to_scene(g, found.road(g)[0] if found is not None else None))
                  for _, g in rows.groupby("frame_id", sort=False)]
        yield str(name), frames


def measure(path: Path, config: SynthConfig, roads: bool = False) -> dict:
    out = {"frames": 0, "scenes": 0, "windows": {}}
    for name, frames in scenes_of(path, roads):
        out["scenes"] += 1
        out["frames"] += len(frames)
        alone = []
        for _, scene in frames:
            t = time.process_time()
            result = synthesize(scene, config)
            alone.append((time.process_time() - t, result.cost, result.status))
        for window_s in WINDOWS_S:
            rows = out["windows"].setdefault(str(window_s), [])
            previous = previous_shape = None
            for first, last in tile([t for t, _ in frames], int(window_s * 1e6)):
                scenes = [s for _, s in frames[first:last + 1]]
                t = time.process_time()
                result = synthesize_window(scenes, config)
                seconds = time.process_time() - t
                ok = all(v.ok for v in check_window(result.program, scenes, config))
                text = str(result.program)
                shape = re.sub(r"Range\([^)]*\)", "Range", text)  # the relations, Range values aside
                rows.append({"scene": name, "first": first, "last": last, "n_frames": len(scenes), "seconds": seconds,
                             "alone_seconds": sum(a for a, _, _ in alone[first:last + 1]), "cost": result.cost,
                             "frame_costs": [c for _, c, _ in alone[first:last + 1]],
                             "frames_optimal": all(s == "optimal" for _, _, s in alone[first:last + 1]),
                             "optimal": result.status == "optimal",
                             "certified": result.certified, "consistent": ok, "entities": result.n_entities,
                             "same_as_previous": None if previous is None else text == previous,
                             "same_relations_as_previous": None if previous_shape is None else shape == previous_shape,
                             "statements_in_both": None if previous_shape is None else len(common(previous_shape, shape)),
                             "statements_kept": None if previous_shape is None else
                             sum(a == b for a, b in common(previous_shape, shape))})
                previous, previous_shape = text, shape
    return out


def common(before: str, after: str) -> list[tuple[str, str]]:
    """The statements (Range values blanked) of the entities two programs both declare, paired."""
    a, b = ({ln.split(" = new ")[0]: ln for ln in t.splitlines()} for t in (before, after))
    return [(a[i], b[i]) for i in sorted(a.keys() & b.keys())]


def summary(rows: list[dict]) -> dict:
    multi = [r for r in rows if r["n_frames"] > 1]
    pairs = [r["same_as_previous"] for r in rows if r["same_as_previous"] is not None]
    shapes = [r["same_relations_as_previous"] for r in rows if r["same_relations_as_previous"] is not None]
    return {
        "windows": len(rows),
        "frames_per_window": statistics.mean(r["n_frames"] for r in rows),
        "all_optimal": all(r["optimal"] for r in rows),
        "all_certified": all(r["certified"] for r in rows),
        "all_consistent": all(r["consistent"] for r in rows),
        "frames_alone_all_optimal": all(r["frames_optimal"] for r in rows),
        "ms_per_window_median": 1000 * statistics.median(r["seconds"] for r in rows),
        "ms_per_frame_alone_median": 1000 * statistics.median(r["alone_seconds"] / r["n_frames"] for r in rows),
        "window_over_its_frames_alone": sum(r["seconds"] for r in rows) / sum(r["alone_seconds"] for r in rows),
        "mean_window_cost": statistics.mean(r["cost"] for r in rows),
        "mean_max_frame_cost": statistics.mean(max(r["frame_costs"]) for r in rows),
        "mean_frame_cost": statistics.mean(c for r in rows for c in r["frame_costs"]),
        "window_over_max_frame_cost": (sum(r["cost"] for r in multi) / max(1, sum(max(r["frame_costs"]) for r in multi))),
        "windows_costing_more_than_every_frame": sum(r["cost"] > max(r["frame_costs"]) for r in multi),
        "multi_frame_windows": len(multi),
        "consecutive_pairs": len(pairs),
        "identical_share": (sum(pairs) / len(pairs)) if pairs else None,
        "same_relations_share": (sum(shapes) / len(shapes)) if shapes else None,
        "statements_kept_share": (sum(r["statements_kept"] or 0 for r in rows)
                                  / max(1, sum(r["statements_in_both"] or 0 for r in rows))),
    }


def main() -> None:
    load0 = os.getloadavg()[0]
    started = time.perf_counter()
    results = {name: measure(path, SynthConfig()) for name, path in DATASETS.items()}
    with tempfile.TemporaryDirectory(prefix="bench-window-") as tmp:
        lanes = LANE_SOURCES if all(p.exists() for _, p in LANE_SOURCES.values()) else SHIPPED_LANES
        for k, (name, (source, path)) in enumerate(lanes.items()):
            frames = extracted(source, path, Path(tmp) / f"lanes{k}")
            results[name] = measure(frames, SynthConfig(lanes=True), roads=True)
    total = time.perf_counter() - started
    load1 = os.getloadavg()[0]
    m = machine()
    payload = {"machine": m, "load_start": load0, "load_end": load1, "total_s": total, "datasets": {
        name: {"scenes": r["scenes"], "frames": r["frames"],
               "windows": {w: {"summary": summary(rows), "rows": rows} for w, rows in r["windows"].items()}}
        for name, r in results.items()}}
    lines = ["# Window programs against single-frame programs", "",
             f"Machine: {m['cpu']} ({m['cores']} cores), commit {m['commit']}, {m['date']}; load average "
             f"{load0:.2f} at the start, {load1:.2f} at the end; total {total:.0f} s. Command: "
             "`.venv/bin/python bench/bench_window.py`.", "",
             "Each scene tiled into consecutive windows of W seconds (synth.window.program.tile), each window synthesized "
             "with the default configuration (auto, hybrid, z3 certification frame by frame), every frame also "
             "synthesized alone; times are CPU seconds of this process (z3 runs in it), as the machine is shared. Cost: the window program's against the largest of its frames' own optimal costs "
             "(a lower bound on it). Identical: the share of consecutive windows of a scene with the same program "
             "text; same relations: the same text once every Range is blanked; statements kept: of the entities "
             "declared in two consecutive windows, those whose statement is the same, Range values aside (as `r2s "
             "report` counts them). Rows marked `--lanes`: the same recordings extracted with their maps (from "
             "../shared/data; the shipped files carry no map), each frame with the road `r2s scene` gives it, "
             "synthesized with lanes on, windows and frames alone alike.", "",
             "| data | W | windows | frames/window | optimal, certified, consistent | CPU ms per window (median) | "
             "CPU ms per frame alone (median) | window CPU time / its frames alone | mean window cost | mean max frame "
             "cost | mean frame cost | windows costing more than every frame | identical consecutive | same "
             "relations | statements kept |",
             "|---|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for name, r in payload["datasets"].items():
        for w, data in r["windows"].items():
            s = data["summary"]
            ok = "yes" if s["all_optimal"] and s["all_certified"] and s["all_consistent"] else "NO"
            ok += "" if s["frames_alone_all_optimal"] else " (a frame alone not optimal)"
            same = "n/a" if s["identical_share"] is None else \
                f"{100 * s['identical_share']:.0f}% of {s['consecutive_pairs']}"
            shape = "n/a" if s["same_relations_share"] is None else f"{100 * s['same_relations_share']:.0f}%"
            lines.append(f"| {name} ({r['frames']} frames) | {w} s | {s['windows']} | {s['frames_per_window']:.1f} | "
                         f"{ok} | {s['ms_per_window_median']:.0f} | {s['ms_per_frame_alone_median']:.0f} | "
                         f"x{s['window_over_its_frames_alone']:.2f} | {s['mean_window_cost']:.2f} | "
                         f"{s['mean_max_frame_cost']:.2f} | {s['mean_frame_cost']:.2f} | "
                         f"{s['windows_costing_more_than_every_frame']} of {s['multi_frame_windows']} | {same} | "
                         f"{shape} | {100 * s['statements_kept_share']:.0f}% |")
    write_results("window", payload, "\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
