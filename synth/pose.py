"""The one world pose transform: a rigid motion of the plane (SE2) between a frame and the frame it sits in.

Every place that moves points or headings between a source's world and a frame does it here: the extractors
(world -> ego: extractors.base.global_to_ego; a box in the vehicle's frame -> the world: Argoverse 2's city
places, the log readers' ground positions), the road (a map in a scene's ego frame: synth.road.roadmap.in_ego_frame)
and the way back (synth.world.WorldPose, the exports, a window's roads).

One heading convention at the boundary: a pose is given by where its frame's origin is (x, y, in the outer
frame's units) and by its yaw, the direction its frame calls forward, in radians counter-clockwise from the outer
frame's forward axis; headings in and out are radians counter-clockwise from their frame's forward axis, so a
heading moves out by adding the yaw and in by subtracting it (`heading_out`, `heading_in`). A world frame's
forward axis is its +x. Degrees, [0, 360) and [-pi, pi) are the callers' to apply, at their edges.

Two layouts of a frame's axes: a body frame (`SE2.body`: +x forward, +y left: ROS base_link, Argoverse 2's
egovehicle frame, a world) and the ego frame of scenes and frames (`SE2.ego`: +x right, +y forward). The ego
layout is the body layout turned a quarter turn clockwise; its cosine and sine are the body's swapped and negated,
exactly (never cos(yaw - pi/2), which rounds), so that every formula this replaced gives the same bits
(tests/synth/test_pose.py compares them). cos and sin are computed once per pose: with `math` for a single pose,
with numpy for arrays of poses (one per row, as Argoverse 2's boxes have), as the places this replaced did.

Values only: numbers or numpy arrays in, the same out, elementwise.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

# The ego layout's +x (right) is a quarter turn clockwise from its forward axis; a body layout's +x is forward.
BODY, EGO = 0, 3  # quarter turns counter-clockwise from forward to the frame's +x, modulo 4


def _cos_sin(yaw: Any) -> tuple[Any, Any]:
    if np.ndim(yaw) == 0:
        return math.cos(yaw), math.sin(yaw)
    return np.cos(yaw), np.sin(yaw)


def _turned(c: Any, s: Any, quarters: int) -> tuple[Any, Any]:
    """(cos, sin) of an angle plus `quarters` quarter turns, exactly (swaps and negations only)."""
    return ((c, s), (-s, c), (-c, -s), (s, -c))[quarters % 4]


@dataclass(frozen=True)
class SE2:
    """A frame placed in an outer frame: origin (x, y), forward axis at `yaw` radians CCW from the outer frame's
    forward axis, its +x axis `quarters` quarter turns CCW from its forward axis less the outer frame's (BODY: 0,
    EGO: 3). Points: `apply` takes the frame's points out, `local` brings the outer frame's in (its inverse,
    without forming one: the arithmetic of the formulas it replaced). x, y, yaw may be numpy arrays (one pose per
    element)."""

    x: Any
    y: Any
    yaw: Any
    quarters: int = BODY
    c: Any = field(init=False, repr=False, compare=False)  # cos and sin of the +x axis's turn, computed once
    s: Any = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        c, s = _turned(*_cos_sin(self.yaw), self.quarters)
        object.__setattr__(self, "c", c)
        object.__setattr__(self, "s", s)

    @classmethod
    def body(cls, x: Any, y: Any, yaw: Any) -> SE2:
        """A body frame (+x forward, +y left) heading `yaw` in a world (or another body frame)."""
        return cls(x, y, yaw, BODY)

    @classmethod
    def ego(cls, x: Any, y: Any, yaw: Any) -> SE2:
        """The ego frame (+x right, +y forward) of a pose heading `yaw` in a world."""
        return cls(x, y, yaw, EGO)

    @classmethod
    def identity(cls) -> SE2:
        return cls(0.0, 0.0, 0.0, BODY)

    def apply(self, px: Any, py: Any) -> tuple[Any, Any]:
        """Points of this frame in the outer frame."""
        return self.x + self.c * px - self.s * py, self.y + self.s * px + self.c * py

    def local(self, wx: Any, wy: Any) -> tuple[Any, Any]:
        """Points of the outer frame in this frame (the inverse of apply)."""
        dx, dy = wx - self.x, wy - self.y
        return self.c * dx + self.s * dy, -self.s * dx + self.c * dy

    def heading_out(self, heading: Any) -> Any:
        """A heading of this frame (radians CCW from its forward axis) in the outer frame."""
        return heading + self.yaw

    def heading_in(self, heading: Any) -> Any:
        """A heading of the outer frame (radians CCW from its forward axis) in this frame."""
        return heading - self.yaw

    def compose(self, inner: SE2) -> SE2:
        """The frame `inner` (placed in this frame) placed in this frame's outer frame: apply of the result is
        self.apply after inner.apply."""
        x, y = self.apply(inner.x, inner.y)
        return SE2(x, y, self.yaw + inner.yaw, (self.quarters + inner.quarters) % 4)

    def inverse(self) -> SE2:
        """The outer frame placed in this one."""
        x, y = self.local(0.0, 0.0)
        return SE2(x, y, -self.yaw, -self.quarters % 4)
