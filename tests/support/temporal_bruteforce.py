"""An independent reference for temporal patterns (docs/dsl.md, "Temporal patterns"): plain loops over each
scene's frames, straight from the definition, sharing nothing with pipeline.query.temporal's windows.

For every injective binding of the variables to the scene's tracks: a step holds at a frame when every variable of
the step is in the frame, the checker accepts the step's statements there (tests.support.query_bruteforce, on
the frame cut to ego and the bound entities, each entity with its map's lane graph for the lane clauses) and each
behaviour of a variable's track or of ego holds (a loop over the track's, or ego's, frames within the window); then every pair (a, b) of positions is tried as a step's interval: all frames a..b hold the step, it lasts
t(b) - t(a) >= its least duration, and a follows an end q of the previous step (q < a, t(a) - t(q) <= within).
The pattern matches at frame b when b ends such an interval of the last step."""

from __future__ import annotations

import itertools
import math
from dataclasses import replace

import pandas as pd

from frames.rows import frame_to_scene
from synth.config import SynthConfig
from synth.parts.motion import SPEED_EPS
from synth.patterns.temporal import (
    LANE_CHANGE_WINDOW_US,
    MOVING_SPEED,
    SPEED_CHANGE,
    SPEED_CHANGE_WINDOW_US,
    STOP_WINDOW_US,
    TURN_ANGLE,
    TURN_WINDOW_US,
    TemporalPattern,
    turn_of,
)
from synth.road.lane_relations import LaneGraph
from synth.road.roadmap import RoadMap
from synth.scene import Scene
from tests.support.query_bruteforce import brute_matches

EGO = ("ego",)  # ego's key among a frame's rows (never a track id, which is a string)


def _turning(name: str, track, p: int, frames: list[dict]) -> bool:
    """Some row of the track with t(p) - 3 s <= t < t(p), both headings in the world finite, turned by >= 30 deg
    to the left (counter-clockwise) or right: the signed turn of each pair, from the definition."""
    now, t = frames[p]["world"].get(track), frames[p]["t"]
    if now is None or not math.isfinite(now) or t is None:
        return False
    for f in frames:
        before = f["world"].get(track)
        if track in f["rows"] and f["t"] is not None and t - TURN_WINDOW_US <= f["t"] < t \
                and before is not None and math.isfinite(before):
            turn = turn_of(before, now)
            if (turn >= TURN_ANGLE) if name == "turning left" else (turn <= -TURN_ANGLE):
                return True
    return False


def _changing_lanes(track, p: int, frames: list[dict], graphs: dict[str, LaneGraph]) -> bool:
    """The track's lane at p is on the chain of the left or right neighbour of its lane at some row with
    t(p) - 3 s <= t < t(p), both rows in a lane of the same map: `in lane left / right of` its earlier self."""
    now, t = frames[p]["lane"].get(track), frames[p]["t"]
    if now is None or now[1] is None or t is None:
        return False
    for f in frames:
        before = f["lane"].get(track)
        if f["t"] is not None and t - LANE_CHANGE_WINDOW_US <= f["t"] < t and before is not None \
                and before[1] is not None and before[0] == now[0] and before[0] in graphs:
            graph = graphs[before[0]]
            if now[1] in graph.related(before[1], "left") | graph.related(before[1], "right"):
                return True
    return False


def _behaviour(name: str, track, p: int, frames: list[dict], config: SynthConfig, graphs) -> bool:
    if name in ("turning left", "turning right"):
        return _turning(name, track, p, frames)
    if name == "changing lanes":
        return _changing_lanes(track, p, frames, graphs)
    now, t = frames[p]["rows"][track].speed, frames[p]["t"]
    if now is None:
        return False
    window = STOP_WINDOW_US if name == "stopping" else SPEED_CHANGE_WINDOW_US
    before = [f["rows"][track].speed for f in frames
              if track in f["rows"] and t - window <= f["t"] < t and f["rows"][track].speed is not None]
    if name == "accelerating":
        return any(now - v >= SPEED_CHANGE for v in before)
    if name == "braking":
        return any(v - now >= SPEED_CHANGE for v in before)
    return now <= config.v_stop + SPEED_EPS and any(v >= MOVING_SPEED for v in before)


def _given(v):
    return None if v is None or (isinstance(v, float) and math.isnan(v)) else v


