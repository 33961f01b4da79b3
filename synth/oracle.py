"""Relation oracles: who witnesses whom. `closed-form`, `hybrid` (default) and `smt` (the paper's way).

An oracle answers, for a target e and a reference r (ego or another entity), which direction relation
(ahead / left / behind / right) and which facing relation (toward / away) hold, if any. Sectors are 2 delta1
wide and 90 degrees apart, so at most one of each holds. Answers are cached per (relation, target, reference),
the paper's M_smt.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from synth.config import SynthConfig
from synth.relations import (
    DIRECTION_NAMES,
    FACING_NAMES,
    NONE,
    UNDECIDED,
    RelationTable,
    closed_form_table,
    settle_exactly,
)
from synth.robust import is_robust, robust_closed_form_table, settle_conservatively
from synth.scene import Entity, Scene
from synth.smt import make_backend


@dataclass
class RelationOracle:
    """Answers position / heading questions about one scene, lazily where it asks a solver."""

    scene: Scene
    config: SynthConfig
    ids: tuple[str, ...] = ()
    table: RelationTable | None = None
    backend: object | None = None
    # The paper's M_smt: (relation, target index, reference index) -> does the relation hold.
    cache: dict[tuple[str, int, int], bool] = field(default_factory=dict)

    @property
    def complete(self) -> bool:
        """True when every pair is already known (no question will reach a solver)."""
        return self.table is not None

    def entities(self) -> tuple[Entity, ...]:
        """The entities in index order (0 = ego); computed once, asked often."""
        if getattr(self, "_entities", None) is None:
            by = self.scene.by_id()
            self._entities = tuple(by[i] for i in self.ids)
        return self._entities

    def position(self, r: int, e: int) -> int:
        """Direction code of e relative to r (index into DIRECTION_NAMES), or NONE."""
        if self.table is not None:
            return int(self.table.position[r, e])
        return self._ask("position", r, e)

    def heading(self, r: int, e: int) -> int:
        if self.table is not None:
            return int(self.table.heading[r, e])
        return self._ask("heading", r, e)

    def _ask(self, kind: str, r: int, e: int) -> int:
        """Ask relation by relation, as Alg. 4 does, through the cache; the first that holds is the answer."""
        if r == e:
            return NONE
        ents = self.entities()
        if kind == "position":
            names, solve = DIRECTION_NAMES, self.backend.position_relation
        else:
            names, solve = FACING_NAMES, self.backend.heading_relation
        for code, name in enumerate(names):
            key = (name, e, r)
            if key not in self.cache:
                self.cache[key] = solve(name, ents[r], ents[e])
            if self.cache[key]:
                return code
        return NONE

    def full_table(self) -> RelationTable:
        """Every pair answered (the smt oracle asks the solver for each one it has not asked yet)."""
        if self.table is not None:
            return self.table
        n = len(self.ids)
        pos = np.array([[self.position(r, e) for e in range(n)] for r in range(n)], dtype=np.int8)
        head = np.array([[self.heading(r, e) for e in range(n)] for r in range(n)], dtype=np.int8)
        self.table = RelationTable(self.ids, pos, head)
        return self.table


def make_oracle(scene: Scene, config: SynthConfig) -> RelationOracle:
    """The oracle the config names. Index 0 is ego, then the scene's other entities in scene order."""
    ids = (scene.ego.id,) + tuple(e.id for e in scene.others)
    # Robust synthesis asks a stronger question of every pair (synth.robust); its floats are a pre-filter too.
    robust = is_robust(scene, config)
    if config.oracle == "closed-form":
        if robust:
            return RelationOracle(scene, config, ids, settle_conservatively(robust_closed_form_table(scene, config)))
        table = settle_exactly(closed_form_table(scene, config), scene, config)
        return RelationOracle(scene, config, ids, table)
    backend = make_backend(config)
    if config.oracle == "smt":
        return RelationOracle(scene, config, ids, None, backend)
    # hybrid: floats settle the clear pairs; the solver settles the ones inside the guard band.
    table = (robust_closed_form_table if robust else closed_form_table)(scene, config)
    oracle = RelationOracle(scene, config, ids, None, backend)
    pos, head = table.position.copy(), table.heading.copy()
    for kind, r, e in table.undecided():
        (pos if kind == "position" else head)[r, e] = oracle._ask(kind, r, e)
    assert not (pos == UNDECIDED).any() and not (head == UNDECIDED).any()
    oracle.table = RelationTable(ids, pos, head)
    return oracle
