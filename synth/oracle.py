"""Relation oracles: who witnesses whom. `closed-form`, `hybrid` (default) and `smt` (the paper's way).

An oracle answers, for a target e, a reference r (ego or another entity) and a statement part, which of the
part's witness relations holds, if any (a part's relations are disjoint: direction sectors are 2 delta1 wide and
90 degrees apart, facing toward and away from are opposite). Answers are cached per (relation, target,
reference), the paper's M_smt (relation names are unique across parts). A part whose questions are robust ones
on this scene (synth.robust) gets the robust table and the robust solver question; the others the plain ones.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from synth.config import SynthConfig
from synth.parts import Part, parts_for
from synth.perturbation import bounds_of
from synth.relations import settle_exactly
from synth.robust import robust_parts, settle_conservatively
from synth.scene import Entity, Scene
from synth.smt import SolverBackend, make_backend
from synth.tables import NONE, UNDECIDED, RelationTable, scene_arrays


@dataclass
class RelationOracle:
    """Answers relation questions about one scene, part by part, lazily where it asks a solver."""

    scene: Scene
    config: SynthConfig
    ids: tuple[str, ...] = ()
    table: RelationTable | None = None
    backend: SolverBackend | None = None
    parts: tuple[Part, ...] = ()
    # The paper's M_smt: (relation, target index, reference index) -> does the relation hold.
    cache: dict[tuple[str, int, int], bool] = field(default_factory=dict)
    # A window's oracle (synth.window.program): each entity's poses in the frames it is in, over which its fallback is weighed.
    poses: Mapping[str, tuple[Entity, ...]] | None = None

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

    def relation(self, k: int, r: int, e: int) -> int:
        """Code of part k's relation of e with reference r (an index into its relations), or NONE."""
        if self.table is not None:
            return int(self.table[self.parts[k].name][r, e])
        return self._ask(self.parts[k], r, e)

    def position(self, r: int, e: int) -> int:
        return self.relation(0, r, e)

    def heading(self, r: int, e: int) -> int:
        return self.relation(1, r, e)

    def _ask(self, part: Part, r: int, e: int) -> int:
        """Ask relation by relation, as Alg. 4 does, through the cache; the first that holds is the answer."""
        if r == e:
            return NONE
        ents = self.entities()
        for code in part.codes_from(r == 0):
            key = (part.relations[code], e, r)
            if key not in self.cache:
                self.cache[key] = part.ask(self.backend, code, ents[r], ents[e])
            if self.cache[key]:
                return code
        return NONE

    def holds(self, k: int, code: int, r: int, e: int) -> bool:
        """Does relation `code` of part k hold between r and e, not only the one the table records? A disjoint
        part's relations exclude each other but for one that needs no reference (Part.refless), recorded in ego's
        row over the others (stationary over `moving like ego`): only there is another one asked; a part whose
        relations are not disjoint (Part.disjoint: lanes) is asked wherever one holds (synth.window.program needs it, as
        a window's frames may agree on a relation the table does not record)."""
        part = self.parts[k]
        found = self.relation(k, r, e)
        if found == code or found == NONE:
            return found == code
        if part.disjoint and (found not in part.refless or r != 0):
            return False
        ents = self.entities()
        if self.backend is None:  # closed form: exact, or conservative for a robust part (settle_conservatively)
            if not part.is_robust(self.scene, self.config):
                return part.exact(code, ents[r], ents[e], self.config)
            return bool(part.robust_exact(code, ents[r], ents[e], self.config))
        key = (part.relations[code], e, r)
        if key not in self.cache:
            self.cache[key] = part.ask(self.backend, code, ents[r], ents[e])
        return self.cache[key]

    def fallback_cost(self, k: int, e: int) -> int:
        """What part k costs entity e without a witness (Part.fallback_cost; a window's oracle: over the frames e
        is in, Part.window_fallback_cost)."""
        if self.poses is not None:
            return self.parts[k].window_fallback_cost(self.poses[self.ids[e]], self.config)
        return self.parts[k].fallback_cost(self.entities()[e], self.config)

    def full_table(self) -> RelationTable:
        """Every pair answered (the smt oracle asks the solver for each one it has not asked yet)."""
        if self.table is not None:
            return self.table
        n = len(self.ids)
        codes = {p.name: np.array([[self.relation(k, r, e) for e in range(n)] for r in range(n)], dtype=np.int8)
                 for k, p in enumerate(self.parts)}
        self.table = RelationTable(self.ids, codes)
        return self.table


def float_table(scene: Scene, config: SynthConfig, parts: tuple[Part, ...], robust: frozenset[str]) -> RelationTable:
    """Every part's float decisions: the robust question for the parts in `robust`, the plain one otherwise."""
    arrays = scene_arrays(scene)
    bounds = [bounds_of(e, config) for e in (scene.ego,) + scene.others] if robust else []
    return RelationTable(arrays.ids, {
        p.name: p.robust_closed_form(arrays, bounds, config) if p.name in robust else p.closed_form(arrays, config)
        for p in parts})


def make_oracle(scene: Scene, config: SynthConfig) -> RelationOracle:
    """The oracle the config names. Index 0 is ego, then the scene's other entities in scene order."""
    ids = (scene.ego.id,) + tuple(e.id for e in scene.others)
    parts = parts_for(config)
    robust = robust_parts(scene, config, parts)
    if config.oracle == "closed-form":
        table = float_table(scene, config, parts, robust)
        plain = settle_exactly(table.replaced({n: c for n, c in table.codes.items() if n not in robust}), scene,
                               config)
        # Robust pairs the floats cannot settle are not claimed (no solver to decide them): conservative.
        sure = settle_conservatively(table.replaced({n: c for n, c in table.codes.items() if n in robust}))
        codes = {p.name: (sure if p.name in robust else plain)[p.name] for p in parts}
        return RelationOracle(scene, config, ids, table.replaced(codes), parts=parts)
    backend = make_backend(config)
    if config.oracle == "smt":
        return RelationOracle(scene, config, ids, None, backend, parts)
    # hybrid: floats settle the clear pairs; the solver settles the ones inside the guard band.
    table = float_table(scene, config, parts, robust)
    oracle = RelationOracle(scene, config, ids, None, backend, parts)
    codes = {name: c.copy() for name, c in table.codes.items()}
    by_name = {p.name: p for p in parts}
    for name, r, e in table.undecided():
        codes[name][r, e] = oracle._ask(by_name[name], r, e)
    assert not any((c == UNDECIDED).any() for c in codes.values())
    oracle.table = table.replaced(codes)
    return oracle
