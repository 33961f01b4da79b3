"""An independent reference for pattern matching: every injective tuple of entities, each judged by `r2s check`.

It shares nothing with pipeline.query.mining / pipeline.query.sql or with synth.patterns.one_frame's matcher: for each tuple of
non-ego entities of the right types (the type classes written out again here), the pattern is made a program with
the bound entities' own types, the scene is cut to ego plus those entities renamed to the pattern's names, and
synth.semantics.check (the checker `r2s check` runs) decides; tuples are extended one name at a time and a prefix
the checker refuses is not extended; a whole tuple then needs the pattern's ego line to hold of ego, judged by the
checker's own statement check with ego's type. A statement that leaves out a clause is checked on the clauses it
has. Exponential in the number of names: small patterns.
"""

from __future__ import annotations

from dataclasses import replace

from synth.config import SynthConfig
from synth.dsl import Program
from synth.patterns.one_frame import Pattern
from synth.scene import Scene
from synth.semantics import check, check_statement

VEHICLE_TYPES = {"Car", "Truck", "Bus", "Motorcycle", "Bicycle", "Trailer", "ConstructionVehicle", "EmergencyVehicle"}


def _fits(pattern_type: str, entity_type: str) -> bool:
    if pattern_type == "Object":
        return True
    if pattern_type == "Vehicle":
        return entity_type in VEHICLE_TYPES
    return pattern_type == entity_type


def brute_matches(pattern: Pattern, scene: Scene, config: SynthConfig | None = None) -> list[tuple[str, ...]]:
    """Every match as a tuple of entity ids (in the pattern's name order), in lexicographic order of the entities'
    positions in the scene."""
    config = config or SynthConfig()
    others = list(scene.others)
    statements = pattern.statements
    found: list[tuple[str, ...]] = []
    # statements[k] with entity i's own type, and entity i renamed to statements[k]'s name (built once each).
    typed = [{t: replace(st, type=t) for t in {e.type for e in others}} for st in statements]
    renamed = [[replace(e, id=st.id) for e in others] for st in statements]

    def holds(bound: list[int]) -> bool:
        # The first len(bound) statements as a program of the bound entities' own types, on ego plus them.
        program = Program(tuple(typed[k][others[i].type] for k, i in enumerate(bound)))
        cut = Scene(scene.frame_id, (scene.ego,) + tuple(renamed[k][i] for k, i in enumerate(bound)))
        return check(program, cut, config).ok

    def extend(bound: list[int]) -> None:
        # A prefix of the program only refers to earlier names, so a failing prefix fails every extension.
        if len(bound) == len(statements):
            if pattern.ego is not None:
                by_id = {"ego": scene.ego, **{st.id: renamed[k][i] for k, (st, i) in enumerate(zip(statements, bound))}}
                if check_statement(replace(pattern.ego, type=scene.ego.type), by_id, config):
                    return
            found.append(tuple(others[i].id for i in bound))
            return
        st = statements[len(bound)]
        for i, e in enumerate(others):
            if i not in bound and _fits(st.type, e.type) and holds(bound + [i]):
                extend(bound + [i])

    extend([])
    return found


def brute_by_frame(scenes, pattern: Pattern, config: SynthConfig | None = None) -> dict[str, list[tuple[str, ...]]]:
    """{frame_id: every match} over the scenes that have one (brute_matches per scene)."""
    return {s.frame_id: b for s in scenes if (b := brute_matches(pattern, s, config))}
