"""Robust synthesis: relations and Ranges that hold for every scene within the measurement error.

Each statement part says which bounds concern it (Part.perturbed) and answers the robust question itself (its
robust_closed_form table, robust_relation, robust_clause and violations); the mathematics they share, the two
exact reductions and the widening of Ranges, is synth.perturbation. This module is what the oracle and the
synthesizer ask: is a scene robust for a part, and the robust relation table.
"""

from __future__ import annotations

from collections.abc import Sequence

from synth.config import SynthConfig
from synth.dsl import fmt_number
from synth.parts import MOTION, Part, parts_for
from synth.perturbation import MIN_CONE, Bounds, bounds_of, covering, narrowed
from synth.scene import Scene
from synth.tables import NONE, UNDECIDED, RelationTable, scene_arrays

__all__ = ["MIN_CONE", "Bounds", "bounds_of", "covering", "is_robust", "narrowed", "robust_closed_form_table",
           "robust_note", "robust_parts", "settle_conservatively"]


def robust_parts(scene: Scene, config: SynthConfig, parts: Sequence[Part] | None = None) -> frozenset[str]:
    """Names of the parts whose questions are robust ones on this scene (some entity perturbs them)."""
    return frozenset(p.name for p in parts or parts_for(config) if p.is_robust(scene, config))


def is_robust(scene: Scene, config: SynthConfig) -> bool:
    """Does any entity carry uncertainty that concerns a part? If not, synthesis is the plain one, byte for byte."""
    return bool(robust_parts(scene, config))


def robust_note(scenes: Sequence[Scene], config: SynthConfig) -> str:
    """What a Scenic header adds when some frame's synthesis was robust (docs/dsl.md, "Robust synthesis"): one
    note for a frame and for a window alike, since a window's clauses are its frames' robust ones merged."""
    if not any(is_robust(s, config) for s in scenes):
        return ""
    speed = f", {fmt_number(config.speed_uncertainty)} m/s" if any(MOTION.is_robust(s, config) for s in scenes) else ""
    return (f"; robust to {fmt_number(config.pos_uncertainty)} m, "
            f"{fmt_number(config.heading_uncertainty)} deg{speed} (entities' own sigmas override)")


def robust_closed_form_table(scene: Scene, config: SynthConfig, parts: Sequence[Part] | None = None) -> RelationTable:
    """The relation table of the robust question, floats outside the guard band, UNDECIDED inside it."""
    arrays = scene_arrays(scene)
    by = scene.by_id()
    bounds = [bounds_of(by[i], config) for i in arrays.ids]
    return RelationTable(arrays.ids, {p.name: p.robust_closed_form(arrays, bounds, config)
                                      for p in parts or parts_for(config)})


def settle_conservatively(table: RelationTable) -> RelationTable:
    """The closed-form oracle has no solver: what the floats cannot show to hold is taken not to hold."""
    codes = {name: c.copy() for name, c in table.codes.items()}
    for c in codes.values():
        c[c == UNDECIDED] = NONE
    return table.replaced(codes)
