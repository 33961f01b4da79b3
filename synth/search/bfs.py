"""Breadth-first search over declaration orders (the paper's Alg. 2), with and without Common Prefix Abstraction.

Layer k holds partial programs that declare k entities. With CPA, the layer is a table keyed by the declared
set, keeping the cheapest prefix per set (first found on ties): O(N 2^N). Without it every order survives: O(N!).
"""

from __future__ import annotations

from synth.search.budget import Budget, BudgetExhausted
from synth.search.common import SearchResult, finish, greedy_completion
from synth.search.costs import CostModel, bits


def bfs(cost_model: CostModel, budget: Budget, cpa: bool = True) -> SearchResult:
    # A layer: declared set -> (cost, order) with CPA; a list of (cost, declared, order) without.
    layer: list[tuple[int, int, tuple[int, ...]]] = [(0, 0, ())]
    try:
        for _depth in range(cost_model.n):
            table: dict[int, tuple[int, tuple[int, ...]]] = {}
            nxt: list[tuple[int, int, tuple[int, ...]]] = []
            for cost, declared, order in layer:
                budget.tick()
                for e in bits(cost_model.all & ~declared):
                    c = cost + cost_model.delta(e, declared)
                    key = declared | (1 << e)
                    if cpa:
                        if key not in table or c < table[key][0]:
                            table[key] = (c, order + (e,))
                    else:
                        nxt.append((c, key, order + (e,)))
            layer = [(c, k, o) for k, (c, o) in table.items()] if cpa else nxt
        best = min(layer, key=lambda s: s[0])
        return finish(cost_model, best[2], best[0], budget.nodes, None)
    except BudgetExhausted as stop:
        # Every complete program passes through the current layer (with CPA, through a state at least as
        # cheap). Each layer state still has the same number of entities to declare, each costing at least its
        # floor, so the least g plus the smallest floors of that many entities bounds the optimum; computed in
        # one pass, since a layer can hold millions of states and the time is already up.
        cost, declared, order = min(layer, key=lambda s: s[0])
        todo = cost_model.n - len(order)
        lb = cost + sum(sorted(cost_model.floors())[:todo])
        return finish(cost_model, greedy_completion(cost_model, order, declared), lb, budget.nodes, stop.reason)
