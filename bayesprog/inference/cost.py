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
        if (exact and not method.exact) or (plan.latent and not method.continuous):
            continue
        cost = method.estimate(plan)
        if cost is not None:
            found.append((cost.operations + cost.fixed + cost.setup, cost.memory, order, method,
                          cost))
    found.sort(key=lambda item: item[:3])
    if exact and not found:
        # no exact method: one that answers approximately and states its error
        return [(m, c) for m, c in ranked(plan, exact=False) if m.fallback]
    return [(method, cost) for *_, method, cost in found]


def unanswerable(plan: QuestionPlan) -> str:
    """Why no method answers ``plan``: each method's own reason."""
    reasons = [f"{m.name}: {why}" for m in registered_methods().values()
               if (why := m.why_not(plan)) is not None]
    unknown = ", ".join(plan.latent)
    head = (f"{plan.question.expression}: no method answers with {unknown} unknown"
            if plan.latent else f"no method answers {plan.question.expression}")
    return head + ("; " + "; ".join(reasons) if reasons else "")
