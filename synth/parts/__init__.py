"""Statement parts, each behind the one interface of synth.parts.base: position and heading (the paper's), and
motion (beyond it, with `--motion`)."""

from __future__ import annotations

from synth.config import SynthConfig
from synth.parts.base import ClauseKind, MeasureRequest, Part, Want
from synth.parts.heading import HEADING
from synth.parts.motion import MOTION
from synth.parts.position import POSITION

# In statement order: the order clauses print in, and the order every module asks its questions in.
STATIC_PARTS: tuple[Part, ...] = (POSITION, HEADING)
ALL_PARTS: tuple[Part, ...] = (POSITION, HEADING, MOTION)
_BY_NAME = {p.name: p for p in ALL_PARTS}
# Every kind of clause of the DSL, grammar order (position, heading, motion).
CLAUSE_KINDS: tuple[ClauseKind, ...] = tuple(k for p in ALL_PARTS for k in p.clause_kinds)


def parts_for(config: SynthConfig) -> tuple[Part, ...]:
    """The parts every statement carries under this configuration."""
    return ALL_PARTS if config.motion else STATIC_PARTS


def part_named(name: str) -> Part:
    return _BY_NAME[name]


__all__ = ["ALL_PARTS", "HEADING", "MOTION", "POSITION", "CLAUSE_KINDS", "STATIC_PARTS", "MeasureRequest", "Part",
           "ClauseKind", "Want", "part_named", "parts_for"]
