"""The statement parts: position and heading (the paper's), motion and lane (beyond it, with `--motion`,
`--lanes`), and any part
registered after them. Each is one module (synth.parts.base says what a part and a clause kind are); this
module is the registry, in statement order: the order clauses print in, and the order every module asks its
questions in. docs/layout.md has the recipes for a new clause kind and a new part.
"""

from __future__ import annotations

from synth.config import SynthConfig
from synth.parts.base import Clause, ClauseKind, Part, Relations
from synth.parts.heading import HEADING
from synth.parts.lane import LANE
from synth.parts.motion import MOTION
from synth.parts.position import POSITION
from synth.smt.backend import MeasureRequest, Want

# The registry: a new part is one more entry here (or a register() call), after the parts it may follow.
_PARTS: list[Part] = [POSITION, HEADING, MOTION, LANE]


def register(part: Part) -> None:
    """Add a part at the end of the statement (a registered part's name must be new)."""
    if any(p.name == part.name for p in _PARTS):
        raise ValueError(f"a part named {part.name!r} is registered already")
    if not part.optional and any(p.optional for p in _PARTS):
        raise ValueError(f"part {part.name!r} is required, but optional parts precede it")
    _PARTS.append(part)


def unregister(part: Part) -> None:
    """Take a registered part out again (tests that register a toy part)."""
    _PARTS.remove(part)


def all_parts() -> tuple[Part, ...]:
    """Every registered part, in statement order."""
    return tuple(_PARTS)


def parts_for(config: SynthConfig) -> tuple[Part, ...]:
    """The parts every statement carries under this configuration."""
    return tuple(p for p in _PARTS if p.enabled(config))


def part_named(name: str) -> Part:
    return next(p for p in _PARTS if p.name == name)


def clause_kinds() -> tuple[ClauseKind, ...]:
    """Every kind of clause of the DSL, grammar order (position, heading, motion, then registered parts)."""
    return tuple(k for p in _PARTS for k in p.clause_kinds)


# The built-in parts' clause kinds, as the report's tables and plots name them (registered parts: clause_kinds()).
CLAUSE_KINDS: tuple[ClauseKind, ...] = clause_kinds()

__all__ = ["CLAUSE_KINDS", "HEADING", "LANE", "MOTION", "POSITION", "Clause", "ClauseKind", "MeasureRequest", "Part",
           "Relations", "Want", "all_parts", "clause_kinds", "part_named", "parts_for", "register", "unregister"]
