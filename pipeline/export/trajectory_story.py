"""A Motion (pipeline/export/motion.py: a recorded clip, or a frame moved by its behaviours) as OpenSCENARIO 1.2
actions (docs/formats.md, "Exported clips"): per entity that moves, one ManeuverGroup of two maneuvers,

- its path: a FollowTrajectoryAction along a Polyline of its world positions at the steps it is there (each
  vertex with its time), following mode `follow` and no time reference, so the path is lateral only;
- its pace: a speed profile, one AbsoluteSpeedAction per step over which its speed changes, from the step's start
  time, linear over the step's duration to the speed at its end (a step whose speed does not change adds none:
  the speed is held),

both starting at its first step (an entity first seen later stands still at its first pose until then). The
lane changes are in the path (a LaneChangeAction besides it would be a second lateral action on the entity, which
OpenSCENARIO resolves by stopping the first), and so are turns. Static objects (MiscObject) keep their first pose.
"""

from __future__ import annotations

import numpy as np

from pipeline.export.motion import Motion, Trajectory

TIME_SLACK = 1e-9  # seconds: a speed piece starts once the simulation time passes its step's start


def world_positions(t: Trajectory, offset: tuple[float, float]) -> list[tuple[int, float, float, float]]:
    """(step, x, y, yaw) at each step the entity is there, x, y in the road's recentred frame."""
    return [(k, float(t.x[k]) - offset[0], float(t.y[k]) - offset[1], float(t.yaw[k]))
            for k in np.flatnonzero(t.valid)]


def speed_pieces(t: Trajectory, times: np.ndarray) -> list[tuple[float, float, float]]:
    """(start time, duration, speed at its end) of every step between two steps the entity is there over which its
    speed changes (a gap in its track is one piece from the step before it to the step after)."""
    ks = np.flatnonzero(t.valid)
    return [(float(times[a]), float(times[b] - times[a]), float(t.speed[b]))
            for a, b in zip(ks, ks[1:]) if t.speed[b] != t.speed[a]]


def _at(time: float, name: str):
    from scenariogeneration import xosc

    return xosc.ValueTrigger(name, 0, xosc.ConditionEdge.none,
                             xosc.SimulationTimeCondition(max(0.0, time - TIME_SLACK), xosc.Rule.greaterThan))


def maneuver_group(t: Trajectory, times: np.ndarray, offset: tuple[float, float]):
    """The entity's path and pace as a ManeuverGroup, or None when it stays put (fewer than two steps there, or
    no change of place, yaw or speed)."""
    from scenariogeneration import xosc

    where = world_positions(t, offset)
    if len(where) < 2 or not t.moves:
        return None
    start = float(times[where[0][0]])
    shape = xosc.Polyline([float(times[k]) for k, *_ in where], [xosc.WorldPosition(x, y, 0, h) for _, x, y, h in where])
    path = xosc.Trajectory(f"{t.id} path", False)
    path.add_shape(shape)
    follow = xosc.Event(f"{t.id} path", xosc.Priority.parallel)
    follow.add_action(f"{t.id} follows its path", xosc.FollowTrajectoryAction(path, xosc.FollowingMode.follow))
    follow.add_trigger(_at(start, f"{t.id} appears"))
    path_maneuver = xosc.Maneuver(f"{t.id} path")
    path_maneuver.add_event(follow)
    pace = xosc.Maneuver(f"{t.id} pace")
    if start > 0:  # it stood still at its first pose until now: its first speed at once
        pace.add_event(_speed_event(t.id, 0, start, 0.0, float(t.speed[where[0][0]])))
    for n, (t0, dt, v) in enumerate(speed_pieces(t, times), start=1):
        pace.add_event(_speed_event(t.id, n, t0, dt, v))
    group = xosc.ManeuverGroup(f"{t.id} motion")
    group.add_actor(t.id)
    group.add_maneuver(path_maneuver)
    if pace.events:
        group.add_maneuver(pace)
    return group


def _speed_event(eid: str, n: int, t0: float, dt: float, v: float):
    from scenariogeneration import xosc

    shape = xosc.DynamicsShapes.linear if dt > 0 else xosc.DynamicsShapes.step
    event = xosc.Event(f"{eid} speed {n}", xosc.Priority.parallel)
    event.add_action(f"{eid} speed {n}", xosc.AbsoluteSpeedAction(
        v, xosc.TransitionDynamics(shape, xosc.DynamicsDimension.time, dt)))
    event.add_trigger(_at(t0, f"{eid} speed {n} at {t0:g} s"))
    return event


def story(motion: Motion, movable: set[str], offset: tuple[float, float]):
    """The Story of every movable entity's ManeuverGroup (None when none moves)."""
    from scenariogeneration import xosc

    act = xosc.Act("motion", _at(0.0, "start"))
    groups = [g for t in motion.trajectories if t.id in movable
              if (g := maneuver_group(t, motion.times, offset)) is not None]
    if not groups:
        return None
    for g in groups:
        act.add_maneuver_group(g)
    out = xosc.Story(f"{motion.how} motion")
    out.add_act(act)
    return out
