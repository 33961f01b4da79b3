"""A Motion (pipeline/export/motion.py: a recorded clip, or a frame moved by its behaviours) as OpenSCENARIO 1.2
actions (docs/formats.md, "Exported clips"): per entity that moves, one ManeuverGroup of two maneuvers,

- its path: a FollowTrajectoryAction along a Polyline of its world positions at the steps it is there (each
  vertex with its time), following mode `follow` and no time reference, so the path is lateral only;
- its pace: a speed profile, one AbsoluteSpeedAction per step over which its speed changes, from the step's start
  time, linear over the step's duration to the speed at its end (a step whose speed does not change adds none:
  the speed is held),

both starting at its first step; an entity first seen later is added at its first pose just before it (and
removed in Init: pipeline/export/openscenario.py), one that leaves before the end removed just after its last. The
lane changes are in the path (a LaneChangeAction besides it would be a second lateral action on the entity, which
OpenSCENARIO resolves by stopping the first), and so are turns. Static objects (MiscObject) keep their first pose.
"""

from __future__ import annotations

import numpy as np

from pipeline.export.motion import Motion, Trajectory

TIME_SLACK = 1e-9  # seconds: a speed piece starts once the simulation time passes its step's start
LEAVE_S = 1e-3  # seconds after its last step an entity that leaves the clip is removed (it reaches that pose first)
ARRIVE_S = 1e-3  # seconds before its first step an entity first seen later is added (its path starts at its step)


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


def maneuver_group(t: Trajectory, times: np.ndarray, offset: tuple[float, float], movable: bool):
    """The entity's ManeuverGroup: its path and pace when it is movable and moves (two or more steps there, a
    change of place, yaw or speed), its arrival when it is first there after the start (AddEntityAction at its
    first pose: it is not in the scenario before) and its removal when it leaves before the end
    (DeleteEntityAction just after its last step); None when none of these applies."""
    from scenariogeneration import xosc

    where = world_positions(t, offset)
    ks = np.flatnonzero(t.valid)
    first, last = int(ks[0]), int(ks[-1])
    start = float(times[first])
    maneuvers = []
    if first > 0:
        _, x, y, h = where[0]
        comes = xosc.Maneuver(f"{t.id} arrival")
        comes.add_event(_event(f"{t.id} arrives", start - ARRIVE_S,
                               xosc.AddEntityAction(t.id, xosc.WorldPosition(x, y, 0, h))))
        maneuvers.append(comes)
    if movable and len(where) >= 2 and t.moves:
        shape = xosc.Polyline([float(times[k]) for k, *_ in where],
                              [xosc.WorldPosition(x, y, 0, h) for _, x, y, h in where])
        path = xosc.Trajectory(f"{t.id} path", False)
        path.add_shape(shape)
        follow = xosc.Maneuver(f"{t.id} path")
        follow.add_event(_event(f"{t.id} path", start,
                                xosc.FollowTrajectoryAction(path, xosc.FollowingMode.follow)))
        maneuvers.append(follow)
        pace = xosc.Maneuver(f"{t.id} pace")
        if first > 0:  # it arrives standing: its first speed at once
            pace.add_event(_speed_event(t.id, 0, start, 0.0, float(t.speed[first])))
        for n, (t0, dt, v) in enumerate(speed_pieces(t, times), start=1):
            pace.add_event(_speed_event(t.id, n, t0, dt, v))
        if pace.events:
            maneuvers.append(pace)
    if last < t.valid.size - 1:  # it leaves the clip: removed just after its last step, not driven on
        goes = xosc.Maneuver(f"{t.id} departure")
        goes.add_event(_event(f"{t.id} leaves", float(times[last]) + LEAVE_S, xosc.DeleteEntityAction(t.id)))
        maneuvers.append(goes)
    if not maneuvers:
        return None
    group = xosc.ManeuverGroup(f"{t.id} motion")
    group.add_actor(t.id)
    for m in maneuvers:
        group.add_maneuver(m)
    return group


def _event(name: str, at: float, action):
    from scenariogeneration import xosc

    event = xosc.Event(name, xosc.Priority.parallel)
    event.add_action(name, action)
    event.add_trigger(_at(at, f"{name} at {at:g} s"))
    return event


def _speed_event(eid: str, n: int, t0: float, dt: float, v: float):
    from scenariogeneration import xosc

    shape = xosc.DynamicsShapes.linear if dt > 0 else xosc.DynamicsShapes.step
    return _event(f"{eid} speed {n}", t0, xosc.AbsoluteSpeedAction(
        v, xosc.TransitionDynamics(shape, xosc.DynamicsDimension.time, dt)))


def story(motion: Motion, movable: set[str], offset: tuple[float, float]):
    """The Story of every entity's ManeuverGroup (None when no entity moves, arrives or leaves)."""
    from scenariogeneration import xosc

    act = xosc.Act("motion", _at(0.0, "start"))
    groups = [g for t in motion.trajectories
              if (g := maneuver_group(t, motion.times, offset, t.id in movable)) is not None]
    if not groups:
        return None
    for g in groups:
        act.add_maneuver_group(g)
    out = xosc.Story(f"{motion.how} motion")
    out.add_act(act)
    return out
