"""A* over declaration orders, f = g + h with h the sum of floors of the undeclared entities.

h relaxes every undeclared entity to its cheapest possible declaration (all others available as references),
so it never overestimates: the first complete program popped is optimal. Without CPA, states are orders (the
same set reached in different orders is kept twice); with CPA, states are declared sets.
"""

from __future__ import annotations

import heapq

from synth.search.budget import Budget, BudgetExhausted
from synth.search.common import SearchResult, finish, greedy_completion
from synth.search.costs import CostModel, bits


def astar(cost_model: CostModel, budget: Budget, cpa: bool) -> SearchResult:
    floors = cost_model.floors()
    h0 = sum(floors)
    # (f, -depth, tie, g, declared, order): deeper first among equal f, then first generated.
    heap = [(h0, 0, 0, 0, 0, ())]
    best_g: dict[int, int] = {0: 0}
    tie = 0
    try:
        while heap:
            budget.tick()  # before the pop: on exhaustion, the open list still holds the least f
            f, _, _, g, declared, order = heapq.heappop(heap)
            if cpa and g > best_g.get(declared, g):
                continue
            if declared == cost_model.all:
                return finish(cost_model, order, f, budget.nodes, None)
            for e in bits(cost_model.all & ~declared):
                g2 = g + cost_model.delta(e, declared)
                d2 = declared | (1 << e)
                if cpa:
                    if d2 in best_g and best_g[d2] <= g2:
                        continue
                    best_g[d2] = g2
                tie += 1
                heapq.heappush(heap, (g2 + f - g - floors[e], -len(order) - 1, tie, g2, d2, order + (e,)))
        raise AssertionError("A* ran out of states before declaring everything")
    except BudgetExhausted as stop:
        f, _, _, g, declared, order = heap[0]
        return finish(cost_model, greedy_completion(cost_model, order, declared), f, budget.nodes, stop.reason)
