"""Exact, by contraction (:mod:`bayesprog.inference.contraction`): answers every discrete
question, with any evidence, inputs and soft evidence, and a layout's first question with
nothing planned when its terms are tables."""

from __future__ import annotations

import numpy as np

from bayesprog.inference.answers import Posterior
from bayesprog.inference.contraction import contract_question, first_question
from bayesprog.inference.factors import is_static
from bayesprog.inference.methods.base import (
    PER_CALL,
    PER_FACTOR,
    PER_PREPARED,
    Cost,
    Method,
    register_method,
)
from bayesprog.inference.plan import Layout, QuestionPlan


@register_method
class ContractionMethod(Method):
    """Applies to every question of a program whose unobserved variables are discrete."""

    name = "contraction"
    answers_first = True
    ablates_rows = True

    def first_question(self, plan: QuestionPlan) -> tuple[np.ndarray, np.ndarray, int] | None:
        return first_question(plan)

    def estimate(self, plan: QuestionPlan) -> Cost | None:
        operations, largest = plan.contraction_cost(plan.searched)
        prepared = sum(1 for t in plan.terms if is_static(t))
        computed = len(plan.terms) - prepared + len(plan.bound.soft)
        return Cost(operations=plan.bound.size * operations, memory=plan.bound.size * largest,
                    fixed=PER_CALL + PER_PREPARED * prepared + PER_FACTOR * computed)

    def prepared_row(self, layout: Layout, values: dict[str, int]
                     ) -> tuple[np.ndarray, float] | None:
        prepared = layout.prepared.get("contraction")
        if prepared is None or prepared.single is None or prepared.others:
            return None
        return prepared.row(values)

    def posterior(self, plan: QuestionPlan) -> Posterior:
        return contract_question(plan)
