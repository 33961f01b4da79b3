"""A small Waymo scenario laid out as ScenarioNet's Waymo converter writes one, map included, for the tests that
must run without the real files (the Waymo licence keeps them out of the repository).

Written from reading scenarionet/converter/waymo/utils.py and type.py (metadriverse/scenarionet at cebcbe6):
`extract_center` (a lane: type, float32 polyline (N, 3), entry / exit lanes as ints, boundaries and neighbours as
dicts of strings), `extract_line` / `extract_edge` (type, polyline), `extract_crosswalk`, `extract_bump`,
`extract_driveway` (polygon), `extract_stop` (lane, position), `compute_width` with its `extract_width` and
`nearest_point` (a side without boundary copies the other side; both missing stay 0), and `extract_tracks`. What
the real files hold beyond that is imitated too: a one-point lane and road edge, and a lane of Waymo's undefined
type written as UNKNOWN (older conversions: type.py mapped lane type 0 to 'UNKNOWN'), without width, which another
lane names as its neighbour.

The road: a straight street along +x. Lane 101 (y = 0, eastbound) and 102 (y = 3.6, eastbound) with lane lines
between them; lane 103 (y = -3.6, westbound) without boundaries, so its width is 0 throughout; lane 104
(UNKNOWN, y = 7.2, eastbound), the left neighbour of 102; lane 106 continues 101 beyond x = 100; 101 also names
lane 999, outside the crop. A crosswalk across the street at x = 60.
"""

from __future__ import annotations

import numpy as np

from tests.support.scenarionet_layouts import as_waymo

SCENE = "wmsynthwaymo"  # as_waymo names it wm + the id given
STEPS = 30


def _line(x0: float, x1: float, y: float, step: float = 0.5) -> np.ndarray:
    """A float32 (N, 3) polyline from (x0, y) to (x1, y), a point every `step` metres (Waymo's lanes: 0.5 m)."""
    n = int(round(abs(x1 - x0) / step)) + 1
    xs = np.linspace(x0, x1, n)
    return np.stack([xs, np.full(n, y), np.zeros(n)], axis=1).astype("float32")


def _boundary(feature_id: str, start: int, end: int, kind: str) -> dict:
    """extract_boundaries: every value as a string."""
    return {"lane_start_index": str(start), "lane_end_index": str(end), "boundary_type": kind,
            "boundary_feature_id": str(feature_id)}


def _neighbour(feature_id: str, n: int, m: int) -> dict:
    """extract_neighbors: every value as a string, and the neighbour's boundaries."""
    return {"feature_id": str(feature_id), "self_start_index": "0", "self_end_index": str(n - 1),
            "neighbor_start_index": "0", "neighbor_end_index": str(m - 1), "boundaries": []}


def _lane(kind: str, polyline: np.ndarray, entry=(), exit_=(), left_b=(), right_b=(), left_n=(), right_n=()) -> dict:
    """extract_center."""
    return {"speed_limit_mph": 25.0, "speed_limit_kmh": 25.0 * 1.609344, "type": kind, "polyline": polyline,
            "interpolating": False, "entry_lanes": list(entry), "exit_lanes": list(exit_),
            "left_boundaries": list(left_b), "right_boundaries": list(right_b), "left_neighbor": list(left_n),
            "right_neighbor": list(right_n)}


def _nearest_point(point: np.ndarray, line: np.ndarray) -> int:
    dist = np.square(line - point)
    return int(np.argmin(np.sqrt(dist[:, 0] + dist[:, 1])))


def _extract_width(features: dict, polyline: np.ndarray, boundaries: list[dict]) -> np.ndarray:
    """converter/waymo/utils.py extract_width, as written there."""
    width = np.zeros(polyline.shape[0], dtype="float32")
    for b in boundaries:
        b = {k: int(v) if k != "boundary_type" else v for k, v in b.items()}
        line = features[str(b["boundary_feature_id"])]["polyline"][:, :2]
        start = _nearest_point(polyline[b["lane_start_index"]], line)
        seg_len = b["lane_end_index"] - b["lane_start_index"]
        end = min(start + seg_len, line.shape[0] - 1)
        length = min(end - start, seg_len) + 1
        mine = range(b["lane_start_index"], b["lane_start_index"] + length)
        theirs = range(start, start + length)
        dist = np.square(polyline[mine] - line[theirs])
        width[mine] = np.sqrt(dist[:, 0] + dist[:, 1])
    return width


def compute_width(features: dict) -> None:
    """converter/waymo/utils.py compute_width: only types with LANE in them (so not UNKNOWN) get a width."""
    for lane in features.values():
        if "LANE" not in lane["type"]:
            continue
        width = np.zeros((lane["polyline"].shape[0], 2), dtype="float32")
        width[:, 0] = _extract_width(features, lane["polyline"][:, :2], lane["left_boundaries"])
        width[:, 1] = _extract_width(features, lane["polyline"][:, :2], lane["right_boundaries"])
        width[width[:, 0] == 0, 0] = width[width[:, 0] == 0, 1]
        width[width[:, 1] == 0, 1] = width[width[:, 1] == 0, 0]
        lane["width"] = width


