"""An independent reference for temporal patterns (docs/dsl.md, "Temporal patterns"): plain loops over each
scene's frames, straight from the definition, sharing nothing with pipeline.query.temporal's windows.

For every injective binding of the variables to the scene's tracks: a step holds at a frame when every variable of
the step is in the frame, the checker accepts the step's statements there (tests.support.query_bruteforce, on
the frame cut to ego and the bound entities) and each behaviour holds (a loop over the track's frames within the
window); then every pair (a, b) of positions is tried as a step's interval: all frames a..b hold the step, it lasts
t(b) - t(a) >= its least duration, and a follows an end q of the previous step (q < a, t(a) - t(q) <= within).
The pattern matches at frame b when b ends such an interval of the last step."""

from __future__ import annotations

import itertools
import math

import pandas as pd

from extractors.frames import frame_to_scene
from synth.config import SynthConfig
from synth.parts.motion import SPEED_EPS
from synth.scene import Scene
from synth.temporal import (
    MOVING_SPEED,
    SPEED_CHANGE,
    SPEED_CHANGE_WINDOW_US,
    STOP_WINDOW_US,
    TURN_ANGLE,
    TURN_WINDOW_US,
    TemporalPattern,
    turn_of,
)
from tests.support.query_bruteforce import brute_matches


def _turning(name: str, track: str, p: int, frames: list[dict]) -> bool:
    """Some row of the track with t(p) - 3 s <= t < t(p), both headings in the world finite, turned by >= 30 deg
    to the left (counter-clockwise) or right: the signed turn of each pair, from the definition."""
    now, t = frames[p]["world"].get(track), frames[p]["t"]
    if now is None or not math.isfinite(now) or t is None:
        return False
    for f in frames:
        before = f["world"].get(track)
        if track in f["tracks"] and f["t"] is not None and t - TURN_WINDOW_US <= f["t"] < t \
                and before is not None and math.isfinite(before):
            turn = turn_of(before, now)
            if (turn >= TURN_ANGLE) if name == "turning left" else (turn <= -TURN_ANGLE):
                return True
    return False


def _behaviour(name: str, track: str, p: int, frames: list[dict], config: SynthConfig) -> bool:
    if name in ("turning left", "turning right"):
        return _turning(name, track, p, frames)
    now, t = frames[p]["tracks"][track].speed, frames[p]["t"]
    if now is None:
        return False
    window = STOP_WINDOW_US if name == "stopping" else SPEED_CHANGE_WINDOW_US
    before = [f["tracks"][track].speed for f in frames
              if track in f["tracks"] and t - window <= f["t"] < t and f["tracks"][track].speed is not None]
    if name == "accelerating":
        return any(now - v >= SPEED_CHANGE for v in before)
    if name == "braking":
        return any(v - now >= SPEED_CHANGE for v in before)
    return now <= config.v_stop + SPEED_EPS and any(v >= MOVING_SPEED for v in before)


def _frame(rows: pd.DataFrame) -> dict:
    """A frame as the loop reads it: its timestamp, ego and its entities by track (one box per track)."""
    scene = frame_to_scene(rows)
    by_track = {}
    for e, track, is_ego in zip(scene.entities, rows.track_id, rows.is_ego):
        if not is_ego:
            assert track not in by_track, "the reference takes one box per track and frame"
            by_track[track] = e
    t = rows.timestamp_us.iloc[0]
    world = {}  # each track's heading in the world (map_heading), where the frames carry one
    if "map_heading" in rows:
        world = {track: float(h) for track, h, is_ego in zip(rows.track_id, rows.map_heading, rows.is_ego)
                 if not is_ego and h is not None and not pd.isna(h)}
    return {"t": None if pd.isna(t) else int(t), "ego": scene.ego, "tracks": by_track, "world": world}


def brute_temporal(frames: pd.DataFrame, pattern: TemporalPattern, config: SynthConfig | None = None) -> dict:
    """{frame_id: {tracks tuple (in pattern.names order), ...}} of the frames where the pattern matches."""
    config = config or SynthConfig()
    order = {fid: k for k, fid in enumerate(dict.fromkeys(frames.frame_id))}
    names = pattern.names
    out: dict[str, set] = {}
    for _, rows in frames.groupby("scene", sort=False):
        by_frame = {fid: f for fid, f in rows.groupby("frame_id", sort=False)}
        fids = sorted(by_frame, key=lambda f: (int(by_frame[f].frame_index.iloc[0]), order[f]))
        scene_frames = [_frame(by_frame[f]) for f in fids]
        ts = [f["t"] for f in scene_frames]
        tracks = sorted({t for f in scene_frames for t in f["tracks"]})
        for chosen in itertools.permutations(tracks, len(names)):
            bound = dict(zip(names, chosen))
            ends: set[int] = set()
            for k, step in enumerate(pattern.steps):
                holds = [_step_holds(step, bound, p, scene_frames, config) for p in range(len(scene_frames))]
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


def _step_holds(step, bound, p: int, scene_frames: list[dict], config) -> bool:
    frame = scene_frames[p]
    if any(bound[n] not in frame["tracks"] for n in step.names):
        return False
    entities = [frame["tracks"][bound[n]] for n in step.names]
    scene = Scene("cut", (frame["ego"], *entities))
    if tuple(e.id for e in entities) not in set(brute_matches(step.pattern, scene, config)):
        return False
    return all(_behaviour(b, bound[n], p, scene_frames, config) for n, b in step.behaviours)
