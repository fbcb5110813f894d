"""Exact, by a compiled table: a discrete question over fixed tables is turned, at its first
call, into the table ``P(observed, searched)`` (by the same scaled contraction as the
contraction method); every later evidence set is a lookup in it."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bayesprog.inference.answers import Posterior
from bayesprog.inference.contraction import TINY, contract
from bayesprog.inference.core import Factor
from bayesprog.inference.factors import is_static, static_table
from bayesprog.inference.methods.base import (
    PER_CALL,
    PER_FACTOR,
    Cost,
    Method,
    answer,
    register_method,
)
from bayesprog.inference.plan import Layout, QuestionPlan

#: Largest joint table (entries) that a compiled discrete question keeps.
TABLE_LIMIT = 1 << 20


@dataclass
class CompiledTable:
    """A compiled discrete question: the joint table over observed + searched variables,
    kept as each configuration of the observed variables' row of ``P(searched | observed)``
    (``normalised``) and the log of its normaliser (``log_z``, the log offset included), the
    rows whose normaliser the scaled arithmetic does not resolve marked (``bad``)."""

    observed: tuple[str, ...]
    normalised: np.ndarray
    log_z: np.ndarray
    bad: np.ndarray

    @classmethod
    def of(cls, observed: tuple[str, ...], table: np.ndarray, log_offset: float,
           searched: int) -> CompiledTable:
        """From the joint ``table`` (observed axes first, then ``searched`` axes)."""
        rows = table.reshape(table.shape[: table.ndim - searched] + (-1,))
        z = rows.sum(axis=-1)
        bad = ~(z > TINY)
        with np.errstate(divide="ignore", invalid="ignore"):
            normalised = table / z.reshape(z.shape + (1,) * searched)
            log_z = np.log(z) + log_offset
        return cls(observed, np.ascontiguousarray(normalised), log_z, bad)


def _observed_and_searched(plan: QuestionPlan) -> tuple[tuple[str, ...], tuple[str, ...]]:
    return tuple(sorted(plan.bound.discrete)), plan.searched


def _compile(plan: QuestionPlan) -> CompiledTable:
    program = plan.program
    observed, searched = _observed_and_searched(plan)
    key = (searched, observed)
    cached = program.inference_cache.tables.get(key)
    if cached is None:
        offset = 0.0
        operands = []
        for t in plan.terms:
            probabilities, top = static_table(program, t)
            offset += top
            operands.append(Factor(t.axes, probabilities, False))
        table = contract(program, operands, observed + searched, False, 1)
        cached = CompiledTable.of(observed, table, offset, len(searched))
        program.inference_cache.tables[key] = cached
    return cached


@register_method
class TableMethod(Method):
    """Applies to a question over fixed tables (no continuous evidence, inputs or soft
    evidence) whose observed and searched variables span at most ``TABLE_LIMIT`` states."""

    name = "table"

    def estimate(self, plan: QuestionPlan) -> Cost | None:
        return self._estimate(plan, full=True)

    def quick_estimate(self, plan: QuestionPlan) -> Cost | None:
        return self._estimate(plan, full=False)

    def _estimate(self, plan: QuestionPlan, full: bool) -> Cost | None:
        bound = plan.bound
        if bound.continuous or bound.inputs or bound.soft:
            return None
        observed, searched = _observed_and_searched(plan)
        joint = int(np.prod([plan.card(v) for v in observed + searched]))
        if joint > TABLE_LIMIT or not all(is_static(t) for t in plan.terms):
            return None
        lookup = int(np.prod([plan.card(v) for v in searched]))
        if (searched, observed) in plan.program.inference_cache.tables:
            return Cost(operations=float(bound.size * lookup), memory=float(joint),
                        fixed=PER_CALL)
        # compiling builds every factor whole and contracts them with the observed variables
        # left open, on the path the full estimate has just found: fitted (benchmarks/engine.py,
        # the bnlearn networks and grids of 6 x 6 to 16 x 16) at the contraction's time per
        # operation, 1.2 times its time per factor and five and a half factors' worth of fixed
        # work (finding the terms, storing the table); its operations are at least one per
        # entry of the table (the bound of a quick estimate, which spares the path search)
        compile_ops, compile_memory = (plan.contraction_cost(observed + searched, sliced=False)
                                       if full else (float(joint), float(joint)))
        setup = compile_ops + PER_FACTOR * (5.5 + 1.2 * len(plan.terms))
        return Cost(operations=float(bound.size * lookup), memory=max(float(joint), compile_memory),
                    fixed=PER_CALL, setup=setup, floor=not full)

    def prepared_row(self, layout: Layout, values: dict[str, int]
                     ) -> tuple[np.ndarray, float] | None:
        compiled = layout.prepared.get("table")
        if compiled is None:
            return None
        index = tuple(values[v] for v in compiled.observed)
        if compiled.bad[index]:
            return None
        return compiled.normalised[index].copy(), float(compiled.log_z[index])

    def posterior(self, plan: QuestionPlan) -> Posterior | None:
        compiled = plan.layout.prepared.get("table")
        if compiled is None:
            compiled = plan.layout.prepared["table"] = _compile(plan)
        bound, size = plan.bound, plan.bound.size
        index = tuple(bound.discrete[v] for v in compiled.observed)
        if compiled.bad[index].any():
            return None  # some row needs the exact log-space path
        cards = plan.layout.cards
        probs = compiled.normalised[index].reshape((-1,) + cards)
        logs = compiled.log_z[index].reshape(-1)
        if probs.shape[0] != size:  # evidence broadcast over the batch
            probs, logs = np.broadcast_to(probs, (size,) + cards), np.broadcast_to(logs, (size,))
        return answer(plan, probs.copy(), logs.copy())
