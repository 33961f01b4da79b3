"""Temporal patterns: a sequence of steps over the same variables, matched over the frames of a scene (docs/dsl.md,
"Temporal patterns").

A step is one-frame pattern statements (synth.patterns.one_frame), optionally with behaviour clauses at the end of a
statement (`, braking`); steps are separated by `then` or `then within T s`, and a step may end with
`for at least T s`. A variable binds one track for the whole pattern. This module is the syntax and the
constants of the definitions; pipeline.query.temporal is the engine over a frames dataset, which must agree with
the definition in docs/dsl.md exactly (tests hold it to a plain loop over frames).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

from synth.dsl import DslError
from synth.geometry import normalize
from synth.patterns.one_frame import MAX_NAMES, Pattern, parse_pattern, too_many_names
from synth.scene import EGO_ID
from synth.syntax import lines

# Behaviours of a track over time, read from its own frames (speeds in m/s, timestamps in microseconds).
SPEED_CHANGE = 1.0  # accelerating / braking: a speed change of at least this, m/s ...
SPEED_CHANGE_WINDOW_US = 1_000_000  # ... from a frame at most this long before
MOVING_SPEED = 1.0  # stopping: moving (at least this, m/s) at a frame at most STOP_WINDOW_US before, stationary now
STOP_WINDOW_US = 3_000_000
# turning left / right: the heading in the world (map_heading) turned by at least TURN_ANGLE degrees, counter-
# clockwise / clockwise, since a frame of the track at most TURN_WINDOW_US before (turn_of: the signed turn).
TURN_ANGLE = 30.0
TURN_WINDOW_US = 3_000_000
# changing lanes: the track's lane at p is on the chain of the left or right neighbour of its lane at a frame at most
# LANE_CHANGE_WINDOW_US before (`in lane left of` / `in lane right of` its earlier self, synth.road.lane_relations).
LANE_CHANGE_WINDOW_US = 3_000_000
SPEED_BEHAVIOURS = ("accelerating", "braking", "stopping")
TURNING = ("turning left", "turning right")
LANE_BEHAVIOURS = ("changing lanes",)
BEHAVIOURS = SPEED_BEHAVIOURS + TURNING + LANE_BEHAVIOURS
_FIRST_WORDS = {b.split()[0] for b in BEHAVIOURS}

# The most steps a pattern has (each is a query of its own), checked at each `then` as the lines are read; and the
# longest duration of `within T s` / `for at least T s`, in seconds (about 11.6 days: longer than any recorded
# scene, and T in microseconds stays an exact integer far from int64's end).
MAX_STEPS = 12
MAX_DURATION_S = 1e6

_THEN = re.compile(r"then(?:\s+within\s+(?P<t>\S+)\s+s)?\Z")
_FOR = re.compile(r"for\s+at\s+least\s+(?P<t>\S+)\s+s\Z")
_BEHAVIOUR = re.compile(r",\s*(?P<b>[a-z]+(?:\s+[a-z]+)?)\s*\Z")
_BEHAVIOUR_TEXT = re.compile(r"\s*(?P<b>[a-z]+(?:\s+[a-z]+)?)\s*\Z")  # what follows a comma in _BEHAVIOUR
# An ego line of behaviours alone has no comma after `ego`: `ego turning left` (`ego changing lanes, braking`).
_EGO_BEHAVIOUR = re.compile(rf"\A\s*{EGO_ID}\s+(?P<b>[a-z]+(?:\s+[a-z]+)?)\s*\Z")
_HEAD = re.compile(r"\s*(?P<id>[A-Za-z_][A-Za-z0-9_]*)")


@dataclass(frozen=True)
class Step:
    """One step: its statements (a one-frame pattern), the behaviours its variables (and ego) show in the same
    frames, the longest gap from the previous step's last frame to this step's first (None: any; microseconds), and
    the least time it lasts (microseconds, from its first frame to its last)."""

    pattern: Pattern
    behaviours: tuple[tuple[str, str], ...] = ()  # (variable or ego, behaviour), in the order written
    within_us: int | None = None
    for_at_least_us: int = 0

    @property
    def names(self) -> tuple[str, ...]:
        return self.pattern.names


@dataclass(frozen=True)
class TemporalPattern:
    steps: tuple[Step, ...]

    @property
    def names(self) -> tuple[str, ...]:
        """Every variable, in order of first declaration."""
        return tuple(dict.fromkeys(n for s in self.steps for n in s.names))

    @property
    def uses_motion(self) -> bool:
        """Does it need the entities' speeds (motion clauses, speed behaviours)?"""
        return any(s.pattern.uses_motion or any(b in SPEED_BEHAVIOURS for _, b in s.behaviours) for s in self.steps)

    @property
    def uses_world_heading(self) -> bool:
        """Does it need the tracks' headings in the world (turning)?"""
        return bool(self.behaving(TURNING))

    @property
    def uses_lanes(self) -> bool:
        """Does it need the frames' lane columns and maps (a lane clause in a step, changing lanes)?"""
        return any(s.pattern.uses_lanes for s in self.steps) or bool(self.behaving(LANE_BEHAVIOURS))

    def behaving(self, kinds: tuple[str, ...]) -> frozenset[str]:
        """The names (variables, or ego) that show one of these behaviours somewhere."""
        return frozenset(n for s in self.steps for n, b in s.behaviours if b in kinds)

    @property
    def needs_timestamps(self) -> bool:
        return any(s.behaviours or s.within_us is not None or s.for_at_least_us for s in self.steps)

    def __str__(self) -> str:
        out = []
        for k, s in enumerate(self.steps):
            if k:
                out.append("then" if s.within_us is None else f"then within {_seconds(s.within_us)} s")
            behaviours = {}
            for name, b in s.behaviours:
                behaviours.setdefault(name, []).append(b)
            out += [f"{st}" + "".join(f", {b}" for b in behaviours.get(st.id, [])) for st in s.pattern.statements]
            ego = [str(c) for _, c in s.pattern.ego.clauses()] if s.pattern.ego is not None else []
            if ego or EGO_ID in behaviours:
                out.append(f"{EGO_ID} {', '.join(ego + behaviours.get(EGO_ID, []))}")
            if s.for_at_least_us:
                out.append(f"for at least {_seconds(s.for_at_least_us)} s")
        return "".join(f"{line}\n" for line in out)


