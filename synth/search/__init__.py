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
    "bfs": lambda cm, b: bfs(cm, b, cpa=False),
    "bfs-cpa": lambda cm, b: bfs(cm, b, cpa=True),
    "dfs": lambda cm, b: dfs(cm, b, bnb=False, cpa=False),
    "dfs-bnb": lambda cm, b: dfs(cm, b, bnb=True, cpa=False),
    "dfs-cpa": lambda cm, b: dfs(cm, b, bnb=False, cpa=True),
    "dfs-bnb-cpa": lambda cm, b: dfs(cm, b, bnb=True, cpa=True),
    "astar": lambda cm, b: astar(cm, b, cpa=False),
    "astar-cpa": lambda cm, b: astar(cm, b, cpa=True),
    "monolithic": monolithic,
}


def search(strategy: str, cm: CostModel, budget: Budget) -> SearchResult:
    if cm.n == 0:
        return SearchResult((), 0, 0, "optimal", 0)
    return _STRATEGIES[strategy](cm, budget)


__all__ = ["Budget", "CostModel", "SearchResult", "search"]
