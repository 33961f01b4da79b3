"""c(e, E): the cost of declaring entity e when the set E (plus ego) is already declared.

Each statement part costs 0 when some declared reference is a witness of e for it (for position: e is ahead
of / behind / left of / right of it; for heading: e faces toward / away from it), else its fallback's cost (1,
relative to ego, for the paper's parts; the lane part's depends on e, and over a window on e's frames:
RelationOracle.fallback_cost); c(e, E) is the sum over the parts. It depends only on the set E, never on its order (the paper's
Common Prefix Abstraction), and only falls as E grows. Sets are Python ints used as bitsets over the entities to
declare, numbered 0..n-1 in scene order.
"""

from __future__ import annotations

import math

import numpy as np

from synth.oracle import RelationOracle
from synth.tables import NONE

POSITION, HEADING = 0, 1  # part indices of the paper's two parts (oracle.parts order)


class CostModel:
    def __init__(self, oracle: RelationOracle):
        self.oracle = oracle
        self.n = len(oracle.ids) - 1
        self.all = (1 << self.n) - 1
        n = self.n
        # Units: a part whose fallback costs w for an entity (Part.fallback_cost; 1 for the paper's parts) counts
        # as w unit parts with its witnesses, the units above an entity's own w met for it from the start, so that
        # c(e, E) stays a count of unmet units: unit (k, j) is unmet iff part k has no declared witness and the
        # fallback costs j or more.
        ents = oracle.entities()[1:]
        weights = [[oracle.fallback_cost(k, e) for e in range(1, n + 1)] for k in range(len(oracle.parts))]
        self.unit_part = [k for k, w in enumerate(weights) for _ in range(max(w, default=1))]
        level = [j for w in weights for j in range(1, max(w, default=1) + 1)]
        free = [sum(1 << e for e in range(n) if weights[k][e] < j) for k, j in zip(self.unit_part, level)]
        # Units per statement: also the cost of an entity no one witnesses (every part at its fallback).
        self.kinds = len(self.unit_part)
        kinds = range(self.kinds)
        if oracle.complete:
            t = oracle.table
            codes = [t[oracle.parts[k].name] for k in self.unit_part]
            # Ego's row also holds the witnesses that need no reference (Part.refless): always available.
            self._ego = [[bool(ego) or bool(f >> e & 1) for e, ego in enumerate(c[0, 1:] != NONE)]
                         for c, f in zip(codes, free)]
            self._mask = [[sum(1 << int(r) for r in np.nonzero(c[1:, e + 1] != NONE)[0]) for e in range(n)]
                          for c in codes]
            self._known = [[self.all] * n for _ in kinds]
        else:
            # The smt oracle: ask lazily, nearest reference first (Alg. 4's order), and remember.
            self._ego = [[True if f >> e & 1 else None for e in range(n)] for f in free]
            self._mask = [[0] * n for _ in kinds]
            self._known = [[1 << e for e in range(n)] for _ in kinds]
            self._nearest = [
                sorted((r for r in range(n) if r != e),
                       key=lambda r, e=e: (math.hypot(ents[r].x - ents[e].x, ents[r].y - ents[e].y), r))
                for e in range(n)
            ]
        # The cost of declaring every entity by its fallbacks (no witness at all): the worst order's cost.
        self.ceiling = sum(sum(w) for w in weights)
        self._floors: list[int] | None = None
        if oracle.complete:
            self._bitsets()

    def _bitsets(self) -> None:
        """The witness relation as bitsets per part, for searches that keep c(e, E) up to date incrementally:
        lonely[k] (no witness at all: part k always costs 1), ego_fed[k] (ego witnesses part k) and fed_by[k][r]
        (the entities whose part k r witnesses). A search state's unmet sets are packed into one int, part k in
        bits k*n .. k*n + n - 1, so that declaring an entity is one operation."""
        n, all_ = self.n, self.all
        self.lonely, self.ego_fed, self.fed_by = [], [], []
        for k in range(self.kinds):
            ego = sum(1 << e for e in range(n) if self._ego[k][e])
            fed = [0] * n
            lonely = 0
            for e in range(n):
                if not self._ego[k][e] and not self._mask[k][e]:
                    lonely |= 1 << e
                for r in bits(self._mask[k][e]):
                    fed[r] |= 1 << e
            self.lonely.append(lonely & all_)
            self.ego_fed.append(ego)
            self.fed_by.append(fed)
        self._fed_packed = [sum(self.fed_by[k][r] << (k * n) for k in range(self.kinds)) for r in range(n)]
        self._one_per_part = sum(1 << (k * n) for k in range(self.kinds))
        self.floor_of = [sum(lonely >> e & 1 for lonely in self.lonely) for e in range(n)]

    # ------------------------------------------------------------------------------------- incremental costs
    def unmet(self, declared: int) -> int:
        """Per part, the entities that have a witness but none among ego and `declared`, packed (see _bitsets):
        c(e, E) is floor(e) plus the number of parts whose unmet set holds e."""
        out = 0
        for k in range(self.kinds):
            fed = self.ego_fed[k] | self.lonely[k]
            for r in bits(declared):
                fed |= self.fed_by[k][r]
            out |= (self.all & ~fed) << (k * self.n)
        return out

    def declare(self, unmet: int, e: int) -> int:
        """unmet after declaring e: only the entities e witnesses change."""
        return unmet & ~self._fed_packed[e]

    def parts_of(self, unmet: int) -> list[int]:
        """The packed unmet sets, one bitset per part."""
        return [(unmet >> (k * self.n)) & self.all for k in range(self.kinds)]

    def union(self, unmet: int) -> int:
        """The entities unmet in some part: those that would pay over their floor if declared now."""
        out = 0
        for k in range(self.kinds):
            out |= unmet >> (k * self.n)
        return out & self.all

    def regret(self, unmet: int, e: int) -> int:
        """c(e, E) - floor(e): the parts of e still without a declared witness."""
        return ((unmet >> e) & self._one_per_part).bit_count()

    def floor_sum(self, todo: int) -> int:
        """Sum of floors over a set: the parts that can never have a witness."""
        return sum((todo & lonely).bit_count() for lonely in self.lonely)

    # ------------------------------------------------------------------------------------- witnesses
    def _ask(self, kind: int, r: int, e: int) -> bool:
        # Oracle indices: 0 is ego, entity i is i + 1; a unit asks its part.
        return self.oracle.relation(self.unit_part[kind], r + 1, e + 1) != NONE

    def ego_witness(self, kind: int, e: int) -> bool:
        known = self._ego[kind][e]
        if known is None:
            known = self._ego[kind][e] = self._ask(kind, -1, e)
        return known

    def has_witness(self, kind: int, e: int, declared: int) -> bool:
        if self.ego_witness(kind, e) or self._mask[kind][e] & declared:
            return True
        unknown = declared & ~self._known[kind][e]
        if not unknown:
            return False
        for r in self._nearest[e]:
            if unknown >> r & 1:
                self._known[kind][e] |= 1 << r
                if self._ask(kind, r, e):
                    self._mask[kind][e] |= 1 << r
                    return True
        return False

    def delta(self, e: int, declared: int) -> int:
        return sum(not self.has_witness(kind, e, declared) for kind in range(self.kinds))

    # ------------------------------------------------------------------------------------- bounds
    def floors(self) -> list[int]:
        """floor(e) = c(e, all others): the least e can ever cost (asks every pair in smt mode)."""
        if self._floors is None:
            self._floors = [self.delta(e, self.all & ~(1 << e)) for e in range(self.n)]
        return self._floors

    def witness_mask(self, e: int) -> int:
        """Every entity that witnesses some part of e (needs an oracle with every pair known)."""
        if not self.oracle.complete:
            raise RuntimeError("witness_mask needs a complete relation table (call oracle.full_table())")
        mask = 0
        for kind in range(self.kinds):
            mask |= self._mask[kind][e]
        return mask

    def order_cost(self, order: tuple[int, ...] | list[int]) -> int:
        declared, total = 0, 0
        for e in order:
            total += self.delta(e, declared)
            declared |= 1 << e
        return total


def bits(mask: int):
    """Indices of the set bits, lowest first."""
    while mask:
        low = mask & -mask
        yield low.bit_length() - 1
        mask ^= low
