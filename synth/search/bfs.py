"""Breadth-first search over declaration orders (the paper's Alg. 2), with and without Common Prefix Abstraction.

Layer k holds partial programs that declare k entities. With CPA, the layer is a table keyed by the declared
set, keeping the cheapest prefix per set (first found on ties): O(N 2^N). Without it every order survives: O(N!).
"""

from __future__ import annotations

from synth.search.budget import Budget, BudgetExhausted
from synth.search.common import SearchResult, finish, floor_bound, greedy_completion
from synth.search.costs import CostModel, bits


def bfs(cm: CostModel, budget: Budget, cpa: bool = True) -> SearchResult:
    # A layer: declared set -> (cost, order) with CPA; a list of (cost, declared, order) without.
    layer: list[tuple[int, int, tuple[int, ...]]] = [(0, 0, ())]
    try:
        for _depth in range(cm.n):
            table: dict[int, tuple[int, tuple[int, ...]]] = {}
            nxt: list[tuple[int, int, tuple[int, ...]]] = []
            for cost, declared, order in layer:
                budget.tick()
                for e in bits(cm.all & ~declared):
                    c = cost + cm.delta(e, declared)
                    key = declared | (1 << e)
                    if cpa:
                        if key not in table or c < table[key][0]:
                            table[key] = (c, order + (e,))
                    else:
                        nxt.append((c, key, order + (e,)))
            layer = [(c, k, o) for k, (c, o) in table.items()] if cpa else nxt
        best = min(layer, key=lambda s: s[0])
        return finish(cm, best[2], best[0], budget.nodes, None)
    except BudgetExhausted as stop:
        # Every complete program passes through the current layer (with CPA, through a state at least as
        # cheap), so its least g + h bounds the optimum; its best state, completed greedily, is the answer.
        frontier = [(c + floor_bound(cm, cm.all & ~d), c, d, o) for c, d, o in layer]
        lb = min(f for f, *_ in frontier)
        _, _, declared, order = min(frontier)
        return finish(cm, greedy_completion(cm, order, declared), lb, budget.nodes, stop.reason)
