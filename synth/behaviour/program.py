"""Behaviour programs as values, printed and parsed in the DSL's style (docs/dsl.md, "Behaviour programs"):
a Segment (path, pace, duration Range), a Behaviour (an entity's segments, or parked), a ClipProgram (the first
frame's relational program and one behaviour per entity)."""

from __future__ import annotations

from dataclasses import dataclass

from synth.behaviour.kinds import (
    PATH_WORDS,
    ChangingLanes,
    Cruising,
    FollowingLane,
    Heading,
    Pace,
    Path,
    SlowingDown,
    SlowingToAStop,
    SpeedingUp,
    Stopped,
    Turning,
)
from synth.dsl import MAX_STATEMENTS, Program, parse_program
from synth.scene import EGO_ID, check_identifier
from synth.syntax import BLANKS, DslError, Line, Range, lines


@dataclass(frozen=True)
class Segment:
    path: Path | None  # None with Stopped only
    pace: Pace
    duration: Range  # seconds

    def __post_init__(self) -> None:
        if self.path is None and not isinstance(self.pace, Stopped):
            raise DslError(f"segment '{self.pace}' needs a path (only 'stopped' goes without one)")

    @property
    def cost(self) -> int:
        return 1 + (self.path.cost if self.path is not None else 0) + self.pace.cost

    def __str__(self) -> str:
        head = "" if self.path is None else f"{self.path}, "
        return f"{head}{self.pace} for {self.duration} s"


@dataclass(frozen=True)
class Behaviour:
    """An entity's behaviour: `parked`, or its segments in order; `after` the Range of its first time (None: in
    the clip's first frame)."""

    id: str
    segments: tuple[Segment, ...]  # empty: parked
    after: Range | None = None

    @property
    def parked(self) -> bool:
        return not self.segments

    @property
    def cost(self) -> int:
        return sum(s.cost for s in self.segments)

    def __str__(self) -> str:
        head = f"behaviour {self.id}" + ("" if self.after is None else f" after {self.after} s")
        if self.parked:
            return f"{head} parked\n"
        first, *rest = self.segments
        return f"{head} {first}\n" + "".join(f"then {s}\n" for s in rest)


@dataclass(frozen=True)
class ClipProgram:
    program: Program  # the clip's first frame
    behaviours: tuple[Behaviour, ...]

    @property
    def cost(self) -> int:
        return self.program.cost + sum(b.cost for b in self.behaviours)

    def behaviour(self, entity_id: str) -> Behaviour | None:
        return next((b for b in self.behaviours if b.id == entity_id), None)

    def __str__(self) -> str:
        return str(self.program) + "".join(str(b) for b in self.behaviours)


def _duration(ln: Line) -> Range:
    r = ln.range_()
    ln.take(text="s")
    return r


def _path(ln: Line) -> Path | None:
    word = ln.peek()
    if word not in PATH_WORDS:
        return None
    ln.take("word")
    if word == "following":
        ln.take(text="lane")
        return FollowingLane()
    if word == "heading":
        r = ln.range_()
        ln.take(text="deg")
        return Heading(r)
    if word == "changing":
        ln.take(text="lanes")
    side = ln.take("word")
    if side not in ("left", "right"):
        raise DslError(f"{ln.where(back=1)}: expected left or right, found {side!r}")
    return ChangingLanes(side) if word == "changing" else Turning(side)


def _pace(ln: Line) -> Pace:
    start = ln.where()
    word = ln.take("word")
    if word == "stopped":
        return Stopped()
    if word == "slowing" and ln.accept("to"):
        ln.take(text="a")
        ln.take(text="stop")
        return SlowingToAStop()
    kind = {"cruising": Cruising, "speeding": SpeedingUp, "slowing": SlowingDown}.get(word)
    if kind is None:
        raise DslError(f"{start}: expected a pace (stopped, slowing to a stop, cruising, speeding up, slowing down), "
                       f"found {word!r}")
    if kind is not Cruising:
        ln.take(text="up" if kind is SpeedingUp else "down")
    r = ln.range_()
    ln.take(text="m")
    ln.take(text="/")
    ln.take(text="s")
    return kind(r)


def _segment(ln: Line) -> Segment:
    start = ln.where()
    path = _path(ln)
    if path is not None:
        ln.take(text=",")
    pace = _pace(ln)
    ln.take(text="for")
    duration = _duration(ln)
    ln.end()
    if path is None and not isinstance(pace, Stopped):
        raise DslError(f"{start}: '{pace}' needs a path before it (only 'stopped' goes without one)")
    return Segment(path, pace, duration)


def _behaviour_line(raw: str) -> bool:
    return raw.split("#", 1)[0].split()[:1] in (["behaviour"], ["then"])


def is_clip_program(text: str) -> bool:
    """Does DSL text have behaviours (a line starting `behaviour` or `then`)? DslError for a line past the bound."""
    return any(_behaviour_line(raw) for raw in lines(text))


def parse_clip_program(text: str) -> ClipProgram:
    """A clip program: the relational program's statements, then `behaviour` blocks (docs/dsl.md). Errors are
    one line naming the line and column."""
    rows = lines(text)
    first = next((k for k, raw in enumerate(rows) if _behaviour_line(raw)), len(rows))
    program = parse_program("\n".join(rows[:first]))
    behaviours: list[Behaviour] = []
    seen: set[str] = set()
    for lineno, raw in enumerate(rows[first:], start=first + 1):
        line = raw.split("#", 1)[0]
        if not line.strip(BLANKS):
            continue
        ln = Line(line, lineno)
        if ln.accept("then"):
            if not behaviours:
                raise DslError(f"line {lineno}: 'then' before any behaviour")
            if behaviours[-1].parked:
                raise DslError(f"line {lineno}: a parked behaviour has no segments to follow")
            last = behaviours[-1]
            behaviours[-1] = Behaviour(last.id, last.segments + (_segment(ln),), last.after)
            continue
        ln.take(text="behaviour")
        where = ln.where()
        name = ln.take("word")
        try:
            check_identifier(name)
        except ValueError as exc:
            raise DslError(f"{where}: {exc}") from None
        if name in seen:
            raise DslError(f"{where}: {name!r} has a behaviour already (one per entity)")
        if len(behaviours) == MAX_STATEMENTS:
            raise DslError(f"line {lineno}: behaviour {MAX_STATEMENTS + 1:,}, more than the bound of "
                           f"{MAX_STATEMENTS:,}")
        seen.add(name)
        after = _duration(ln) if ln.accept("after") else None
        if ln.accept("parked"):
            ln.end()
            behaviours.append(Behaviour(name, (), after))
        else:
            behaviours.append(Behaviour(name, (_segment(ln),), after))
    return ClipProgram(program, tuple(behaviours))


__all__ = ["Behaviour", "ClipProgram", "EGO_ID", "Segment", "parse_clip_program"]
