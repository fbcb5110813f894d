"""Exact, by contraction: the question's factors, each rescaled in log space, contracted by a
cached opt_einsum expression with a batch axis; rows that underflow are redone exactly in log
space. Answers every discrete question, with any evidence, inputs and soft evidence."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
from scipy.special import logsumexp

from bayesprog.inference.answers import Posterior
from bayesprog.inference.binding import Bound
from bayesprog.inference.contract import TINY, contract, eliminate, log_contract
from bayesprog.inference.core import Factor
from bayesprog.inference.factors import (
    is_static,
    plain_table,
    question_factors,
    rescaled,
    static_table,
)
from bayesprog.inference.methods.base import (
    PER_CALL,
    PER_FACTOR,
    PER_PREPARED,
    Cost,
    Method,
    answer,
    register_method,
)
from bayesprog.inference.plan import QuestionPlan
from bayesprog.limits import limit


@register_method
class ContractionMethod(Method):
    """Applies to every question of a program whose unobserved variables are discrete."""

    name = "contraction"

    def estimate(self, plan: QuestionPlan) -> Cost | None:
        operations, largest = plan.contraction_cost(plan.searched)
        prepared = sum(1 for t in plan.terms if is_static(t))
        computed = len(plan.terms) - prepared + len(plan.bound.soft)
        return Cost(operations=plan.bound.size * operations, memory=plan.bound.size * largest,
                    fixed=PER_CALL + PER_PREPARED * prepared + PER_FACTOR * computed)

    def posterior(self, plan: QuestionPlan) -> Posterior:
        return contract_question(plan)


def contract_question(plan: QuestionPlan) -> Posterior:
    """The posterior by scaled contraction, with exact log-space rows where it underflows."""
    prepared = plan.layout.prepared.get("contraction")
    if prepared is None:
        prepared = plan.layout.prepared["contraction"] = Sliceable(plan)
    bound = plan.bound
    if bound.size == 1 and not (prepared.others or bound.soft):
        one = prepared.one_row(plan)
        if one is not None:
            return answer(plan, *one)
    operands, offset = prepared.operands(plan)
    return answer(plan, *_normalised(plan, operands, offset, plan.searched,
                                     lambda: question_factors(plan.program, plan.terms,
                                                              plan.bound)))


#: The entries the steps of a layout's first question may join in all (about 10 ms of
#: einsum over several operands, which runs at about 10 ns an entry): beyond, the question is
#: planned (a path search that finds pairwise steps, checked against the memory limit) as
#: every later question of its layout is. munin1's benchmark question joins 0.4 M; a 12 x 12
#: grid's 7 M, which a planned contraction answers five times faster.
FIRST_WORK = 1 << 20


def _one_row(bound: Bound) -> dict[str, int]:
    """The observed discrete values of a one-row ``bound`` (a batch of one row, or none)."""
    if not bound.batch_shape:  # nothing batched: numbers
        return bound.discrete  # type: ignore[return-value]
    return {k: int(np.ravel(v)[0]) for k, v in bound.discrete.items()}


def first_question(plan: QuestionPlan) -> tuple[np.ndarray, np.ndarray, int] | None:
    """The answer to the first question of a layout, when it has one row of evidence on
    discrete variables and every requisite term is a table: the tables sliced by the evidence
    and the unobserved variables eliminated one at a time (:func:`~bayesprog.inference.
    contract.eliminate`), with nothing planned nor compiled. The normalised table
    ``[1] + cards`` and the log normaliser ``[1]``, as :meth:`Sliceable.one_row` gives them,
    and the operations it took; None when the question needs the planned path (other
    evidence, steps above ``FIRST_WORK`` entries in all, or probabilities below what the
    tables' arithmetic resolves).

    Planning a question (its path searched, its tables made ready to slice, its runner built)
    costs several times what answering it this way does, and pays off only over the questions
    of a layout asked again: the cost model plans a layout at its second question."""
    bound, program = plan.bound, plan.program
    if bound.size != 1 or bound.continuous or bound.inputs or bound.soft or not plan.searched \
            or plan.latent:
        return None
    values = _one_row(bound)
    factors: list[tuple[tuple[str, ...], np.ndarray]] = []
    cards: dict[str, int] = {}
    scale, log_scale = 1.0, 0.0
    for term in plan.terms:
        found = plain_table(program, term)
        if found is None:
            return None
        axes, table, top = found
        log_scale += top
        if any(a in values for a in axes):
            table = table[tuple(values[a] if a in values else slice(None) for a in axes)]
            axes = tuple(a for a in axes if a not in values)
            if not axes:
                scale *= float(table)
                continue
        factors.append((axes, table))
        cards.update(zip(axes, table.shape, strict=True))
    for name in plan.searched:
        cards.setdefault(name, plan.card(name))
    eliminated = eliminate(factors, plan.searched, cards, min(FIRST_WORK, limit("entries")))
    if eliminated is None:
        return None
    table, work = eliminated  # a new array
    total = float(table.sum())
    if not (TINY < total < math.inf and TINY < scale):
        return None
    table /= total
    return table[np.newaxis], np.array([math.log(total) + math.log(scale) + log_scale]), work


class Sliceable:
    """A layout's terms made ready for every call: each term that depends on no evidence
    value nor input, in the probability domain, divided by its largest entry, with the axes
    the evidence fixes first, so that a call slices it by indexing; the other terms are
    computed at each call."""

    def __init__(self, plan: QuestionPlan) -> None:
        program, observed = plan.program, set(plan.layout.key[1])
        self.tables: list[tuple[tuple[str, ...], tuple[str, ...], np.ndarray]] = []
        self.others = []
        self.log_scale = 0.0
        for term in plan.terms:
            if not is_static(term):
                self.others.append(term)
                continue
            table, top = static_table(program, term)
            fixed = tuple(a for a in term.axes if a in observed)
            rest = tuple(a for a in term.axes if a not in observed)
            order = [term.axes.index(a) for a in fixed + rest]
            self.tables.append((fixed, rest, np.ascontiguousarray(table.transpose(order))))
            self.log_scale += top
        self.single: Any = None  # the contraction of one row of evidence, once made

    def one_row(self, plan: QuestionPlan) -> tuple[np.ndarray, np.ndarray] | None:
        """The answer to one row of evidence when every term is prepared, in scalars: the
        normalised table ``[1] + cards`` and the log normaliser ``[1]``; None when it needs
        the general path (a probability below what scaled arithmetic resolves)."""
        values = _one_row(plan.bound)
        arrays: list[np.ndarray] = []
        scale = 1.0
        for fixed, rest, table in self.tables:
            sliced = table[tuple(values[a] for a in fixed)] if fixed else table
            if rest:
                arrays.append(sliced)
            else:
                scale *= float(sliced)
        if self.single is None:
            if not arrays and not any(v not in {a for t in self.tables for a in t[1]}
                                      for v in plan.searched):
                self.ones = []
                self.single = lambda: np.ones(())  # nothing left to contract
                return self.one_row(plan)
            operands = [Factor(rest, a, False) for (_, rest, _), a in zip(
                (t for t in self.tables if t[1]), arrays, strict=True)]
            present = {a for f in operands for a in f.axes}
            self.ones = [np.ones(plan.card(v)) for v in plan.searched if v not in present]
            operands += [Factor((v,), ones, False) for v, ones in zip(
                (v for v in plan.searched if v not in present), self.ones, strict=True)]
            self.single = plan.program.inference_cache.plans.get(operands, plan.searched,
                                                                 False)
        table = self.single(*arrays, *self.ones)
        total = float(table.sum())
        if not (TINY < total < math.inf and scale > 0):
            return None
        return (table / total)[np.newaxis], np.array(
            [math.log(total) + math.log(scale) + self.log_scale])

    def operands(self, plan: QuestionPlan) -> tuple[list[Factor], np.ndarray | float]:
        """The rescaled operands for ``plan``'s evidence, and the log of what they were
        divided by (per row when it varies)."""
        bound = plan.bound
        values = bound.discrete
        operands: list[Factor] = []
        scale: np.ndarray | float | None = None  # the product of the fully fixed tables
        for fixed, rest, table in self.tables:
            if not fixed:
                operands.append(Factor(rest, table, False))
                continue
            sliced = table[tuple(values[a] for a in fixed)]
            if rest:
                operands.append(Factor(rest, sliced, sliced.ndim > len(rest)))
            else:  # every axis fixed: a number per row
                scale = sliced if scale is None else scale * sliced
        if scale is None:
            offset: np.ndarray | float = self.log_scale
        else:
            with np.errstate(divide="ignore"):
                offset = self.log_scale + np.log(scale)
        if self.others or bound.soft:
            more, more_offset = rescaled(question_factors(plan.program, self.others, bound),
                                         bound.size)
            operands += more
            offset = offset + more_offset
        return operands, offset


def contract_factors(plan: QuestionPlan, factors: list[Factor], searched: tuple[str, ...]
                     ) -> tuple[np.ndarray, np.ndarray]:
    """``factors`` contracted to a normalised table over ``searched`` (``[rows] + cards``),
    and the log of the normaliser per row (``[rows]``)."""
    operands, offset = rescaled(factors, plan.bound.size)
    return _normalised(plan, operands, offset, searched, lambda: factors)


def _normalised(plan: QuestionPlan, operands: list[Factor], offset: np.ndarray | float,
                searched: tuple[str, ...], exact: Callable[[], list[Factor]]
                ) -> tuple[np.ndarray, np.ndarray]:
    """The rescaled ``operands`` contracted to a normalised table over ``searched``, and the
    log of the normaliser per row (``offset``: the log of what they were divided by); rows
    that underflow are redone in log space from the log-factors ``exact()`` gives."""
    program, bound = plan.program, plan.bound
    size = bound.size
    batched_out = any(f.batched for f in operands) or bool(bound.batch_shape)
    table = contract(program, operands, searched, batched_out, size)
    if not batched_out and np.ndim(offset) == 0:  # one row: in scalars
        total = float(table.sum())
        if TINY < total < math.inf and math.isfinite(offset):
            return (table / total)[np.newaxis], np.array([math.log(total) + offset])
    if not batched_out:
        table = table[np.newaxis]
    table = np.broadcast_to(table, (size,) + table.shape[1:])
    axes = tuple(range(1, table.ndim))
    z = table.sum(axis=axes)
    offset = np.broadcast_to(offset, (size,))
    with np.errstate(divide="ignore"):
        log_z = np.log(z) + offset
    # a row is bad when its scaled contraction underflowed, or an observed value's own
    # probability (folded into the offset) is zero: both are redone exactly in log space
    bad = ~(z > TINY) | ~np.isfinite(z) | ~np.isfinite(offset)
    if not bad.any():
        return table / z.reshape((-1,) + (1,) * len(axes)), log_z
    probs = np.empty_like(table)
    good = ~bad
    probs[good] = table[good] / z[good].reshape((-1,) + (1,) * len(axes))
    factors = exact()
    for row in np.flatnonzero(bad):
        logs = [(f.axes, f.log[row] if f.batched else f.log) for f in factors]
        lt = log_contract(logs, searched)
        total = logsumexp(lt) if np.isfinite(lt).any() else -np.inf
        log_z[row] = total
        probs[row] = np.exp(lt - total) if np.isfinite(total) else 0.0
    return probs, log_z
