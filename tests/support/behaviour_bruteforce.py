"""An independent reference for behaviour programs: the minimum cost over every choice of boundary samples.

It shares nothing with synth.behaviour.segmentation or kinds' writing (Summary, write_pace, write_path): for each
segment it writes every candidate clause from the samples directly (speed and heading hulls rounded outward to
cents with decimal arithmetic, the shortest arc of the headings by its largest gap), keeps those the checker's
`holds` accepts, and takes the cheapest; the behaviour's cost is then minimised over all 2^(n-2) boundary sets.
Exponential: tracks of up to ~12 samples."""

from __future__ import annotations

import itertools
import math
from decimal import ROUND_CEILING, ROUND_FLOOR, Decimal

from synth.behaviour.check import segment_holds
from synth.behaviour.kinds import (
    ChangingLanes,
    Cruising,
    FollowingLane,
    Heading,
    SlowingDown,
    SlowingToAStop,
    SpeedingUp,
    Stopped,
    Turning,
)
from synth.behaviour.program import Segment
from synth.behaviour.track import Track
from synth.config import SynthConfig
from synth.syntax import Range


def cents(lo: float, hi: float) -> Range:
    d_lo = Decimal(lo).quantize(Decimal("0.01"), rounding=ROUND_FLOOR)
    d_hi = Decimal(hi).quantize(Decimal("0.01"), rounding=ROUND_CEILING)
    return Range(float(d_lo), float(d_hi))


def shortest_arc(headings: list[float]) -> tuple[float, float]:
    """The arc (start, start + width) holding every heading, opposite the largest gap between them."""
    hs = sorted(h % 360.0 for h in headings)
    # The gap after each heading, counter-clockwise to the next (the last one's wraps round to the first: all
    # headings equal leave one gap of 360 there, and an arc of width 0).
    gaps = [hs[k + 1] - hs[k] for k in range(len(hs) - 1)] + [hs[0] + 360.0 - hs[-1]]
    if len(hs) == 1:
        return hs[0], hs[0]
    k = max(range(len(hs)), key=lambda i: gaps[i])
    start = hs[(k + 1) % len(hs)]
    return start, start + (360.0 - gaps[k])


def cheapest_segment(track: Track, a: int, b: int, config: SynthConfig) -> int | None:
    """The least cost of a candidate segment that holds on samples a .. b, or None."""
    samples = track.samples[a:b + 1]
    speeds = [s.speed for s in samples]
    hull = cents(min(speeds), max(speeds))
    one_step = b - a <= 1
    paces = [Stopped(), SlowingToAStop(), SpeedingUp(hull), SlowingDown(hull)]
    if one_step or Decimal(str(hull.hi)) - Decimal(str(hull.lo)) <= Decimal(config.c_speed):
        paces.append(Cruising(hull))
    start, end = shortest_arc([s.heading for s in samples])
    arc = cents(start, end)
    paths = [FollowingLane(), ChangingLanes("left"), ChangingLanes("right"), Turning("left"), Turning("right")]
    if one_step or Decimal(str(arc.hi)) - Decimal(str(arc.lo)) <= Decimal(config.c_head):
        paths.append(Heading(arc))
    duration = cents(samples[-1].t - samples[0].t, samples[-1].t - samples[0].t)
    best = None
    for pace in paces:
        for path in ([None] if isinstance(pace, Stopped) else paths):
            seg = Segment(path, pace, duration)
            if segment_holds(seg, track, a, b, config) and (best is None or seg.cost < best):
                best = seg.cost
    return best


def brute_cost(track: Track, config: SynthConfig) -> int:
    """The least cost of a behaviour over every boundary set (parked: 0, when every sample is stopped)."""
    if all(s.speed <= config.v_stop for s in track.samples):
        return 0
    n = track.n
    if n == 1:
        return cheapest_segment(track, 0, 0, config)
    best = math.inf
    for k in range(n - 1):
        for inner in itertools.combinations(range(1, n - 1), k):
            bounds = (0, *inner, n - 1)
            costs = [cheapest_segment(track, a, b, config) for a, b in zip(bounds, bounds[1:])]
            if None not in costs:
                best = min(best, sum(costs))
    return best