def _seconds(us: int) -> str:
    return f"{us / 1e6:g}"


def turn_of(before: float, now: float) -> float:
    """The signed turn from heading `before` to heading `now` (degrees CCW), in [-180, 180): positive is to the
    left. Written with synth.geometry.normalize, which the engine computes operation for operation (r2s_norm)."""
    return normalize(now - before + 180.0) - 180.0


def duration_us(text: str, where: str) -> int:
    """T of `within T s` / `for at least T s`: a number of seconds from 0 to MAX_DURATION_S, in whole
    microseconds (rounded to the nearest), so that the engine and the definition compare integers."""
    try:
        t = float(text)
    except ValueError:
        raise DslError(f"{where}: expected a number of seconds, found {text!r}") from None
    if not (math.isfinite(t) and 0 <= t <= MAX_DURATION_S):
        raise DslError(f"{where}: a duration is a number of seconds from 0 to {MAX_DURATION_S:g}, found {text}")
    return round(t * 1e6)


def _strip_behaviours(line: str) -> tuple[str, tuple[str, ...]]:
    """The statement without its trailing behaviour clauses, and those clauses. An ego line's first clause may be
    a behaviour too (`ego turning left`); an ego line of behaviours alone leaves no statement ("")."""
    # The line cut at its commas once, the behaviours read from the last piece back (what _BEHAVIOUR finds at the
    # last comma, again and again): linear in the line, however many behaviours it lists.
    pieces = line.split(",")
    k = len(pieces)
    while k > 1 and (m := _BEHAVIOUR_TEXT.match(pieces[k - 1])) is not None and m.group("b") in BEHAVIOURS:
        k -= 1
    # else a DSL clause (stationary, ...) ends the line: the statement parser reads it
    found = [_BEHAVIOUR_TEXT.match(p).group("b") for p in pieces[k:]]
    line = ",".join(pieces[:k])
    if (m := _EGO_BEHAVIOUR.match(line)) is not None and m.group("b") in BEHAVIOURS:
        return "", (m.group("b"), *found)
    return line, tuple(found)


def is_temporal(text: str) -> bool:
    """Does the text use any temporal syntax (then, for at least, a behaviour)?"""
    for raw in lines(text):
        line = raw.split("#", 1)[0].strip()
        if _THEN.match(line) or _FOR.match(line) or line.startswith(("then ", "for ")) or line == "then":
            return True
        if (m := _BEHAVIOUR.search(line) or _EGO_BEHAVIOUR.match(line)) and m.group("b").split()[0] in _FIRST_WORDS:
            return True
    return False


