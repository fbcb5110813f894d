"""Exact, by contraction: the question's factors, each rescaled in log space, contracted by a
cached opt_einsum expression with a batch axis; rows that underflow are redone exactly in log
space. Answers every discrete question, with any evidence, inputs and soft evidence."""

from __future__ import annotations

import numpy as np
from scipy.special import logsumexp

from bayesprog.inference.answers import Posterior
from bayesprog.inference.contract import TINY, contract, log_contract
from bayesprog.inference.core import Factor
from bayesprog.inference.factors import question_factors, rescaled
from bayesprog.inference.methods.base import PER_FACTOR, Cost, Method, answer, register_method
from bayesprog.inference.plan import QuestionPlan


@register_method
class ContractionMethod(Method):
    """Applies to every question of a program whose unobserved variables are discrete."""

    name = "contraction"

    def estimate(self, plan: QuestionPlan) -> Cost | None:
        operations, largest = plan.contraction_cost(plan.searched)
        factors = len(plan.terms) + len(plan.bound.soft)
        return Cost(operations=plan.bound.size * operations, memory=plan.bound.size * largest,
                    fixed=PER_FACTOR * factors)

    def posterior(self, plan: QuestionPlan) -> Posterior:
        return contract_question(plan)


def contract_question(plan: QuestionPlan) -> Posterior:
    """The posterior by scaled contraction, with exact log-space rows where it underflows."""
    factors = question_factors(plan.program, plan.terms, plan.bound)
    return answer(plan, *contract_factors(plan, factors, plan.searched))


def contract_factors(plan: QuestionPlan, factors: list[Factor], searched: tuple[str, ...]
                     ) -> tuple[np.ndarray, np.ndarray]:
    """``factors`` contracted to a normalised table over ``searched`` (``[rows] + cards``),
    and the log of the normaliser per row (``[rows]``)."""
    program, bound = plan.program, plan.bound
    size = bound.size
    operands, offset = rescaled(factors, size)
    batched_out = any(f.batched for f in factors) or bool(bound.batch_shape)
    table = contract(program, operands, searched, batched_out, size)
    if not batched_out:
        table = table[np.newaxis]
    table = np.broadcast_to(table, (size,) + table.shape[1:])
    axes = tuple(range(1, table.ndim))
    z = table.sum(axis=axes)
    with np.errstate(divide="ignore"):
        log_z = np.log(z) + offset
    # a row is bad when its scaled contraction underflowed, or an observed value's own
    # probability (folded into the offset) is zero: both are redone exactly in log space
    bad = ~(z > TINY) | ~np.isfinite(z) | ~np.isfinite(offset)
    probs = np.empty_like(table)
    good = ~bad
    probs[good] = table[good] / z[good].reshape((-1,) + (1,) * len(axes))
    if np.any(bad):
        for row in np.flatnonzero(bad):
            logs = [(f.axes, f.log[row] if f.batched else f.log) for f in factors]
            lt = log_contract(logs, searched)
            total = logsumexp(lt) if np.isfinite(lt).any() else -np.inf
            log_z[row] = total
            probs[row] = np.exp(lt - total) if np.isfinite(total) else 0.0
    return probs, log_z
