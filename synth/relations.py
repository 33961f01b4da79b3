"""Which relations hold between every (reference, target) pair of a scene: closed form, all at once, per part.

Each statement part computes its own table in floats (synth.parts); pairs inside the guard band are left
UNDECIDED for the caller to settle exactly (with rationals here, with the solver in hybrid).
"""

from __future__ import annotations

from collections.abc import Sequence

from synth.config import SynthConfig
from synth.parts import HEADING, POSITION, Part, part_named, parts_for
from synth.parts.heading import FACING_NAMES
from synth.parts.position import DIRECTION_NAMES
from synth.scene import Scene
from synth.tables import GUARD, NONE, UNDECIDED, RelationTable, scene_arrays

__all__ = ["DIRECTION_NAMES", "FACING_NAMES", "GUARD", "NONE", "UNDECIDED", "RelationTable", "closed_form_table",
           "exact_heading", "exact_position", "settle_exactly"]


def closed_form_table(scene: Scene, config: SynthConfig, parts: Sequence[Part] | None = None) -> RelationTable:
    arrays = scene_arrays(scene)
    return RelationTable(arrays.ids, {p.name: p.closed_form(arrays, config) for p in parts or parts_for(config)})


def settle_exactly(table: RelationTable, scene: Scene, config: SynthConfig) -> RelationTable:
    """Replace every UNDECIDED entry by the exact rational decision."""
    codes = {name: c.copy() for name, c in table.codes.items()}
    ents = (scene.ego,) + scene.others
    for name, r, e in table.undecided():
        part = part_named(name)
        hits = [c for c in part.codes_from(r == 0) if part.exact(c, ents[r], ents[e], config)]
        codes[name][r, e] = hits[0] if hits else NONE
    return table.replaced(codes)


def exact_position(scene: Scene, ref_id: str, target_id: str, direction: str, config: SynthConfig) -> bool:
    by = scene.by_id()
    return POSITION.exact(DIRECTION_NAMES.index(direction), by[ref_id], by[target_id], config)


def exact_heading(scene: Scene, ref_id: str, target_id: str, mode: str, config: SynthConfig) -> bool:
    by = scene.by_id()
    return HEADING.exact(FACING_NAMES.index(mode), by[ref_id], by[target_id], config)
