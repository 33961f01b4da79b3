"""What `r2s export --to opendrive` costs per map against its size, and whether simulators can use what it writes
(issue 37).

Maps: the shipped Argoverse 2 log's whole map, and the shared Waymo scenarios' maps (../shared/data/waymo, the
--waymo smallest files; skipped without). Each is exported by `r2s export MAPS --map ID --to opendrive` in a fresh
interpreter (its CPU seconds, wall seconds and peak resident memory, VmHWM), then read back: ASAM's qc-opendrive
(errors and warnings), Scenic's parser (its intersections; each Scenic lane's largest distance from the recorded
centre line it follows, sampled every metre; the recorded successor links Scenic keeps), and driving: one car
per recorded lane that has a successor in the map, set 6 m before its end (at its middle if it is shorter than
8 m), FollowLaneBehavior at 6 m/s in Scenic's Newtonian simulator (2D, render off, collisions allowed and cars anywhere: the
cars do not see each other) for 6 s; a car drove on when at some step its lane is one of the recorded lanes within
three links after its own; lanes side by side: the recorded same-direction neighbour pairs in the map that
Scenic's network reports as adjacent lanes, and on up to 10 of those a LaneChangeBehavior car (lane_change).
Writes bench/results/opendrive.json and opendrive.md.

    .venv/bin/python bench/bench_opendrive.py [--waymo 3]
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(ROOT))

from common import R2S_CHILD, machine, run_child, write_results  # noqa: E402

STEPS = 60  # 6 s at Scenic's 0.1 s step
CHANGES, CHANGE_STEPS = 10, 40  # lane changes tried per map, each for 4 s
NAMES = "l.road.name.split(' | ')[-l.sections[0].openDriveID - 1].split(' > ')"  # Scenic lane l's recorded lanes
SHARED = ROOT.parent / "shared" / "data" / "waymo"


def simulate(xodr: Path, helpers: str, cars: list[str], steps: int):
    """A Scenic scene on the map (Newtonian driving model, 2D, render off) with Scenic helper definitions and one
    line per car (the first made ego), and its trajectory over `steps` steps."""
    import scenic
    from scenic.simulators.newtonian import NewtonianSimulator

    code = (f"param map = {str(xodr)!r}\nmodel scenic.simulators.newtonian.driving_model\n" + helpers
            + "\n".join(["ego = " + cars[0].split(" = ", 1)[1]] + cars[1:]) + "\n")
    scenario = scenic.scenarioFromString(code, mode2D=True, params={"render": False})
    scene, _ = scenario.generate(maxIterations=1)
    return scene, NewtonianSimulator().simulate(scene, maxSteps=steps).trajectory


def drive(xodr: Path, road, shift) -> tuple[int, int, list[str]]:
    """Cars that drove from their lane into a successor, cars started, and the lanes of those that did not.

    Recorded lanes overlap (Waymo's merging lanes run over each other for metres, junction lanes cross): a car
    set at a point only would take the lane and heading Scenic finds first there, often a neighbour's. So each
    car faces its recorded lane's heading and follows the Scenic lane of its own recorded lane there
    (FollowLaneBehavior's laneToFollow); it drove on when at some step it is inside a Scenic lane of a recorded
    lane within three links after its own and no longer inside its own (every lane holding the point, not the
    one Scenic's laneAt picks), or, having run more than its lane's rest and MIN_PIECE, inside such a lane and in
    no Scenic lane of its own lane alone (a lane's last metres may be put before its successor,
    synth.road.opendrive: a Scenic lane of both)."""
    import numpy as np
    import shapely

    from synth.road.opendrive import lane_graph
    from synth.road.opendrive_group import MIN_PIECE
    from tests.support.opendrive import recorded

    lanes = {f.feature_id: f for f in road.lanes}
    succ, _ = lane_graph(lanes)
    starts, lines, left = [], [], []  # left: metres from each car's start to its lane's end
    for k in sorted(lanes):
        if not succ[k]:
            continue
        line = shapely.LineString([(x - shift[0], y - shift[1]) for x, y in lanes[k].line])
        at = line.length / 2 if line.length < 8 else line.length - 6
        p, q = line.interpolate(at), line.interpolate(min(line.length, at + 0.5))
        if q.distance(p) < 1e-6:
            p, q = line.interpolate(at - 0.5), p
        heading = math.atan2(q.y - p.y, q.x - p.x) - math.pi / 2  # Scenic's headings start at the y axis
        starts.append(k)
        left.append(line.length - at)
        lines.append(f"c{len(starts)} = new Car at ({p.x!r}, {p.y!r}), facing {heading!r}, with behavior "
                     f"FollowLaneBehavior(target_speed=6, laneToFollow=lane_of({k!r}, {p.x!r}, {p.y!r})), "
                     "with allowCollisions True, with requireVisible False, with regionContainedIn everywhere")
    scene, trajectory = simulate(xodr, "def lane_of(name, x, y):\n"
                                 f"    here = [l for l in network.lanes if name in {NAMES} and l.containsPoint((x, y))]\n"
                                 "    return here[0] if here else network.laneAt((x, y))\n", lines, STEPS)
    network = scene.workspace.network
    names = [set(recorded(lane)) for lane in network.lanes]
    tree = shapely.STRtree([lane.polygon for lane in network.lanes])
    # step -> car -> the recorded lanes of each Scenic lane holding it (a lane's piece put before its successor,
    # synth.road.opendrive's trims, is a lane of both)
    inside = [[[] for _ in starts] for _ in trajectory]
    points = shapely.points([tuple(step[i])[:2] for step in trajectory for i in range(len(starts))])
    for where, lane in zip(*tree.query(points, predicate="intersects")):
        inside[where // len(starts)][where % len(starts)].append(names[lane])
    ok, failed = 0, []
    for i, k in enumerate(starts):
        after, frontier = set(), {k}
        for _ in range(3):
            frontier = {s for f in frontier for s in succ[f]} - after
            after |= frontier
        run = np.concatenate([[0.0], np.cumsum([(b[i] - a[i]).norm() for a, b in zip(trajectory, trajectory[1:])])])
        reached = any(set().union(*step[i]) & after and k not in set().union(*step[i]) for step in inside) or any(
            any(held & after for held in step[i]) and {k} not in step[i] and run[t] > left[i] + MIN_PIECE
            for t, step in enumerate(inside))
        ok += reached
        if not reached:
            end = network.laneAt(trajectory[-1][i])
            failed.append(f"{k}: moved {(trajectory[-1][i] - trajectory[0][i]).norm():.1f} m, ends on "
                          f"{end.road.name if end is not None else None}")
    return ok, len(starts), failed


def lane_change(xodr: Path, pairs: list[tuple[str, str]], sample: int = CHANGES) -> tuple[int, int, list[str]]:
    """Cars that moved into the neighbour lane, cars started, and the pairs where they did not: for the first
    `sample` recorded neighbour pairs Scenic sees as adjacent, one car each (cars do not see each other) set at a
    third of its lane's Scenic centre line (the one adjacent to the neighbour's), facing along it, with
    LaneChangeBehavior into the neighbour's lane section there at 6 m/s for 4 s; it moved over when at some step
    it is inside the neighbour's Scenic lane and no longer inside its own."""

    from tests.support.opendrive import recorded

    chosen = pairs[:sample]
    if not chosen:
        return 0, 0, []
    lines = []
    for i, (a, b) in enumerate(chosen):
        pair = f"adjacent_pair({a!r}, {b!r})"
        lines.append(f"c{i} = new Car on {pair}[0].centerline.pointAlongBy({pair}[0].centerline.length / 3), facing "
                     f"{pair}[0].orientation, with behavior LaneChangeBehavior({pair}[1].sections[0], target_speed=6), "
                     "with allowCollisions True, with requireVisible False, with regionContainedIn everywhere")
    # the Scenic lanes of the pair that are adjacent (a recorded lane may have pieces on several roads), the car
    # facing its own lane's direction (roadDirection there may be an overlapping lane's: AV2's lanes overlap)
    helpers = ("def adjacent_pair(a, b):\n    for l in network.lanes:\n        if a in " + NAMES + ":\n"
               "            mine = l\n            for l in mine.adjacentLanes:\n                if b in " + NAMES
               + ":\n                    return mine, l\n")
    scene, trajectory = simulate(xodr, helpers, lines, CHANGE_STEPS)
    network = scene.workspace.network
    by_name = {}
    for lane in network.lanes:
        for n in recorded(lane):
            by_name.setdefault(n, []).append(lane)
    ok, failed = 0, []
    for i, (a, b) in enumerate(chosen):
        moved = any(any(lane.containsPoint(step[i]) for lane in by_name[b])
                    and not any(lane.containsPoint(step[i]) for lane in by_name[a]) for step in trajectory)
        ok += moved
        if not moved:
            failed.append(f"{a} -> {b}")
    return ok, len(chosen), failed


def measure(maps: Path, map_id: str, work: Path) -> dict:
    from frames.maps import read_maps
    from tests.support.opendrive import (
        adjacent_pairs,
        asam_issues,
        centre_line_gaps,
        kept_links,
        offset,
        scenic_network,
    )

    road = next(m for m in read_maps(maps) if m.map_id == map_id)
    xodr = work / f"{map_id}.xodr"
    cost = run_child("bench_opendrive", [sys.executable, "-c", R2S_CHILD, "export", str(maps), "--map", map_id, "--to",
                                         "opendrive", "--out", str(xodr)], ROOT)
    issues = asam_issues(xodr)
    t = time.perf_counter()
    net = scenic_network(xodr)
    load = time.perf_counter() - t
    gaps = centre_line_gaps(net, road, offset(xodr))
    kept, lost = kept_links(net, road)
    drove, cars, failed = drive(xodr, road, offset(xodr))
    adjacent, apart = adjacent_pairs(net, road)
    changed, changes, not_changed = lane_change(xodr, adjacent)
    return {"map": map_id, "features": len(road.features), "lanes": len(road.lanes),
            "points": sum(len(f.line) + len(f.polygon) for f in road.features), "cpu_s": cost["cpu_s"],
            "wall_s": cost["wall_s"], "peak_rss_mb": cost["peak_rss_mb"], "xodr_mb": xodr.stat().st_size / 2**20,
            "asam_issues": len(issues), "scenic_load_s": load, "intersections": len(net.intersections),
            "max_gap_m": max(gaps.values()), "links_kept": len(kept), "links": len(kept) + len(lost),
            "drove": drove, "cars": cars, "failed": failed[:10], "adjacent": len(adjacent),
            "neighbour_pairs": len(adjacent) + len(apart), "changed": changed, "changes": changes,
            "not_changed": not_changed}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--waymo", type=int, default=3, help="shared Waymo scenarios to take, smallest first (0: none)")
    args = ap.parse_args()
    import subprocess

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        from frames.maps import read_maps

        av2 = ROOT / "data/argoverse2-log-excerpt/frames.maps"
        rows += [measure(av2, m.map_id, work) for m in read_maps(av2)]
        pkls = sorted(SHARED.glob("sd_*.pkl"), key=lambda p: p.stat().st_size)[:args.waymo] if SHARED.exists() else []
        if pkls:
            (work / "waymo").mkdir()
            for p in pkls:
                (work / "waymo" / p.name).symlink_to(p)
            subprocess.run([sys.executable, "-m", "pipeline.cli", "extract", "scenarionet", str(work / "waymo"),
                            "--out", str(work / "waymo.parquet")], check=True, cwd=ROOT, capture_output=True)
            rows += [measure(work / "waymo.maps", m.map_id, work) for m in read_maps(work / "waymo.maps")]
        for r in rows:
            print(r)
    load = os.getloadavg()
    m = {**machine(), "load": [round(v, 1) for v in load]}
    payload = {"machine": m, "rows": rows}
    write_results("opendrive", payload, markdown(payload))


def markdown(payload: dict) -> str:
    """The results table, and the cars that did not drive on (their lane, how far they went, where they ended)."""
    m, rows = payload["machine"], payload["rows"]
    lines = ["# OpenDRIVE from recorded maps (issue 37)", "",
             f"`bench/bench_opendrive.py`; {m['cpu']}, commit {m['commit']}, {m['date']}, load average "
             f"{', '.join(map(str, m.get('load', [])))} at the end; {m['note']}.", "",
             "| map | features | points | export CPU s | wall s | peak MB | .xodr MB | ASAM issues | Scenic load s "
             "| intersections | max lane gap m | links kept | drove on | neighbours adjacent | lane changes |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['map'][:16]} | {r['features']} | {r['points']:,} | {r['cpu_s']:.1f} | {r['wall_s']:.1f} "
                     f"| {r['peak_rss_mb']:.0f} | {r['xodr_mb']:.1f} | {r['asam_issues']} | {r['scenic_load_s']:.0f} "
                     f"| {r['intersections']} | {r['max_gap_m']:.3f} | {r['links_kept']} / {r['links']} "
                     f"| {r['drove']} / {r['cars']} ({100 * r['drove'] / max(1, r['cars']):.0f}%) "
                     f"| {r['adjacent']} / {r['neighbour_pairs']} | {r['changed']} / {r['changes']} |")
    lines += ["", "Cars that did not drive on (start lane: distance moved in 6 s, the Scenic lane it ended on):", ""]
    lines += [f"- {r['map'][:16]}: " + "; ".join(r["failed"]) for r in rows if r["failed"]]
    lines += ["", "Lane changes that did not move over (lane -> neighbour):", ""]
    lines += [f"- {r['map'][:16]}: " + "; ".join(r["not_changed"]) for r in rows if r["not_changed"]]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()
