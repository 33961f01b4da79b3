"""What every search strategy returns, and the pieces they share: bounds and greedy completion."""

from __future__ import annotations

from dataclasses import dataclass

from synth.search.costs import CostModel, bits


@dataclass(frozen=True)
class SearchResult:
    order: tuple[int, ...]  # declaration order, entity indices 0..n-1
    cost: int
    lower_bound: int
    status: str  # optimal | feasible | timeout | memout
    nodes_expanded: int


def floor_bound(cost_model: CostModel, undeclared: int) -> int:
    """Sum of floors of the undeclared entities: admissible (each costs at least its floor)."""
    floors = cost_model.floors()
    return sum(floors[e] for e in bits(undeclared))


def greedy_completion(cost_model: CostModel, order: tuple[int, ...], declared: int,
                      within: int | None = None) -> tuple[int, ...]:
    """Complete an order by always declaring the entity that loses least against its floor (ties: lowest index).

    `within` limits the completion to a subset (the rest of it); default: every undeclared entity.
    """
    floors = cost_model.floors()
    todo = (cost_model.all if within is None else within) & ~declared
    out = list(order)
    while todo:
        best, best_regret = -1, cost_model.kinds + 1  # above any regret: each part loses at most 1
        for e in bits(todo):
            regret = cost_model.delta(e, declared) - floors[e]
            if regret < best_regret:
                best, best_regret = e, regret
                if regret == 0:
                    break
        out.append(best)
        declared |= 1 << best
        todo &= ~(1 << best)
    return tuple(out)


def finish(cost_model: CostModel, order: tuple[int, ...], lower_bound: int, nodes: int,
           stopped: str | None) -> SearchResult:
    """The anytime answer: optimal when the bound meets the cost; else feasible, or timeout / memout when the
    best program found is no better than declaring everything by fallback (CostModel.ceiling)."""
    cost = cost_model.order_cost(order)
    lower_bound = min(lower_bound, cost)
    if cost == lower_bound:
        status = "optimal"
    elif stopped == "memout":
        status = "memout"
    elif stopped and cost >= cost_model.ceiling:
        status = "timeout"
    else:
        status = "feasible"
    return SearchResult(tuple(order), cost, lower_bound, status, nodes)
