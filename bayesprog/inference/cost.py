"""The cost model: of the methods that apply to a question, the cheapest by estimated
operations (ties: the smaller memory, then the first registered). Approximate methods are
ranked only when asked for: a question is answered exactly unless it names its method."""

from __future__ import annotations

from bayesprog.inference.methods import Cost, Method, registered_methods
from bayesprog.inference.plan import QuestionPlan


def ranked(plan: QuestionPlan, exact: bool = True, quick: bool = False
           ) -> list[tuple[Method, Cost]]:
    """The methods that apply to ``plan`` with their estimates, cheapest first (the exact
    ones only, unless ``exact`` is False); ``quick``: their quick estimates (some bounds
    marked ``floor``, see :func:`refined`)."""
    found = []
    for method in registered_methods().values():
        if (exact and not method.exact) or (plan.latent and not method.continuous) or (
                plan.bound.ablated and not method.ablates_rows):
            continue
        cost = method.quick_estimate(plan) if quick else method.estimate(plan)
        if cost is not None:
            found.append((method, cost))
    if exact and not found:
        # no exact method: one that answers approximately and states its error
        return [(m, c) for m, c in ranked(plan, exact=False, quick=quick) if m.fallback]
    return in_order(found)


def refined(plan: QuestionPlan, methods: list[tuple[Method, Cost]]
            ) -> list[tuple[Method, Cost]]:
    """``methods`` with each quick estimate (``floor``) replaced by the full one, in order."""
    found = [(m, m.estimate(plan) if c.floor else c) for m, c in methods]
    return in_order([(m, c) for m, c in found if c is not None])


def in_order(methods: list[tuple[Method, Cost]]) -> list[tuple[Method, Cost]]:
    """Cheapest first by total operations; ties: the smaller memory, then the first
    registered."""
    order = {name: i for i, name in enumerate(registered_methods())}
    return sorted(methods, key=lambda mc: (mc[1].operations + mc[1].fixed + mc[1].setup,
                                           mc[1].memory, order[mc[0].name]))


def unanswerable(plan: QuestionPlan) -> str:
    """Why no method answers ``plan``: each method's own reason."""
    reasons = [f"{m.name}: {why}" for m in registered_methods().values()
               if (why := why_not(m, plan)) is not None]
    unknown = ", ".join(plan.latent)
    head = (f"{plan.question.expression}: no method answers with {unknown} unknown"
            if plan.latent else f"no method answers {plan.question.expression}")
    return head + ("; " + "; ".join(reasons) if reasons else "")


def why_not(method: Method, plan: QuestionPlan) -> str | None:
    """Why ``method`` does not answer ``plan`` (None: it does, or has nothing to say)."""
    if plan.bound.ablated and not method.ablates_rows:
        return ("a term made uniform on some rows of the batch (ablate=...) is answered by "
                + ", ".join(m.name for m in registered_methods().values() if m.ablates_rows))
    return method.why_not(plan)
