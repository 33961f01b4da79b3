"""Search over declaration orders, by strategy name."""

from __future__ import annotations

from synth.search.astar import astar
from synth.search.auto import auto
from synth.search.bfs import bfs
from synth.search.budget import Budget
from synth.search.common import SearchResult
from synth.search.costs import CostModel
from synth.search.dfs import dfs
from synth.search.monolithic import monolithic

_STRATEGIES = {
    "auto": auto,
    "bfs": lambda cost_model, budget: bfs(cost_model, budget, cpa=False),
    "bfs-cpa": lambda cost_model, budget: bfs(cost_model, budget, cpa=True),
    "dfs": lambda cost_model, budget: dfs(cost_model, budget, bnb=False, cpa=False),
    "dfs-bnb": lambda cost_model, budget: dfs(cost_model, budget, bnb=True, cpa=False),
    "dfs-cpa": lambda cost_model, budget: dfs(cost_model, budget, bnb=False, cpa=True),
    "dfs-bnb-cpa": lambda cost_model, budget: dfs(cost_model, budget, bnb=True, cpa=True),
    "astar": lambda cost_model, budget: astar(cost_model, budget, cpa=False),
    "astar-cpa": lambda cost_model, budget: astar(cost_model, budget, cpa=True),
    "monolithic": monolithic,
}


def search(strategy: str, cost_model: CostModel, budget: Budget) -> SearchResult:
    if cost_model.n == 0:
        return SearchResult((), 0, 0, "optimal", 0)
    return _STRATEGIES[strategy](cost_model, budget)


__all__ = ["Budget", "CostModel", "SearchResult", "search"]