def waymo_map() -> dict:
    """The map_features of the street (module docstring), as the converter writes them."""
    lane101, lane102 = _line(0, 100, 0.0), _line(0, 100, 3.6)
    lane103, lane104, lane106 = _line(100, 0, -3.6), _line(0, 100, 7.2), _line(100, 150, 0.0)
    n = len(lane101)
    f: dict = {
        "201": {"type": "ROAD_LINE_BROKEN_SINGLE_WHITE", "polyline": _line(0, 100, 1.8)},
        "202": {"type": "ROAD_LINE_SOLID_DOUBLE_YELLOW", "polyline": _line(0, 100, -1.8)},
        "301": {"type": "ROAD_EDGE_BOUNDARY", "polyline": _line(0, 100, 9.0)},
        "302": {"type": "ROAD_EDGE_BOUNDARY", "polyline": _line(0, 100, -5.4)},
        "303": {"type": "ROAD_EDGE_BOUNDARY", "polyline": _line(20, 20, -5.4)},  # one point
        "203": {"type": "ROAD_LINE_SOLID_SINGLE_WHITE", "polyline": _line(0, 100, 5.4)},
        "101": _lane("LANE_SURFACE_STREET", lane101, entry=[], exit_=[106, 999],
                     left_b=[_boundary("201", 0, n - 1, "ROAD_LINE_BROKEN_SINGLE_WHITE")],
                     right_b=[_boundary("202", 0, n - 1, "ROAD_LINE_SOLID_DOUBLE_YELLOW")],
                     left_n=[_neighbour("102", n, n)]),
        "102": _lane("LANE_SURFACE_STREET", lane102,
                     left_b=[_boundary("203", 0, n - 1, "ROAD_LINE_SOLID_SINGLE_WHITE")],
                     right_b=[_boundary("201", 0, n - 1, "ROAD_LINE_BROKEN_SINGLE_WHITE")],
                     left_n=[_neighbour("104", n, n)], right_n=[_neighbour("101", n, n)]),
        "103": _lane("LANE_SURFACE_STREET", lane103),  # no boundary: width 0 throughout
        "104": _lane("UNKNOWN", lane104, right_n=[_neighbour("102", n, n)]),
        "105": _lane("LANE_SURFACE_STREET", _line(40, 40, 0.0), exit_=[101]),  # one point
        "106": _lane("LANE_SURFACE_STREET", lane106, entry=[101],
                     left_b=[_boundary("201", 0, len(lane106) - 1, "ROAD_LINE_BROKEN_SINGLE_WHITE")]),
        "401": {"type": "CROSSWALK", "polygon": np.array([[58, -6, 0], [62, -6, 0], [62, 9, 0], [58, 9, 0]],
                                                         dtype="float32")},
        "402": {"type": "DRIVEWAY", "polygon": np.array([[30, 9, 0], [34, 9, 0], [34, 15, 0]], dtype="float32")},
        "403": {"type": "STOP_SIGN", "lane": [101], "position": np.array([99, -2, 0], dtype="float32")},
        "404": {"type": "SPEED_BUMP", "polygon": np.array([[80, -2, 0], [81, -2, 0], [81, 2, 0], [80, 2, 0]],
                                                          dtype="float32")},
    }
    compute_width(f)
    return f


def _track(xs: np.ndarray, y: float, heading: float, kind: str, length: float = 4.5, width: float = 2.0) -> dict:
    steps = len(xs)
    speed = abs(float(xs[1] - xs[0])) * 10 if steps > 1 else 0.0
    return {"type": kind, "state": {
        "position": np.stack([xs, np.full(steps, y), np.zeros(steps)], axis=1),
        "heading": np.full(steps, heading), "velocity": np.tile([speed * np.cos(heading), speed * np.sin(heading)],
                                                                (steps, 1)),
        "valid": np.ones(steps, dtype=bool), "length": np.full(steps, length), "width": np.full(steps, width),
        "height": np.full(steps, 1.5)}}


def waymo_scenario() -> dict:
    """The street with four road users over STEPS steps at 10 Hz, as the converter writes a scenario: ego on 101,
    a car on 102 and one on 104 (the UNKNOWN lane), a car coming the other way on 103, a pedestrian crossing."""
    t = np.arange(STEPS) / 10
    tracks = {
        "ego": _track(10 + 8 * t, 0.0, 0.0, "VEHICLE"),
        "car_a": _track(20 + 9 * t, 3.6, 0.0, "VEHICLE"),
        "car_b": _track(15 + 7 * t, 7.2, 0.0, "VEHICLE"),
        "car_c": _track(70 - 10 * t, -3.6, np.pi, "VEHICLE"),
        "walker": _track(np.full(STEPS, 60.0), 0.0, np.pi / 2, "PEDESTRIAN", 0.6, 0.6),
    }
    tracks["walker"]["state"]["position"][:, 1] = -5 + 0.5 * np.arange(STEPS)
    sd = as_waymo({"id": "synthwaymo", "length": STEPS, "tracks": tracks, "metadata": {"sdc_id": "ego"}})
    sd["map_features"] = waymo_map()
    return sd
