"""Approximate, by loopy belief propagation: sum-product messages between the question's
factors (sliced by the evidence) and its unobserved discrete variables, every evidence row at
once, until the largest change of a message falls under a tolerance. Exact on programs whose
factor graph is a tree; on loopy ones a fixed point of the Bethe approximation, with no bound on
its error. Answers the marginal of one searched variable, or of searched variables that share a
factor; reports its iterations and last change (``residual``), and the evidence's probability
by the Bethe approximation of ``log Z`` (exact on a tree; ``evidence`` says so)."""

from __future__ import annotations

from typing import Any

import numpy as np

from bayesprog.errors import QuestionError
from bayesprog.inference.answers import Posterior
from bayesprog.inference.core import symbol
from bayesprog.inference.factors import question_factors, rescaled
from bayesprog.inference.methods.base import PER_FACTOR, Cost, Method, answer, register_method
from bayesprog.inference.plan import QuestionPlan
from bayesprog.support.extras import LazyModule

#: scipy.special, imported by the first computation that reads it
special = LazyModule("scipy.special")
opt_einsum = LazyModule("opt_einsum")

#: Sweeps over all messages at most, and the change of a message that counts as converged.
MAX_ITERATIONS, TOLERANCE = 200, 1e-10
#: Sweeps the cost model counts on (grids of binary variables converge in 20 to 25)
EXPECTED_ITERATIONS = 25


@register_method
class LoopyBeliefPropagation(Method):
    name = "lbp"
    title = "loopy belief propagation"
    exact = False

    def describe(self, answer: Any) -> str:
        return (f"{self.title}: {answer.iterations} sweeps, last change "
                f"{answer.residual:.2g}; no error estimate")
    ablates_rows = True

    def estimate(self, plan: QuestionPlan) -> Cost | None:
        sizes = [plan.free_size(t.axes) for t in plan.terms] or [1]
        iterations = min(plan.options.get("max_iterations", MAX_ITERATIONS), EXPECTED_ITERATIONS)
        size = float(plan.bound.size)
        # a sweep handles each group of factors of one shape in a few array operations: about
        # 24 x PER_FACTOR per group and sweep (measured on grids, benchmarks/engine.py)
        groups = len({tuple(plan.card(a) for a in t.axes if a not in plan.bound.discrete)
                      for t in plan.terms})
        return Cost(operations=size * iterations * sum(sizes) * 4,
                    memory=size * max(sizes), fixed=iterations * 24 * PER_FACTOR * groups)

    def posterior(self, plan: QuestionPlan) -> Posterior:
        program, bound, searched = plan.program, plan.bound, plan.searched
        rows = bound.size
        operands, offset = rescaled(question_factors(program, plan.terms, bound), rows,
                                    merge=False)
        # every table with the batch axis of rows, in the probability domain, largest value 1
        tables = [(f.axes, np.broadcast_to(f.log if f.batched else f.log[np.newaxis],
                                           (rows,) + f.log.shape[f.batched:]))
                  for f in operands]
        variables = sorted({a for axes, _ in tables for a in axes} | set(searched))
        card = {v: plan.card(v) for v in variables}
        iterations = plan.options.get("max_iterations", MAX_ITERATIONS)
        tolerance = plan.options.get("tolerance", TOLERANCE)
        beliefs, residual, done = _propagate(tables, variables, card, rows, iterations, tolerance)
        home = next((i for i, (axes, _) in enumerate(tables) if set(searched) <= set(axes)), None)
        if not searched:  # the evidence's probability alone (every variable known or summed)
            probs = np.ones(rows)
        elif len(searched) == 1:
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
        log_z = np.where(zero, -np.inf, offset + _bethe(tables, variables, beliefs, rows))
        return answer(plan, np.where(zero.reshape((-1,) + (1,) * len(cards)), 0.0, probs), log_z,
                      method=self.name, iterations=done, residual=residual,
                      evidence="Bethe approximation")


def _bethe(tables: list[tuple[tuple[str, ...], np.ndarray]], variables: list[str],
           beliefs: dict[str, Any], rows: int) -> np.ndarray:
    """The Bethe approximation of ``log Z`` (the evidence's log-probability, less the tables'
    rescaling) at the fixed point: the factors' average energies and entropies, less the
    variables' entropies counted once per factor beyond the first. Exact on a tree."""
    total = np.zeros(rows)
    degree = dict.fromkeys(variables, 0)
    for i, (axes, table) in enumerate(tables):
        for a in axes:
            degree[a] += 1
        if not axes:
            continue
        b = beliefs["factor"](i, axes).reshape(rows, -1)
        b = b / b.sum(axis=1, keepdims=True)
        f = np.broadcast_to(table, (rows,) + table.shape[1:]).reshape(rows, -1)
        with np.errstate(divide="ignore", invalid="ignore"):
            terms = np.where(b > 0, b * (np.log(f) - np.log(b)), 0.0)
        total += terms.sum(axis=1)
    for v in variables:
        b = beliefs["var"][v].reshape(rows, -1)
        with np.errstate(divide="ignore", invalid="ignore"):
            entropy = -np.where(b > 0, b * np.log(b), 0.0).sum(axis=1)
        total -= (degree[v] - 1) * entropy
    return total


