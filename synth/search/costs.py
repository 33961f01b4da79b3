"""c(e, E): the cost of declaring entity e when the set E (plus ego) is already declared.

Position costs 0 when some declared reference is a position witness of e (e is ahead of / behind / left of /
right of it), else 1 (`on Range @ Range relative to ego`); heading likewise with facing toward / away from.
c depends only on the set E, never on its order (the paper's Common Prefix Abstraction), and only falls as E
grows. Sets are Python ints used as bitsets over the entities to declare, numbered 0..n-1 in scene order.
"""

from __future__ import annotations

import math

import numpy as np

from synth.oracle import RelationOracle
from synth.relations import NONE

POSITION, HEADING = 0, 1


class CostModel:
    def __init__(self, oracle: RelationOracle):
        self.oracle = oracle
        self.n = len(oracle.ids) - 1
        self.all = (1 << self.n) - 1
        n = self.n
        if oracle.complete:
            t = oracle.table
            self._ego = [list(t.position[0, 1:] != NONE), list(t.heading[0, 1:] != NONE)]
            self._mask = [
                [sum(1 << int(r) for r in np.nonzero(m[1:, e + 1] != NONE)[0]) for e in range(n)]
                for m in (t.position, t.heading)
            ]
            self._known = [[self.all] * n, [self.all] * n]
        else:
            # The smt oracle: ask lazily, nearest reference first (Alg. 4's order), and remember.
            self._ego = [[None] * n, [None] * n]
            self._mask = [[0] * n, [0] * n]
            self._known = [[1 << e for e in range(n)], [1 << e for e in range(n)]]
            ents = oracle.entities()[1:]
            self._nearest = [
                sorted((r for r in range(n) if r != e),
                       key=lambda r, e=e: (math.hypot(ents[r].x - ents[e].x, ents[r].y - ents[e].y), r))
                for e in range(n)
            ]
        self._floors: list[int] | None = None

    # ------------------------------------------------------------------------------------- witnesses
    def _ask(self, kind: int, r: int, e: int) -> bool:
        # Oracle indices: 0 is ego, entity i is i + 1.
        ask = self.oracle.position if kind == POSITION else self.oracle.heading
        return ask(r + 1, e + 1) != NONE

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
        return (not self.has_witness(POSITION, e, declared)) + (not self.has_witness(HEADING, e, declared))

    # ------------------------------------------------------------------------------------- bounds
    def floors(self) -> list[int]:
        """floor(e) = c(e, all others): the least e can ever cost (asks every pair in smt mode)."""
        if self._floors is None:
            self._floors = [self.delta(e, self.all & ~(1 << e)) for e in range(self.n)]
        return self._floors

    def witness_mask(self, e: int) -> int:
        """Every entity that witnesses e's position or heading (needs an oracle with every pair known)."""
        if not self.oracle.complete:
            raise RuntimeError("witness_mask needs a complete relation table (call oracle.full_table())")
        return self._mask[POSITION][e] | self._mask[HEADING][e]

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
