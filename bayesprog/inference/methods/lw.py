"""Approximate, by likelihood weighting: forward draws of the question's relevant terms with the
known variables fixed and each draw weighted by their likelihood
(:mod:`bayesprog.inference.sampling`). Answers every question the exact methods answer, with a
standard error per probability and the effective sample size per row; the error shrinks as
``1 / sqrt(samples)``. Unknown real variables are drawn too (a formula's parents draw by draw),
so it also answers a discrete question where the exact methods do not apply."""

from __future__ import annotations

import numpy as np

from bayesprog.inference.answers import Posterior
from bayesprog.inference.methods.base import PER_FACTOR, Cost, Method, answer, register_method
from bayesprog.inference.plan import QuestionPlan
from bayesprog.inference.sampling import draw, generators
from bayesprog.support.extras import LazyModule

#: scipy.special, imported by the first computation that reads it
special = LazyModule("scipy.special")

#: Draws per evidence row when the question does not say.
DEFAULT_SAMPLES = 10_000


@register_method
class LikelihoodWeighting(Method):
    name = "lw"
    title = "likelihood weighting"
    exact = False
    uncertainty = "stderr"
    continuous = True
    fallback = True

    def why_not(self, plan: QuestionPlan) -> str | None:
        real = [v for v in plan.searched if not plan.program.variables[v].is_discrete]
        if real:
            return (f"{', '.join(real)} is real: likelihood weighting answers discrete searched "
                    "variables (it draws the unknown real ones)")
        return None

    def estimate(self, plan: QuestionPlan) -> Cost | None:
        if self.why_not(plan) is not None:
            return None
        n = plan.options.get("samples", DEFAULT_SAMPLES)
        cards = [plan.card(t.child.name) for t in plan.terms if t.child.is_discrete] or [1]
        draws = float(plan.bound.size) * n
        # a draw of a term gathers its row, sums and compares it: about 90 operations per
        # state (measured on grids, benchmarks/engine.py)
        return Cost(operations=90 * draws * sum(cards), memory=draws * max(cards),
                    fixed=PER_FACTOR * len(plan.terms))

    def posterior(self, plan: QuestionPlan) -> Posterior:
        program, bound, searched = plan.program, plan.bound, plan.searched
        n = plan.options.get("samples", DEFAULT_SAMPLES)
        draws = draw(program, plan.terms, bound, n,
                     generators(plan.options.get("rng"), bound.size))
        cards = tuple(plan.card(v) for v in searched)
        rows = bound.size
        cell = np.ravel_multi_index(tuple(draws.values[v] for v in searched), cards) \
            if searched else np.zeros((rows, n), np.intp)
        w = draws.weights  # [rows, n], each row summing to one
        total = int(np.prod(cards))
        offsets = (np.arange(rows) * total)[:, None]
        probs = np.bincount((cell + offsets).ravel(), weights=w.ravel(),
                            minlength=rows * total).reshape(rows, total)
        # the delta-method standard error of a self-normalised estimate:
        # sum_i w_i^2 (1[x_i = s] - p_s)^2, with w normalised
        sq = np.bincount((cell + offsets).ravel(), weights=(w**2).ravel(),
                         minlength=rows * total).reshape(rows, total)
        w2 = (w**2).sum(axis=1, keepdims=True)
        variance = sq * (1 - 2 * probs) + w2 * probs**2
        stderr = np.sqrt(np.maximum(variance, 0.0))
        with np.errstate(divide="ignore"):
            log_z = special.logsumexp(draws.log_weights, axis=1) - np.log(n)
        return answer(plan, probs, log_z, method=self.name, stderr=stderr, ess=draws.ess,
                      uncertainty=self.uncertainty)
