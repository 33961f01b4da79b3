"""Reading an exported .xodr back the way a simulator does (Scenic's own OpenDRIVE parser) and comparing it with
the recorded map it came from: each Scenic lane's distance from its recorded centre line, and which recorded
successor links Scenic's network keeps (as a successor or a junction maneuver)."""

from __future__ import annotations

import logging
import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import shapely

from synth.road.roadmap import RoadMap

SEP = " > "  # how a connecting road's name joins the recorded lanes it follows (synth.road.opendrive.Road.name)
LANE_SEP = " | "  # how a road's name joins its lanes' (lane -1 first: synth.road.opendrive_model.LANE_SEP)


def recorded(lane) -> list[str]:
    """The recorded lanes a Scenic lane follows: its OpenDRIVE lane's part of its road's name."""
    return lane.road.name.split(LANE_SEP)[-lane.sections[0].openDriveID - 1].split(SEP)


def adjacent_pairs(net, road: RoadMap) -> tuple[list[tuple[str, str]], list[tuple[str, str]]]:
    """The recorded same-direction neighbour pairs (lane, its right neighbour) that run side by side
    (_side_by_side), both of whose lanes are in the network, split into those Scenic reports as adjacent lanes (lane.adjacentLanes) and those it does not."""
    by_name: dict[str, list] = {}
    for lane in net.lanes:
        for n in recorded(lane):
            by_name.setdefault(n, []).append(lane)
    lanes = {f.feature_id: f for f in road.lanes}
    pairs = set()
    for k, f in lanes.items():
        for a, b in ((k, f.right), (f.left, k)):
            if a in by_name and b in by_name and _side_by_side(lanes[a], lanes[b]):
                pairs.add((a, b))
    seen, not_seen = [], []
    for a, b in sorted(pairs):
        adjacent = any(o in la.adjacentLanes for la in by_name[a] for o in by_name[b])
        (seen if adjacent else not_seen).append((a, b))
    return seen, not_seen


def _side_by_side(a, b) -> bool:
    """Whether two recorded neighbour lanes run side by side one way: their centre lines do not cross (Waymo
    records crossing lanes in intersections as neighbours too), and their directions at b's nearest vertex to
    a's middle and a's nearest vertex to that point the same side (positive dot product)."""
    if shapely.LineString(a.line).crosses(shapely.LineString(b.line)):
        return False
    pa, pb = np.asarray(a.line, dtype=float), np.asarray(b.line, dtype=float)
    mid = pa[len(pa) // 2]
    j = int(np.hypot(*(pb - mid).T).argmin())
    i = int(np.hypot(*(pa - pb[j]).T).argmin())
    da = pa[min(i + 1, len(pa) - 1)] - pa[max(i - 1, 0)]
    db = pb[min(j + 1, len(pb) - 1)] - pb[max(j - 1, 0)]
    return float(da @ db) > 0


def scenic_network(xodr: Path):
    """Scenic's road network of the file (no cache written)."""
    from scenic.domains.driving.roads import Network

    return Network.fromFile(str(xodr), useCache=False, writeCache=False)


def offset(xodr: Path) -> tuple[float, float]:
    o = ET.parse(xodr).getroot().find("header/offset")
    return float(o.get("x")), float(o.get("y"))


def centre_line_gaps(net, road: RoadMap, shift: tuple[float, float], step: float = 1.0) -> dict[str, float]:
    """Each Scenic lane (by its road's name) -> the largest distance from a point of its centre line, sampled
    every `step` metres, to the recorded centre line(s) it follows (shifted into the file's frame)."""
    out = {}
    for lane in net.lanes:
        names = recorded(lane)
        line = shapely.LineString(np.concatenate([np.asarray(road[n].line) for n in names]) - shift)
        pts = np.asarray([(p.x, p.y) if hasattr(p, "x") else tuple(p)[:2] for p in lane.centerline.points])
        scenic_line = shapely.LineString(pts)
        n = max(2, int(math.ceil(scenic_line.length / step)) + 1)
        samples = shapely.line_interpolate_point(scenic_line, np.linspace(0, scenic_line.length, n))
        out[SEP.join(names)] = float(shapely.distance(samples, line).max())
    return out


def kept_links(net, road: RoadMap) -> tuple[list[tuple[str, str]], list[tuple[str, str]]]:
    """The recorded successor links (a, b) between lanes of the map, split into those Scenic's network keeps (b
    follows a: as a's lane's successor, in one connecting road, or as a junction maneuver's connecting or end
    lane) and those it does not."""
    follows = set()
    for lane in net.lanes:
        names = recorded(lane)
        follows.update(zip(names, names[1:]))
        if lane._successor is not None:
            follows.add((names[-1], recorded(lane._successor)[0]))
        for m in lane.maneuvers:  # a maneuver of a lane that is itself a connecting road's has no connecting lane
            via = recorded(m.connectingLane) if m.connectingLane is not None else names
            follows.add((names[-1], via[0]))
            follows.add((via[-1], recorded(m.endLane)[0]))
    kept, lost = [], []
    for f in road.lanes:
        for s in f.successors:
            (kept if (f.feature_id, s) in follows else lost).append((f.feature_id, s))
    return kept, lost


def reference_pose(road, s: float) -> tuple[np.ndarray, np.ndarray]:
    """The point and unit direction at s of the reference line of a road element of an .xodr (its line
    geometries), read from the XML alone."""
    geoms = road.findall("planView/geometry")
    g = max((g for g in geoms if float(g.get("s")) <= s + 1e-9), key=lambda g: float(g.get("s")))
    h = float(g.get("hdg"))
    d = np.array([math.cos(h), math.sin(h)])
    return np.array([float(g.get("x")), float(g.get("y"))]) + (s - float(g.get("s"))) * d, d


def asam_issues(path: Path) -> list[tuple[str, str, str]]:
    """Every issue ASAM's checker bundle for the file's format raises (checker, level, what), run in process as
    its command (qc_opendrive / qc_openscenario -c CONFIG) runs it; and the checkers that did not complete."""
    pytest.importorskip("qc_baselib")
    from qc_baselib import Configuration, Result, StatusType

    if path.suffix == ".xosc":
        import qc_openscenario.main as bundle
        name = "xoscBundle"
    else:
        import qc_opendrive.main as bundle
        name = "xodrBundle"
    logging.disable(logging.INFO)
    config = Configuration()
    config.set_config_param("InputFile", str(path))
    config.register_checker_bundle(name)
    result = Result()
    result.register_checker_bundle(name=name, description="", version="", summary="")
    bundle.run_checks(config, result)
    logging.disable(logging.NOTSET)
    out = []
    for checker in result.get_checker_results(name):
        out += [(checker.checker_id, str(i.level), " ".join(loc.description for loc in i.locations))
                for i in checker.issues]
        # a checker skipped for want of a precondition would hide issues; skipped by version is fine (1.8 only)
        if checker.status != StatusType.COMPLETED and "Version" not in (checker.summary or ""):
            out.append((checker.checker_id, str(checker.status), checker.summary))
    return out
