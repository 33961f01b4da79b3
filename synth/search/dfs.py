"""Depth-first search over declaration orders (the paper's Alg. 3) with optional Branch-and-Bound and CPA.

B&B drops a partial program whose cost already reaches the best complete one; CPA keeps a global table of the
least cost seen per declared set and drops any prefix that does not improve on it.
"""

from __future__ import annotations

from synth.search.budget import Budget, BudgetExhausted
from synth.search.common import SearchResult, finish, floor_bound, greedy_completion
from synth.search.costs import CostModel, bits


def dfs(cost_model: CostModel, budget: Budget, bnb: bool, cpa: bool) -> SearchResult:
    best_cost, best_order = float("inf"), None
    seen: dict[int, int] = {}
    stack: list[tuple[int, int, tuple[int, ...]]] = [(0, 0, ())]
    try:
        while stack:
            cost, declared, order = stack.pop()
            budget.tick()
            if cpa:
                if declared in seen and cost >= seen[declared]:
                    continue
                seen[declared] = cost
            if bnb and cost >= best_cost:
                continue
            if declared == cost_model.all:
                if cost < best_cost:
                    best_cost, best_order = cost, order
                continue
            # Pushed in reverse so that the lowest index is explored first.
            for e in sorted(bits(cost_model.all & ~declared), reverse=True):
                stack.append((cost + cost_model.delta(e, declared), declared | (1 << e), order + (e,)))
        return finish(cost_model, best_order, best_cost, budget.nodes, None)
    except BudgetExhausted as stop:
        lb = floor_bound(cost_model, cost_model.all)
        if best_order is None:
            cost, declared, order = stack[-1] if stack else (0, 0, ())
            best_order = greedy_completion(cost_model, order, declared)
        return finish(cost_model, best_order, lb, budget.nodes, stop.reason)