#: Messages are kept above this, so that a variable's message to a factor (the product of its
#: other messages) is the product of all divided by the factor's own.
FLOOR = 1e-300


def _propagate(tables: list[tuple[tuple[str, ...], np.ndarray]], variables: list[str],
               card: dict[str, int], rows: int, iterations: int,
               tolerance: float) -> tuple[dict[str, Any], float, int]:
    """Flooding schedule, vectorised: the factors are grouped by the cards of their axes, and
    each group's messages to the variables of one position are one einsum over the group.
    A variable's messages to its factors are, in log space, the sum of all it receives minus
    the factor's own. Returns beliefs, the last residual (largest change of a factor-to-
    variable message) and the sweeps made."""
    index = {v: i for i, v in enumerate(variables)}
    width = max([card[v] for v in variables] or [1])
    groups: dict[tuple[int, ...], list[int]] = {}
    for i, (axes, _) in enumerate(tables):
        groups.setdefault(tuple(card[a] for a in axes), []).append(i)
    plans = []
    for cards, members in groups.items():
        arity = len(cards)
        stacked = np.stack([tables[i][1] for i in members])  # [F, rows, c1..ca]
        where = np.array([[index[a] for a in tables[i][0]] for i in members])  # [F, a]
        letters = [symbol(2 + k) for k in range(arity)]
        head = "fr" + "".join(letters)
        equations = [",".join([head] + ["fr" + letters[q] for q in range(arity) if q != p])
                     + "->fr" + letters[p] for p in range(arity)]
        plans.append((members, cards, stacked, where, equations))
    # messages factor -> variable (probabilities) and variable -> factor (logs), by group and
    # position: [F, rows, card]
    to_var = [[np.full((len(m), rows, c), 1.0 / c) for c in cards]
              for m, cards, *_ in plans]
    to_factor = [[np.full((len(m), rows, c), -np.log(c)) for c in cards]
                 for m, cards, *_ in plans]
    received = np.zeros((len(variables), rows, width))
    residual, done = np.inf, 0
    while done < iterations:
        done += 1
        residual = 0.0
        received[...] = 0.0
        for g, (_, cards, stacked, where, equations) in enumerate(plans):
            incoming = [np.exp(m) for m in to_factor[g]]
            for p, c in enumerate(cards):
                others = [incoming[q] for q in range(len(cards)) if q != p]
                m = opt_einsum.contract(equations[p], stacked, *others) if others else stacked
                total = m.sum(axis=-1, keepdims=True)
                with np.errstate(invalid="ignore", divide="ignore"):
                    m = np.where(total > 0, m / total, 1.0 / c)
                m = np.maximum(m, FLOOR)
                residual = max(residual, float(np.max(np.abs(m - to_var[g][p]))))
                to_var[g][p] = m
                np.add.at(received[:, :, :c], where[:, p], np.log(m))  # a view: in place
        for g, (_, cards, _, where, _) in enumerate(plans):
            for p, c in enumerate(cards):
                log = received[where[:, p], :, :c] - np.log(to_var[g][p])
                to_factor[g][p] = log - special.logsumexp(log, axis=-1, keepdims=True)
        if residual < tolerance:
            break

    def var_belief(v: str) -> np.ndarray:
        log = received[index[v], :, : card[v]]
        return np.exp(log - special.logsumexp(log, axis=-1, keepdims=True))

    position = {i: (g, k) for g, (members, *_) in enumerate(plans)
                for k, i in enumerate(members)}

    def factor_belief(i: int, keep: tuple[str, ...]) -> np.ndarray:
        axes, table = tables[i]
        g, k = position[i]
        letters = [symbol(2 + q) for q in range(len(axes))]
        eq = ",".join(["r" + "".join(letters)] + ["r" + letter for letter in letters]) + \
            "->r" + "".join(letters[axes.index(a)] for a in keep)
        return opt_einsum.contract(eq, table, *(np.exp(to_factor[g][p][k]) for p in range(len(axes))))

    return ({"var": {v: var_belief(v) for v in variables}, "factor": factor_belief},
            residual, done)
