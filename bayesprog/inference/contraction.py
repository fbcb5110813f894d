"""Contraction, in one place: the question's factors, each rescaled in log space, contracted
by a cached opt_einsum expression with a batch axis (:func:`contract_question`); rows that
underflow redone exactly in log space (:func:`log_contract`); a layout's first question
answered by eliminating variables one at a time (:func:`first_question`, :func:`eliminate`);
and the evidence-free tables a layout slices by indexing (:class:`Sliceable`).

The contraction method (:mod:`bayesprog.inference.methods.contraction`) answers questions with
it; the table, Gaussian and grid methods use its pieces.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from bayesprog.inference.answers import Posterior
from bayesprog.inference.binding import Bound
from bayesprog.inference.core import ONE_STEP, Factor, equation
from bayesprog.inference.factors import (
    is_static,
    plain_table,
    question_factors,
    rescaled,
    static_table,
)
from bayesprog.inference.methods.base import answer
from bayesprog.inference.plan import QuestionPlan
from bayesprog.inference.protocol import ProgramLike
from bayesprog.limits import limit
from bayesprog.support.extras import LazyModule
from bayesprog.vocabulary.variables import discrete

if TYPE_CHECKING:
    from bayesprog.inference.recurring import _Last

#: scipy.special, imported by the first computation that reads it
special = LazyModule("scipy.special")

#: Below this, a row's normaliser is recomputed in log space (underflow, or subnormal precision).
TINY = 1e-280
#: numpy's einsum names axes by letters: a step of :func:`eliminate` joins at most this many.
LETTERS = "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ"
#: numpy's einsum takes at most 32 operands in one call before numpy 2 (64 from it): a step of
#: :func:`eliminate` takes at most this many, whichever numpy is installed.
MAX_OPERANDS = 32


def contract(program: ProgramLike, operands: list[Factor], searched: tuple[str, ...],
             batched_out: bool, size: int) -> np.ndarray:
    """Contract the (rescaled) ``operands`` down to ``searched``, with a batch axis of ``size``
    rows when ``batched_out``; searched variables without a factor are uniform."""
    if not operands:
        cards = tuple(discrete(program.variables[v]).card for v in searched)
        return np.ones(((size,) if batched_out else ()) + cards)
    present = {a for f in operands for a in f.axes}
    missing = [v for v in searched if v not in present]
    if missing:  # a searched variable with no factor left: uniform over its states
        for v in missing:
            operands.append(Factor((v,), np.ones(discrete(program.variables[v]).card), False))
    if batched_out and not any(f.batched for f in operands):
        operands.append(Factor((), np.ones(size), True))
    expr = program.inference_cache.plans.get(operands, searched, batched_out)
    return expr(*(f.log for f in operands))


def eliminate(factors: list[tuple[tuple[str, ...], np.ndarray]], output: tuple[str, ...],
              cards: dict[str, int], limit: float) -> tuple[np.ndarray, int] | None:
    """The product of ``factors`` (probability tables over their axes) summed down to
    ``output`` (in its order), a new array, and the entries its steps joined (its operations),
    by variable elimination: each step sums out the variable whose factors join into the
    smallest table (of equal ones, the first to appear in the factors, so the same factors give
    the same arithmetic), in one einsum over those factors. The sizes wait in a heap, and a
    step recomputes only those of the variables it joined: choosing costs a logarithm per
    change, not a scan of every variable. None, before the step that would bring the entries
    its steps join past ``limit`` (their work, which bounds what they allocate), or that joins
    more axes or operands than one einsum takes. An output variable in no factor is uniform
    (ones)."""
    pool: dict[int, tuple[tuple[str, ...], np.ndarray]] = dict(enumerate(factors))
    holders: dict[str, dict[int, None]] = {}
    for i, (axes, _) in pool.items():
        for a in axes:
            holders.setdefault(a, {})[i] = None
    rank = {a: r for r, a in enumerate(a for a in holders if a not in output)}

    def joined_by(name: str) -> dict[str, None]:
        return {a: None for i in holders[name] for a in pool[i][0]}

    size_of = {a: math.prod(cards[b] for b in joined_by(a)) for a in rank}
    heap = [(size, rank[a], a) for a, size in size_of.items()]
    heapq.heapify(heap)
    made, work = len(pool), 0
    while heap:
        size, _, name = heapq.heappop(heap)
        if size_of.get(name) != size:
            continue  # eliminated, or its size changed since
        del size_of[name]
        joined = joined_by(name)
        taken = holders.pop(name)
        work += size
        if work > limit or len(joined) > len(LETTERS) or len(taken) > MAX_OPERANDS:
            return None
        letter = dict(zip(joined, LETTERS, strict=False))
        kept = tuple(a for a in joined if a != name)
        operands = [pool.pop(i) for i in taken]
        text = ",".join("".join(letter[a] for a in axes) for axes, _ in operands)
        result = np.einsum(text + "->" + "".join(letter[a] for a in kept),
                           *(table for _, table in operands))
        for a in kept:
            for i in taken:
                holders[a].pop(i, None)
            holders[a][made] = None
        pool[made] = (kept, result)
        made += 1
        for a in kept:
            if a in size_of:
                size_of[a] = math.prod(cards[b] for b in joined_by(a))
                heapq.heappush(heap, (size_of[a], rank[a], a))
    cards_out = [cards[a] for a in output]
    work += math.prod(cards_out)
    if work > limit:
        return None
    operands = list(pool.values())
    operands += [((a,), np.ones(card)) for a, card in zip(output, cards_out, strict=True)
                 if a not in holders]
    if not operands:
        return np.ones(cards_out), work
    if all(axes == output for axes, _ in operands):  # a product, entry by entry
        product = operands[0][1].copy()
        for _, table in operands[1:]:
            product *= table
        return product, work
    if len(operands) > MAX_OPERANDS:
        return None
    letter = dict(zip(output, LETTERS, strict=False))
    text = ",".join("".join(letter[a] for a in axes) for axes, _ in operands)
    found = np.einsum(text + "->" + "".join(letter[a] for a in output),
                      *(table for _, table in operands))
    return (found if found.flags.owndata else found.copy()), work  # never a program's table


def log_contract(factors: list[tuple[tuple[str, ...], np.ndarray]],
                 output: tuple[str, ...]) -> np.ndarray:
    """Exact log-space variable elimination, for rows whose scaled contraction underflowed."""
    pool = [(tuple(a), np.asarray(v, dtype=float)) for a, v in factors]
    names = {a for axes, _ in pool for a in axes} - set(output)
    while names:
        var = min(names, key=lambda n: len({a for axes, _ in pool if n in axes for a in axes}))
        names.discard(var)
        take = [f for f in pool if var in f[0]]
        pool = [f for f in pool if var not in f[0]]
        axes, arr = _log_product(take)
        pool.append((tuple(a for a in axes if a != var), special.logsumexp(arr, axis=axes.index(var))))
    axes, arr = _log_product(pool, output)
    return arr


def _log_product(factors: list[tuple[tuple[str, ...], np.ndarray]],
                 order: Sequence[str] | None = None) -> tuple[tuple[str, ...], np.ndarray]:
    axes = list(order) if order is not None else []
    for f_axes, _ in factors:
        axes += [a for a in f_axes if a not in axes]
    total: Any = 0.0
    for f_axes, arr in factors:
        perm = [f_axes.index(a) for a in axes if a in f_axes]
        shape = [arr.shape[f_axes.index(a)] if a in f_axes else 1 for a in axes]
        total = total + arr.transpose(perm).reshape(shape)
    total = np.asarray(total, dtype=float)
    if total.ndim < len(axes):
        total = total.reshape((1,) * len(axes))
    return tuple(axes), total


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
    operands, offset, kept = prepared.operands(plan)
    found = _normalised(plan, operands, offset, plan.searched,
                        lambda: question_factors(plan.program, plan.terms, plan.bound))
    if kept is not None:  # contracted: the state they are arrays of serves the next question
        prepared.recurring.leave(kept)
    return answer(plan, *found)


#: The entries the steps of a layout's first question may join in all (about 10 ms of
#: einsum over several operands, which runs at about 10 ns an entry): beyond, the question is
#: planned (a path search that finds pairwise steps, checked against the memory limit) as
#: every later question of its layout is. munin1's benchmark question joins 0.4 M; a 12 x 12
#: grid's 7 M, which a planned contraction answers five times faster.
FIRST_WORK = 1 << 20
#: A group of evidence-free tables is folded into one (:meth:`Sliceable._fold`) when that
#: table holds at most this many times the entries of the group's tables.
FOLD_GROWTH = 4


def _one_row(bound: Bound) -> dict[str, int]:
    """The observed discrete values of a one-row ``bound`` (a batch of one row, or none)."""
    if not bound.batch_shape:  # nothing batched: numbers
        return bound.discrete  # type: ignore[return-value]
    return {k: int(np.ravel(v)[0]) for k, v in bound.discrete.items()}


def first_question(plan: QuestionPlan) -> tuple[np.ndarray, np.ndarray, int] | None:
    """The answer to the first question of a layout, when it has one row of evidence on
    discrete variables and every requisite term is a table: the tables sliced by the evidence
    and the unobserved variables eliminated one at a time (:func:`eliminate`), with nothing
    planned nor compiled. The normalised table
    ``[1] + cards`` and the log normaliser ``[1]``, as :meth:`Sliceable.one_row` gives them,
    and the operations it took; None when the question needs the planned path (other
    evidence, steps above ``FIRST_WORK`` entries in all, or probabilities below what the
    tables' arithmetic resolves).

    Planning a question (its path searched, its tables made ready to slice, its runner built)
    costs several times what answering it this way does, and pays off only over the questions
    of a layout asked again: the cost model plans a layout at its second question."""
    bound, program = plan.bound, plan.program
    if bound.size != 1 or bound.continuous or bound.inputs or bound.soft or bound.ablated \
            or not plan.searched or plan.latent:
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
        ablated = set(plan.layout.key[5])  # (terms uniform on some rows: they vary by row)
        self.tables: list[tuple[tuple[str, ...], tuple[str, ...], np.ndarray]] = []
        self.others = []
        self.log_scale = 0.0
        for term in plan.terms:
            if not is_static(term) or str(term.expression) in ablated:
                self.others.append(term)
                continue
            table, top = static_table(program, term)
            fixed = tuple(a for a in term.axes if a in observed)
            rest = tuple(a for a in term.axes if a not in observed)
            order = [term.axes.index(a) for a in fixed + rest]
            self.tables.append((fixed, rest, np.ascontiguousarray(table.transpose(order))))
            self.log_scale += top
        self._fold(plan)
        self.single: Any = None  # the contraction of one row of evidence, once made
        # (a layout's first question is answered without it: imported at its second)
        from bayesprog.inference.recurring import Recurring

        self.recurring = Recurring()

    def _fold(self, plan: QuestionPlan) -> None:
        """Sum out, once, the variables that only evidence-free tables hold: such tables
        are joined by those variables into groups, and each group is contracted to one table
        over the variables it shares with the rest of the question (opt_einsum's constant
        subexpressions, chosen by variable). A call then contracts the tables the evidence
        slices with a few folded ones (a question about a variable far from its evidence:
        one step where it took one per term). A group is left as it is when its folded table
        would hold more than ``FOLD_GROWTH`` times its tables' entries (and more than
        ``ONE_STEP``), or more than the memory limit allows."""
        shared = set(plan.searched) | set(plan.layout.key[4])
        shared.update(a for fixed, rest, _ in self.tables if fixed for a in rest)
        shared.update(a for term in self.others for a in term.axes)
        free = [i for i, (fixed, _, _) in enumerate(self.tables) if not fixed]
        # groups of evidence-free tables joined by the variables no other table holds
        group = {i: i for i in free}

        def root(i: int) -> int:
            while group[i] != i:
                group[i] = group[group[i]]
                i = group[i]
            return i

        holder: dict[str, int] = {}
        for i in free:
            for a in self.tables[i][1]:
                if a in shared:
                    continue
                if a in holder:
                    group[root(i)] = root(holder[a])
                else:
                    holder[a] = i
        members: dict[int, list[int]] = {}
        for i in free:
            members.setdefault(root(i), []).append(i)
        folded: dict[int, tuple[tuple[str, ...], np.ndarray, float]] = {}
        cap = limit("entries")
        for first, each in members.items():
            axes = [a for i in each for a in self.tables[i][1]]
            if all(a in shared for a in axes):
                continue  # nothing to sum out
            kept = tuple(dict.fromkeys(a for a in axes if a in shared))
            cards = dict(zip(axes, (n for i in each for n in self.tables[i][2].shape),
                             strict=True))
            size = math.prod(cards[a] for a in kept)
            entries = sum(self.tables[i][2].size for i in each)
            if size > max(FOLD_GROWTH * entries, ONE_STEP) or size > cap:
                continue
            operands = [Factor(self.tables[i][1], self.tables[i][2], False) for i in each]
            eq = equation([f.axes for f in operands], kept)
            _, info, _ = plan.program.inference_cache.plans.path(
                eq, [f.log.shape for f in operands])
            if info.largest_intermediate > cap:
                continue
            table = contract(plan.program, operands, kept, False, 1)
            top = float(table.max()) if table.size else 0.0
            if not top > 0 or not math.isfinite(top):
                continue  # (zero everywhere: left to the general path's checks)
            folded[first] = (kept, np.ascontiguousarray(table / top), math.log(top))
        if not folded:
            return
        dropped = {i for first in folded for i in members[first]}
        tables = [t for i, t in enumerate(self.tables) if i not in dropped]
        for kept, table, top in folded.values():
            tables.append(((), kept, table))
            self.log_scale += top
        self.tables = tables

    def one_row(self, plan: QuestionPlan) -> tuple[np.ndarray, np.ndarray] | None:
        """The answer to one row of evidence when every term is prepared, in scalars: the
        normalised table ``[1] + cards`` and the log normaliser ``[1]``; None when it needs
        the general path (a probability below what scaled arithmetic resolves)."""
        if self.single is None:
            self._plan_single(plan)
        found = self.row(_one_row(plan.bound))
        if found is None:
            return None
        return found[0][np.newaxis], np.array([found[1]])

    def _plan_single(self, plan: QuestionPlan) -> None:
        """The contraction of one row of evidence: its runner, and the uniform factors of the
        searched variables that no table holds."""
        # a table sliced by one row keeps the axes after its observed ones
        shapes = [(rest, table.shape[len(fixed):]) for fixed, rest, table in self.tables if rest]
        present = {a for rest, _ in shapes for a in rest}
        missing = [v for v in plan.searched if v not in present]
        self.ones = [np.ones(plan.card(v)) for v in missing]
        if not shapes and not missing:
            self.single = lambda: np.ones(())  # nothing left to contract
            return
        operands = [Factor(rest, np.empty(shape), False) for rest, shape in shapes]
        operands += [Factor((v,), ones, False) for v, ones in zip(missing, self.ones,
                                                                   strict=True)]
        self.single = plan.program.inference_cache.plans.get(operands, plan.searched, False)

    def row(self, values: dict[str, Any]) -> tuple[np.ndarray, float] | None:
        """One row of evidence (a state index per observed variable) once its contraction is
        planned: the normalised table over the searched variables (a new array) and the log
        normaliser; None when it needs the general path (a probability below what scaled
        arithmetic resolves)."""
        arrays: list[np.ndarray] = []
        scale = 1.0
        for fixed, rest, table in self.tables:
            sliced = table[tuple(values[a] for a in fixed)] if fixed else table
            if rest:
                arrays.append(sliced)
            else:
                scale *= float(sliced)
        table = self.single(*arrays, *self.ones)
        total = float(table.sum())
        if not (TINY < total < math.inf and scale > 0):
            return None
        return table / total, math.log(total) + math.log(scale) + self.log_scale

    def operands(self, plan: QuestionPlan
                 ) -> tuple[list[Factor], np.ndarray | float, _Last | None]:
        """The rescaled operands for ``plan``'s evidence, the log of what they were divided by
        (per row when it varies), and what the layout keeps of them for its next question
        (None: nothing), to give to ``self.recurring.leave`` once the operands are used
        (:class:`~bayesprog.inference.recurring.Recurring`)."""
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
        kept: _Last | None = None
        if self.others or bound.soft:
            # the factors that read the evidence: computed again where it changed since the
            # layout's last question
            more, more_offset, kept = self.recurring.operands(plan.program, self.others, bound)
            operands += more
            offset = offset + more_offset
        return operands, offset, kept


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
        total = special.logsumexp(lt) if np.isfinite(lt).any() else -np.inf
        log_z[row] = total
        probs[row] = np.exp(lt - total) if np.isfinite(total) else 0.0
    return probs, log_z