def parse_temporal(text: str) -> TemporalPattern:
    """A temporal pattern; errors (DslError) carry the line (and column where there is one)."""
    text_lines = lines(text)
    blocks: list[dict] = [{"lines": {}, "behaviours": [], "within": None, "for": 0, "for_line": None}]
    for lineno, raw in enumerate(text_lines, start=1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        if (m := _THEN.match(line)) is not None:
            if not blocks[-1]["lines"]:
                raise DslError(f"line {lineno}: `then` follows no step (a step is one or more statements)")
            if len(blocks) == MAX_STEPS:
                raise DslError(f"line {lineno}: the pattern has {MAX_STEPS + 1} or more steps, more than the bound of "
                               f"{MAX_STEPS} (docs/cli.md, Inputs and their bounds)")
            within = duration_us(m.group("t"), f"line {lineno}") if m.group("t") is not None else None
            blocks.append({"lines": {}, "behaviours": [], "within": within, "for": 0, "for_line": None})
            continue
        if (m := _FOR.match(line)) is not None:
            if not blocks[-1]["lines"] or blocks[-1]["for_line"] is not None:
                raise DslError(f"line {lineno}: `for at least` ends a step, once, after its statements")
            blocks[-1]["for"], blocks[-1]["for_line"] = duration_us(m.group("t"), f"line {lineno}"), lineno
            continue
        if line.startswith(("then", "for ")):
            raise DslError(f"line {lineno}: expected `then`, `then within T s` or `for at least T s`, found {line!r}")
        if blocks[-1]["for_line"] is not None:
            raise DslError(f"line {lineno}: a statement after `for at least` (line {blocks[-1]['for_line']}): "
                           "start the next step with `then`")
        statement, behaviours = _strip_behaviours(raw.split("#", 1)[0])
        blocks[-1]["lines"][lineno] = statement
        who = _head(statement or EGO_ID)
        for b in behaviours:
            # Said twice, a behaviour would only ask the engine the same question again (one join each).
            if (who, b) in blocks[-1]["behaviours"]:
                raise DslError(f"line {lineno}: {who} is {b!r} twice in one step: say each behaviour once")
            blocks[-1]["behaviours"].append((who, b))
    if not blocks[-1]["lines"]:
        raise DslError(f"line {len(text_lines)}: the pattern ends with `then` and no step after it")
    steps = []
    for block in blocks:
        if all(text == "" or _head(text) == EGO_ID for text in block["lines"].values()):
            raise DslError(f"line {min(block['lines'])}: a step declares at least one name (NAME = new TYPE ...); "
                           "ego's line alone is no step")
        # The step's lines, numbered as in the file, so a DSL error names the line of the file.
        first = min(block["lines"])
        step_text = "\n".join(block["lines"].get(n, "") for n in range(first, max(block["lines"]) + 1))
        pattern = parse_pattern(step_text, first_line=first)
        steps.append(Step(pattern, tuple(block["behaviours"]), block["within"], block["for"]))
    pattern = TemporalPattern(tuple(steps))
    if len(pattern.names) > MAX_NAMES:  # each step has at most MAX_NAMES; together they may have more
        first_at: dict[str, int] = {}  # each name and the line it is first declared on, in file order
        for block in blocks:
            for ln, text in sorted(block["lines"].items()):
                first_at.setdefault(_head(text), ln)
        raise too_many_names([ln for name, ln in first_at.items() if name not in (EGO_ID, "")][MAX_NAMES])
    if len(steps) > 1:
        for name in pattern.names:
            where = [k for k, s in enumerate(steps) if name in s.names]
            if len(where) == 1:
                line = next(ln for ln, text in sorted(blocks[where[0]]["lines"].items()) if _head(text) == name)
                raise DslError(f"line {line}: {name!r} is mentioned in one step only; a variable binds one track "
                               "across the steps, so declare it in another step too (or drop it)")
    return pattern


def _head(statement: str) -> str:
    """The name a statement line is about (its declared name, or ego)."""
    m = _HEAD.match(statement)
    return m.group("id") if m else ""


def parse_query_pattern(text: str) -> Pattern | TemporalPattern:
    """What `r2s query` reads: a one-frame pattern (synth.patterns.one_frame), or a temporal one if it uses their syntax."""
    return parse_temporal(text) if is_temporal(text) else parse_pattern(text)
