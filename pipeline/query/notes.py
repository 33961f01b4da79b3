"""The note `r2s query` prints when its pattern names a type the frames never hold (issue 26: nothing is filtered
silently). A pedestrian pattern over frames extracted with `--categories vehicles` matches nothing; the note says
so before the query runs, with how the frames were extracted when that is recorded beside them (`make corpus`
writes FRAMES.args: the source, the input and the categories). A note, not an error: the answer (no match) is
still right."""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path

from synth.patterns.one_frame import Pattern, matched_types

ARGS_SUFFIX = ".args"  # `make corpus`: OUT/frames.args beside OUT/frames
MAX_ARGS_BYTES = 4096


def missing_types(patterns: Iterable[Pattern], present: Iterable[str]) -> list[str]:
    """The pattern types (in order of first use) that no entity of the frames can bind: a concrete type absent
    from them, `Vehicle` when no vehicle class is there; `Object` binds any type."""
    present = set(present)
    missing: dict[str, None] = {}
    for pattern in patterns:
        for st in pattern.statements:
            types = matched_types(st.type)
            if types is not None and not types & present:
                missing[st.type] = None
    return list(missing)


def extraction(frames: str | os.PathLike) -> str:
    """How the frames were extracted, as far as it is recorded: the `make corpus` stamp beside them, or a word
    that it is not."""
    stamp = Path(str(frames).rstrip("/") + ARGS_SUFFIX)
    try:
        if stamp.is_file():  # a regular file only, read bounded (a stamp is one short line)
            with open(stamp, "rb") as f:
                text = " ".join(f.read(MAX_ARGS_BYTES).decode("utf-8", "replace").split())
            categories = "--categories" in text.split()
            return (f"they were extracted from `{text}` ({stamp})"
                    + ("" if categories else ", every type: r2s extract's default --categories all"))
    except OSError:
        pass
    return ("how they were extracted is not recorded beside them (`r2s extract --categories` selects types; "
            "`all` keeps every one)")


def absent_types_note(patterns: Iterable[Pattern], present: Iterable[str], frames: str | os.PathLike) -> str | None:
    """One line, or None when every type of the pattern occurs in the frames."""
    present = sorted(set(present))
    missing = missing_types(patterns, present)
    if not missing:
        return None
    there = ", ".join(present) if present else "none"
    return (f"r2s query: note: the pattern names {', '.join(missing)}, which the frames never hold (their types: "
            f"{there}), so it cannot match; {extraction(frames)}")
