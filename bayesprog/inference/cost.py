"""The cost model: of the methods that apply to a question, the cheapest by estimated
operations (ties: the smaller memory, then the first registered). Approximate methods are
ranked only when asked for: a question is answered exactly unless it names its method."""

from __future__ import annotations

from bayesprog.inference.methods import Cost, Method, registered_methods
from bayesprog.inference.plan import QuestionPlan


def ranked(plan: QuestionPlan, exact: bool = True) -> list[tuple[Method, Cost]]:
    """The methods that apply to ``plan`` with their estimates, cheapest first (the exact
    ones only, unless ``exact`` is False)."""
    found = []
    for order, method in enumerate(registered_methods().values()):
        if exact and not method.exact:
            continue
        cost = method.estimate(plan)
        if cost is not None:
            found.append((cost.operations, cost.memory, order, method, cost))
    found.sort(key=lambda item: item[:3])
    return [(method, cost) for *_, method, cost in found]