def _frame(rows: pd.DataFrame, graphs: dict[str, LaneGraph]) -> dict:
    """A frame as the loop reads it: its timestamp, ego and its entities by track (one box per track), each with
    its map's lane graph (the lane clauses' relations); per track, and for ego (key EGO), its row, its heading in
    the world (map_heading) and its (map, lane), where the frames carry them."""
    scene = frame_to_scene(rows)
    keys = [EGO if is_ego else track for track, is_ego in zip(rows.track_id, rows.is_ego)]
    maps = list(rows.map_id) if "map_id" in rows else [None] * len(rows)
    entities = [replace(e, lane_graph=graphs.get(_given(m))) for e, m in zip(scene.entities, maps)]
    by_key = {}
    for e, key in zip(entities, keys):
        assert key not in by_key, "the reference takes one box per track and frame"
        by_key[key] = e
    t = rows.timestamp_us.iloc[0]
    world = {}  # each track's heading in the world (map_heading), where the frames carry one
    if "map_heading" in rows:
        world = {key: float(h) for key, h in zip(keys, rows.map_heading) if _given(h) is not None}
    lane = {}
    if "lane" in rows:
        lane = {key: (_given(m), _given(ln)) for key, m, ln in zip(keys, maps, rows.lane)}
    return {"t": None if pd.isna(t) else int(t), "ego": by_key[EGO], "rows": by_key,
            "tracks": {k: e for k, e in by_key.items() if k != EGO}, "world": world, "lane": lane}


def prepare(frames: pd.DataFrame, roads: list[RoadMap] = ()) -> tuple[dict, list[tuple[list, list[dict]]]]:
    """The maps' lane graphs and each scene's frames in time order as the loop reads them (ids, frames): what every
    pattern over the same frames shares, so a test of many patterns may build it once."""
    graphs = {road.map_id: LaneGraph(road) for road in roads}
    order = {fid: k for k, fid in enumerate(dict.fromkeys(frames.frame_id))}
    scenes = []
    for _, rows in frames.groupby("scene", sort=False):
        by_frame = {fid: f for fid, f in rows.groupby("frame_id", sort=False)}
        fids = sorted(by_frame, key=lambda f: (int(by_frame[f].frame_index.iloc[0]), order[f]))
        scenes.append((fids, [_frame(by_frame[f], graphs) for f in fids]))
    return graphs, scenes


def brute_temporal(frames: pd.DataFrame | None, pattern: TemporalPattern, config: SynthConfig | None = None,
                   roads: list[RoadMap] = (), prepared=None) -> dict:
    """{frame_id: {tracks tuple (in pattern.names order), ...}} of the frames where the pattern matches; `roads`:
    the maps the frames name (for lane clauses and changing lanes); `prepared`: `prepare(frames, roads)` made once
    (then `frames` and `roads` are not read)."""
    config = config or SynthConfig()
    graphs, scenes = prepared if prepared is not None else prepare(frames, roads)
    names = pattern.names
    out: dict[str, set] = {}
    for fids, scene_frames in scenes:
        ts = [f["t"] for f in scene_frames]
        tracks = sorted({t for f in scene_frames for t in f["tracks"]})
        for chosen in itertools.permutations(tracks, len(names)):
            bound = dict(zip(names, chosen))
            ends: set[int] = set()
            for k, step in enumerate(pattern.steps):
                holds = [_step_holds(step, bound, p, scene_frames, config, graphs) for p in range(len(scene_frames))]
                new = set()
                for a in range(len(scene_frames)):
                    if k and not any(q < a and (step.within_us is None or ts[a] - ts[q] <= step.within_us)
                                     for q in ends):
                        continue
                    for b in range(a, len(scene_frames)):
                        if not holds[b]:
                            break
                        if not step.for_at_least_us or ts[b] - ts[a] >= step.for_at_least_us:
                            new.add(b)
                ends = new
                if not ends:
                    break
            for b in ends:
                out.setdefault(fids[b], set()).add(chosen)
    return out


def _step_holds(step, bound, p: int, scene_frames: list[dict], config, graphs) -> bool:
    frame = scene_frames[p]
    if any(bound[n] not in frame["tracks"] for n in step.names):
        return False
    entities = [frame["tracks"][bound[n]] for n in step.names]
    scene = Scene("cut", (frame["ego"], *entities))
    if tuple(e.id for e in entities) not in set(brute_matches(step.pattern, scene, config)):
        return False
    return all(_behaviour(b, EGO if n == "ego" else bound[n], p, scene_frames, config, graphs) for n, b in step.behaviours)
