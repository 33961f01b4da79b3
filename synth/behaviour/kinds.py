"""The paths and paces of a behaviour segment (docs/dsl.md, "Behaviour programs"): each kind owns its semantics
over a track's samples a .. b (`holds`, the checker's reading, within EPS), its cost and text, and what synthesis
writes for an interval (`write`, from the interval's Summary, None where it cannot be written).

A Summary is what every kind's writing needs of samples a .. b, folded one sample at a time (`Summary.start`,
`Summary.then`), so that the minimum-cost segmentation decides all O(n^2) intervals of a track in O(n^2) steps.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from fractions import Fraction
from typing import ClassVar

from synth.behaviour.track import Sample, Steps
from synth.config import SynthConfig
from synth.geometry import normalize
from synth.patterns.temporal import TURN_ANGLE, turn_of
from synth.syntax import Range, printed

EPS = 1e-9  # the checker's slack: degrees, m/s, seconds (as r2s check's)


def wider_than(r: Range, width: float) -> bool:
    """Is the Range, at its printed bounds, wider than `width`? (Exact: cents against the float's rational.)"""
    return printed(r.hi) - printed(r.lo) > Fraction(width)


def outward(lo: float, hi: float) -> Range:
    """The narrowest Range of cents holding [lo, hi] (its bounds are exact as printed, at most two decimals)."""
    a, b = math.floor(lo * 100) / 100, math.ceil(hi * 100) / 100
    # x * 100 may round across a whole cent; step back out where it did.
    return Range(a - 0.01 if a > lo else a, b + 0.01 if b < hi else b)


@dataclass(frozen=True)
class Summary:
    """Samples a .. b of a track, as the kinds' writing reads them (m/s, degrees, seconds)."""

    steps: int
    t0: float
    t1: float
    s_first: float
    s_last: float
    s_min: float
    s_max: float
    rising: bool  # s_j >= s_i - DV for all i < j
    falling: bool  # s_j <= s_i + DV for all i < j
    laned: bool  # every sample in a lane
    keep: bool  # every step keeps the lane
    left: bool  # every step keeps the lane or moves left
    right: bool
    moved_left: bool  # some step moves left and does not keep the lane
    moved_right: bool
    crossing: bool  # some sample in an intersection
    turn: float  # the steps' summed signed turn, degrees
    h0: float  # the first heading
    h_lo: float  # the least and greatest offset of a heading from h0, in (-180, 180]
    h_hi: float

    @classmethod
    def start(cls, s: Sample) -> Summary:
        laned = s.lane is not None
        return cls(0, s.t, s.t, s.speed, s.speed, s.speed, s.speed, True, True, laned, laned, laned, laned, False,
                   False, s.in_intersection, 0.0, s.heading, 0.0, 0.0)

    def then(self, s: Sample, last: Sample, steps: Steps, k: int, config: SynthConfig) -> Summary:
        """This summary extended by sample `s`, the step k from `last` (the summary's last sample) to it."""
        keep, left, right = steps.keep[k], steps.left[k], steps.right[k]
        offset = normalize(s.heading - self.h0 + 180.0) - 180.0
        offset = 180.0 if offset == -180.0 else offset
        return Summary(
            self.steps + 1, self.t0, s.t, self.s_first, s.speed, min(self.s_min, s.speed),
            max(self.s_max, s.speed), self.rising and s.speed >= self.s_max - config.dv,
            self.falling and s.speed <= self.s_min + config.dv, self.laned and s.lane is not None,
            self.keep and keep, self.left and (keep or left), self.right and (keep or right),
            self.moved_left or (left and not keep), self.moved_right or (right and not keep),
            self.crossing or s.in_intersection, self.turn + turn_of(last.heading, s.heading), self.h0,
            min(self.h_lo, offset), max(self.h_hi, offset))


def pace_possible(m: Summary, config: SynthConfig) -> bool:
    """Can write_pace write a pace on this interval or on any longer one from the same start? Each pace's
    condition but the last change is kept only while it holds (a speed above V_STOP, a rise or a fall past DV, a
    hull wider than C_SPEED stay), so once none is left, none comes back: the segmentation stops extending."""
    return (m.s_max <= config.v_stop or m.falling or m.rising or m.steps <= 1
            or not wider_than(outward(m.s_min, m.s_max), config.c_speed))


def _all(samples: Sequence[Sample], a: int, b: int, test) -> bool:
    return all(test(samples[k]) for k in range(a, b + 1))


def _never_falls(samples: Sequence[Sample], a: int, b: int, dv: float) -> bool:
    """s_j >= s_i - dv for all a <= i < j <= b: the fastest sample before each j decides it."""
    top = samples[a].speed
    for k in range(a + 1, b + 1):
        if samples[k].speed < top - dv - EPS:
            return False
        top = max(top, samples[k].speed)
    return True


def _never_rises(samples: Sequence[Sample], a: int, b: int, dv: float) -> bool:
    """s_j <= s_i + dv for all a <= i < j <= b: the slowest sample before each j decides it."""
    low = samples[a].speed
    for k in range(a + 1, b + 1):
        if samples[k].speed > low + dv + EPS:
            return False
        low = min(low, samples[k].speed)
    return True


# ----------------------------------------------------------------------------------------------------- paths
class Kind:
    """A path or a pace: its cost, and its text (a class attribute, or a property of its Range), which it prints as."""

    cost: ClassVar[int]
    text: str

    def __str__(self) -> str:
        return self.text


class Path(Kind):
    """Where a segment goes: holds(samples, steps, a, b); written by write_path."""


@dataclass(frozen=True)
class FollowingLane(Path):
    cost: ClassVar[int] = 0
    text: ClassVar[str] = "following lane"

    def holds(self, samples: Sequence[Sample], steps: Steps, a: int, b: int) -> bool:
        return _all(samples, a, b, lambda s: s.lane is not None) and all(steps.keep[a:b])

    @classmethod
    def write(cls, m: Summary, config: SynthConfig) -> FollowingLane | None:
        return cls() if m.laned and m.keep else None


@dataclass(frozen=True)
class ChangingLanes(Path):
    side: str  # left | right
    cost: ClassVar[int] = 0

    @property
    def text(self) -> str:
        return f"changing lanes {self.side}"

    def holds(self, samples: Sequence[Sample], steps: Steps, a: int, b: int) -> bool:
        moved = steps.left if self.side == "left" else steps.right
        return (_all(samples, a, b, lambda s: s.lane is not None)
                and all(k or m for k, m in zip(steps.keep[a:b], moved[a:b]))
                and any(m and not k for k, m in zip(steps.keep[a:b], moved[a:b])))

    @classmethod
    def write_side(cls, side: str, m: Summary) -> ChangingLanes | None:
        ok = m.left and m.moved_left if side == "left" else m.right and m.moved_right
        return cls(side) if m.laned and ok else None


@dataclass(frozen=True)
class Turning(Path):
    side: str  # left | right
    cost: ClassVar[int] = 0

    @property
    def text(self) -> str:
        return f"turning {self.side}"

    def holds(self, samples: Sequence[Sample], steps: Steps, a: int, b: int) -> bool:
        turn = sum(turn_of(samples[k].heading, samples[k + 1].heading) for k in range(a, b))
        return (any(samples[k].in_intersection for k in range(a, b + 1))
                and (turn >= TURN_ANGLE - EPS if self.side == "left" else turn <= -TURN_ANGLE + EPS))

    @classmethod
    def write_side(cls, side: str, m: Summary) -> Turning | None:
        ok = m.turn >= TURN_ANGLE if side == "left" else m.turn <= -TURN_ANGLE
        return cls(side) if m.crossing and ok else None


@dataclass(frozen=True)
class Heading(Path):
    """`heading Range(c, d) deg`: every heading in the world in the arc from c counter-clockwise to d."""

    range: Range
    cost: ClassVar[int] = 2

    @property
    def text(self) -> str:
        return f"heading {self.range} deg"

    def holds(self, samples: Sequence[Sample], steps: Steps, a: int, b: int) -> bool:
        lo, width = self.range.lo, self.range.hi - self.range.lo
        return width >= 360.0 or _all(samples, a, b, lambda s: normalize(s.heading - lo) <= width + EPS
                                      or normalize(s.heading - lo) >= 360.0 - EPS)

    @classmethod
    def write(cls, m: Summary, config: SynthConfig) -> Heading | None:
        lo = m.h0 + m.h_lo
        shift = normalize(lo) - lo  # the arc's start printed in [0, 360)
        r = outward(lo + shift, m.h0 + m.h_hi + shift)
        return None if m.steps > 1 and wider_than(r, config.c_head) else cls(r)


def write_path(m: Summary, config: SynthConfig) -> Path | None:
    """The path synthesis writes for an interval (docs/dsl.md): the first of following lane, changing lanes left,
    right, turning left, right that holds, else a heading Range (None when its arc is too wide)."""
    return (FollowingLane.write(m, config) or ChangingLanes.write_side("left", m)
            or ChangingLanes.write_side("right", m) or Turning.write_side("left", m)
            or Turning.write_side("right", m) or Heading.write(m, config))


# ----------------------------------------------------------------------------------------------------- paces
class Pace(Kind):
    """How fast a segment goes: holds(samples, a, b, config); written by write_pace."""


@dataclass(frozen=True)
class Stopped(Pace):
    cost: ClassVar[int] = 0
    text: ClassVar[str] = "stopped"

    def holds(self, samples: Sequence[Sample], a: int, b: int, config: SynthConfig) -> bool:
        return _all(samples, a, b, lambda s: s.speed <= config.v_stop + EPS)


@dataclass(frozen=True)
class SlowingToAStop(Pace):
    cost: ClassVar[int] = 0
    text: ClassVar[str] = "slowing to a stop"

    def holds(self, samples: Sequence[Sample], a: int, b: int, config: SynthConfig) -> bool:
        return (samples[a].speed > config.v_stop - EPS and samples[b].speed <= config.v_stop + EPS
                and _never_rises(samples, a, b, config.dv))


@dataclass(frozen=True)
class Cruising(Pace):
    range: Range
    cost: ClassVar[int] = 1
    word: ClassVar[str] = "cruising"

    @property
    def text(self) -> str:
        return f"{self.word} {self.range} m/s"

    def within(self, samples: Sequence[Sample], a: int, b: int) -> bool:
        return _all(samples, a, b, lambda s: self.range.contains(s.speed, EPS))

    def holds(self, samples: Sequence[Sample], a: int, b: int, config: SynthConfig) -> bool:
        return self.within(samples, a, b)


@dataclass(frozen=True)
class SpeedingUp(Cruising):
    word: ClassVar[str] = "speeding up"

    def holds(self, samples: Sequence[Sample], a: int, b: int, config: SynthConfig) -> bool:
        return (self.within(samples, a, b) and samples[b].speed - samples[a].speed >= config.dv - EPS
                and _never_falls(samples, a, b, config.dv))


@dataclass(frozen=True)
class SlowingDown(Cruising):
    word: ClassVar[str] = "slowing down"

    def holds(self, samples: Sequence[Sample], a: int, b: int, config: SynthConfig) -> bool:
        return (self.within(samples, a, b) and samples[a].speed - samples[b].speed >= config.dv - EPS
                and _never_rises(samples, a, b, config.dv))


def write_pace(m: Summary, config: SynthConfig) -> Pace | None:
    """The pace synthesis writes for an interval (docs/dsl.md): the first of the table's that holds, its Range
    the speeds' hull rounded outward to cents (cruising: at most C_SPEED wide but on one step)."""
    if m.s_max <= config.v_stop:
        return Stopped()
    if m.s_first > config.v_stop and m.s_last <= config.v_stop and m.falling:
        return SlowingToAStop()
    hull = outward(m.s_min, m.s_max)
    if m.steps <= 1 or not wider_than(hull, config.c_speed):
        return Cruising(hull)
    if m.rising and m.s_last - m.s_first >= config.dv:
        return SpeedingUp(hull)
    if m.falling and m.s_first - m.s_last >= config.dv:
        return SlowingDown(hull)
    return None


PATH_WORDS = ("following", "changing", "turning", "heading")
PACES = (Stopped, SlowingToAStop, Cruising, SpeedingUp, SlowingDown)
