"""What an exported scenario's entities do over its steps, in the world: one `Trajectory` per entity (positions,
yaws, speeds, and whether it is there at each step), the `Motion` of a scenario (its step times and every
entity's trajectory, ego first). Both targets write a Motion (pipeline/export/scenarionet.py: every step of every
track; pipeline/export/trajectory_story.py: OpenSCENARIO actions), whichever way it was made:

- `straight`: one frame, every entity on at its speed along its heading for `--steps` steps of 0.1 s (the
  default: today's behaviour without a behaviour program);
- `recorded`: a clip, every frame's world poses and speeds at the clip's own times (docs/formats.md, "Exported
  clips");
- pipeline/export/behaviour_motion.py: one frame moved by a clip program's behaviours (`--program P.json`).

Values only: no I/O."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from synth.scene import Scene
from synth.world import WorldPose, in_world

STEP_S = 0.1  # ScenarioNet's 10 Hz: the step of --steps
STRAIGHT, RECORDED, BEHAVIOURS = "straight", "recorded", "behaviours"  # how a Motion was made


@dataclass(frozen=True, eq=False)
class Trajectory:
    """An entity over a scenario's steps, in the world: centre x, y (metres), yaw (radians CCW from +x), speed
    (m/s along the yaw; 0 where the scene has none), `valid` (false where the entity is not there: its other
    values are then 0), its box (the recorded one, else its type's typical size)."""

    id: str
    type: str
    length: float
    width: float
    x: np.ndarray
    y: np.ndarray
    yaw: np.ndarray
    speed: np.ndarray
    valid: np.ndarray

    @property
    def first(self) -> int:
        """The first step it is there."""
        return int(np.argmax(self.valid))

    @property
    def moves(self) -> bool:
        """Does it change place or yaw between the steps it is there (or have a speed)?"""
        v = self.valid
        return bool(np.ptp(self.x[v]) > 0 or np.ptp(self.y[v]) > 0 or np.ptp(self.yaw[v]) > 0 or self.speed[v].any())


@dataclass(frozen=True, eq=False)
class Motion:
    """A scenario's step times (seconds from its start, increasing) and its entities' trajectories (ego first);
    `how` it was made (STRAIGHT, RECORDED, BEHAVIOURS)."""

    times: np.ndarray
    trajectories: tuple[Trajectory, ...]
    how: str

    @property
    def steps(self) -> int:
        return len(self.times)

    @property
    def end(self) -> float:
        """When its scenario stops: a clip at its last frame, --steps T after T steps of 0.1 s."""
        return float(self.times[-1]) if self.how == RECORDED else self.steps * STEP_S


def steps_of(n: int) -> np.ndarray:
    return np.arange(n, dtype=float) * STEP_S


def straight(scene: Scene, world: WorldPose, steps: int) -> Motion:
    """One scene over `steps` steps of 0.1 s: every entity on at its speed along its heading (1: the instant)."""
    t = steps_of(steps)
    out = []
    for e in scene.entities:
        w = in_world(world, e)
        speed = w.speed or 0.0  # no speed: standing (MetaDrive needs a velocity)
        vx, vy = speed * math.cos(w.yaw), speed * math.sin(w.yaw)
        x, y = w.x + vx * t, w.y + vy * t
        x[0], y[0] = w.x, w.y  # the instant itself exactly, not x + 0.0 * vx
        out.append(Trajectory(e.id, e.type, w.length, w.width, x, y, np.full(steps, w.yaw), np.full(steps, speed),
                              np.ones(steps, dtype=bool)))
    return Motion(t, tuple(out), STRAIGHT)


def recorded(scenes: Sequence[Scene], times: Sequence[float]) -> Motion:
    """A clip (frames of one scene in time order, each with its world pose; `times` seconds after the first) as
    every entity's recorded trajectory: ego first, the others in order of first appearance, each valid in the
    frames it is in; its box the first frame's it is in."""
    n = len(scenes)
    order: dict[str, int] = {"ego": 0}
    for s in scenes:
        for e in s.others:
            order.setdefault(e.id, len(order))
    cols = {k: np.zeros((len(order), n)) for k in ("x", "y", "yaw", "speed")}
    valid = np.zeros((len(order), n), dtype=bool)
    first: dict[str, object] = {}
    for k, s in enumerate(scenes):
        for e in s.entities:
            w = in_world(s.world, e)
            i = order[e.id]
            first.setdefault(e.id, w)
            cols["x"][i, k], cols["y"][i, k], cols["yaw"][i, k] = w.x, w.y, w.yaw
            cols["speed"][i, k] = w.speed or 0.0
            valid[i, k] = True
    out = []
    for eid, i in order.items():
        w = first[eid]
        out.append(Trajectory(eid, w.type, w.length, w.width, cols["x"][i], cols["y"][i], cols["yaw"][i],
                              cols["speed"][i], valid[i]))
    return Motion(np.asarray(times, dtype=float), tuple(out), RECORDED)
