"""Approximate, by loopy belief propagation: sum-product messages between the question's
factors (sliced by the evidence) and its unobserved discrete variables, every evidence row at
once, until the largest change of a message falls under a tolerance. Exact on programs whose
factor graph is a tree; on loopy ones a fixed point of the Bethe approximation, with no bound on
its error. Answers the marginal of one searched variable, or of searched variables that share a
factor; reports its iterations and last change (``residual``)."""

from __future__ import annotations

from typing import Any

import numpy as np
from opt_einsum import contract, get_symbol

from bayesprog.errors import QuestionError
from bayesprog.inference.answers import Posterior
from bayesprog.inference.core import Factor
from bayesprog.inference.factors import slice_factor, term_factor
from bayesprog.inference.methods.base import Cost, Method, answer, register_method
from bayesprog.inference.plan import QuestionPlan

#: Sweeps over all messages at most, and the change of a message that counts as converged.
MAX_ITERATIONS, TOLERANCE = 200, 1e-10


@register_method
class LoopyBeliefPropagation(Method):
    name = "lbp"
    exact = False

    def estimate(self, plan: QuestionPlan) -> Cost | None:
        if plan.bound.continuous and any(not plan.program.variables[t.child.name].is_discrete
                                         and t.child.name not in plan.bound.continuous
                                         for t in plan.terms):
            return None
        sizes = [plan.free_size(t.axes) for t in plan.terms] or [1]
        iterations = plan.options.get("max_iterations", MAX_ITERATIONS)
        size = float(plan.bound.size)
        return Cost(operations=size * iterations * sum(sizes) * 4,
                    memory=size * max(sizes))

    def posterior(self, plan: QuestionPlan) -> Posterior:
        program, bound, searched = plan.program, plan.bound, plan.searched
        rows = bound.size
        factors = []  # (axes, table [rows, cards...]) in the probability domain, rescaled
        offset = np.zeros(rows)
        for term in plan.terms:
            factors.append(slice_factor(term_factor(program, term, bound), bound))
        for name, pv in bound.soft.items():
            with np.errstate(divide="ignore"):
                factors.append(slice_factor(Factor((name,), np.log(pv.array), pv.batched),
                                            bound))
        tables: list[tuple[tuple[str, ...], np.ndarray]] = []
        for f in factors:
            log = f.log if f.batched else f.log[np.newaxis]
            log = np.broadcast_to(log, (rows,) + log.shape[1:])
            axes_r = tuple(range(1, log.ndim))
            top = np.max(log, axis=axes_r, keepdims=True) if axes_r else log
            top = np.where(np.isfinite(top), top, 0.0)
            offset += top.reshape(rows)
            if f.axes:
                tables.append((f.axes, np.exp(log - top)))
        variables = sorted({a for axes, _ in tables for a in axes} | set(searched))
        card = {v: plan.card(v) for v in variables}
        iterations = plan.options.get("max_iterations", MAX_ITERATIONS)
        tolerance = plan.options.get("tolerance", TOLERANCE)
        beliefs, residual, done = _propagate(tables, variables, card, rows, iterations, tolerance)
        home = next((i for i, (axes, _) in enumerate(tables) if set(searched) <= set(axes)), None)
        if len(searched) == 1:
            probs = beliefs["var"][searched[0]]
        elif home is not None:
            probs = beliefs["factor"](home, searched)
        else:
            raise QuestionError(f"lbp answers the marginal of one variable, or of variables "
                                f"that share a term; {', '.join(searched)} do not: ask them "
                                "one at a time, or use method='lw'")
        cards = tuple(card[v] for v in searched)
        total = probs.reshape(rows, -1).sum(axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            probs = probs / total.reshape((-1,) + (1,) * len(cards))
        zero = ~(total > 0)
        log_z = np.where(zero, -np.inf, np.nan)  # lbp estimates no evidence
        return answer(plan, np.where(zero.reshape((-1,) + (1,) * len(cards)), 0.0, probs), log_z,
                      method=self.name, iterations=done, residual=residual)


def _normalised(m: np.ndarray) -> np.ndarray:
    total = m.sum(axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(total > 0, m / total, 1.0 / m.shape[-1])


def _propagate(tables: list[tuple[tuple[str, ...], np.ndarray]], variables: list[str],
               card: dict[str, int], rows: int, iterations: int,
               tolerance: float) -> tuple[dict[str, Any], float, int]:
    """Flooding schedule: all factor-to-variable messages from the variable-to-factor ones of
    the previous sweep, then the reverse. Returns beliefs, the last residual and the sweeps."""
    letters = {v: get_symbol(i + 1) for i, v in enumerate(variables)}
    batch = get_symbol(0)
    neighbours: dict[str, list[int]] = {v: [] for v in variables}
    for i, (axes, _) in enumerate(tables):
        for v in axes:
            neighbours[v].append(i)
    to_var = {(i, v): np.full((rows, card[v]), 1.0 / card[v])
              for i, (axes, _) in enumerate(tables) for v in axes}
    to_factor = dict(to_var)
    specs = {}
    for i, (axes, _) in enumerate(tables):
        inputs = batch + "".join(letters[a] for a in axes)
        for v in axes:
            others = [u for u in axes if u != v]
            eq = ",".join([inputs] + [batch + letters[u] for u in others]) + "->" + batch + \
                letters[v]
            specs[i, v] = (eq, others)
    residual, done = np.inf, 0
    while done < iterations:
        done += 1
        new_to_var = {}
        for i, (axes, table) in enumerate(tables):
            for v in axes:
                eq, others = specs[i, v]
                new_to_var[i, v] = _normalised(contract(eq, table, *(to_factor[i, u]
                                                                     for u in others)))
        residual = max((float(np.max(np.abs(new_to_var[k] - to_var[k]))) for k in to_var),
                       default=0.0)
        to_var = new_to_var
        for v in variables:
            for i in neighbours[v]:
                m = np.ones((rows, card[v]))
                for j in neighbours[v]:
                    if j != i:
                        m = m * to_var[j, v]
                to_factor[i, v] = _normalised(m)
        if residual < tolerance:
            break

    def var_belief(v: str) -> np.ndarray:
        m = np.ones((rows, card[v]))
        for i in neighbours[v]:
            m = m * to_var[i, v]
        return m

    def factor_belief(i: int, keep: tuple[str, ...]) -> np.ndarray:
        axes, table = tables[i]
        eq = ",".join([batch + "".join(letters[a] for a in axes)]
                      + [batch + letters[a] for a in axes]) + "->" + batch + \
            "".join(letters[a] for a in keep)
        return contract(eq, table, *(to_factor[i, a] for a in axes))

    return ({"var": {v: var_belief(v) for v in variables}, "factor": factor_belief},
            residual, done)
