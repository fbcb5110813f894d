"""A layout's question asked again: the factors of its last question kept, and computed again
only where the evidence or inputs they read changed.

A batch of runs that advance in lockstep asks the same question at every step, with evidence
of the same layout whose values change little from one step to the next: a field of cues of
which a cell or two per run changed, the inputs of some runs and not of the others. Each factor
of a question reads its values row by row: its entries on a row (one run) depend on that row's
evidence and inputs alone. A term whose form is ``pointwise`` over a field (a density of a real
variable indexed by a discrete one) reads even less: its log density at one cell depends on the
field's value at that cell alone, and a value met before has the log density it had then (kept
by value while the field's values repeat: :class:`~bayesprog.inference.memo.Memo`).

:class:`Recurring` keeps what the factors of a layout's last question read (copies) and made:
each term's factor, and each product of factors over the same variables in the probability
domain, as :func:`~bayesprog.inference.factors.rescaled` makes it (the log of its largest entry
per row taken out, then the exponential). A question with as many rows compares what its
factors read with what was kept, to the bit, and computes again the rows, or for a pointwise
field term the cells, whose values differ; the others are taken as they were. Each entry is
computed by the same operations on the same values as a question asked afresh computes it, so
the answer is the same to the last bit, as long as a term's arithmetic on a row does not depend
on the other rows of its batch (numpy's elementwise operations and reductions along a row, a
matrix product per row, as the forms compute; a sub-program is asked for the changed rows
alone, as for any batch of them).
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from bayesprog.forms import FormulaParam, InputRef, ParamValue
from bayesprog.inference.binding import Bound
from bayesprog.inference.core import Factor
from bayesprog.inference.factors import (
    _same_axes_summed,
    as_factor,
    log_values,
    observed_part,
    question_factors,
    rescale_one,
    rescaled,
    slice_factor,
    term_factor,
    term_log,
    term_params,
)
from bayesprog.inference.protocol import ProgramLike
from bayesprog.limits import limit
from bayesprog.model import Term
from bayesprog.vocabulary.variables import Continuous

if TYPE_CHECKING:
    from bayesprog.inference.memo import Memo

#: A factor is computed again whole, not row by row (cell by cell), once this share of its rows
#: (cells) changed: gathering them and scattering their values back costs more than it saves.
WHOLE = 0.5
#: What a layout keeps is at most this share of the memory limit (``BAYESPROG_MAX_ENTRIES``,
#: 5 million entries by default: 40 MB): a question larger than that is computed afresh each
#: time, keeping nothing.
KEPT_SHARE = 0.05
#: After this many questions in a row that found nothing to reuse (every row of every factor
#: changed: readings of a sensor), a layout keeps nothing for the next ``REST`` questions (the
#: copies and comparisons would be spent for nothing), then tries again.
IDLE, REST = 3, 32


def unequal(new: np.ndarray, old: np.ndarray) -> np.ndarray:
    """Where two arrays of one shape differ to the bit (NaN equals NaN, -0.0 differs from
    0.0): what makes an entry computed from them the same or not."""
    if new.dtype.kind == "f" and new.dtype == old.dtype:
        bits = np.dtype(f"u{new.dtype.itemsize}")
        return np.asarray(np.ascontiguousarray(new).view(bits)
                          != np.ascontiguousarray(old).view(bits))
    return np.asarray(new != old)


def _row_changes(new: np.ndarray, old: np.ndarray) -> np.ndarray:
    """The rows (first axis) where two batched arrays of one shape differ."""
    diff = unequal(new, old)
    return np.asarray(diff.reshape(len(diff), -1).any(axis=1)) if diff.ndim > 1 else diff


def _reads(program: ProgramLike, term: Term, bound: Bound) -> list[tuple[np.ndarray, bool]]:
    """The arrays of ``bound`` that the factor of ``term`` reads (``term_factor``), each with
    whether it has the rows' axis: its child's field or value, its inputs, the known values
    its formulas name, the rows that ablate it."""
    out: list[tuple[np.ndarray, bool]] = []
    child = term.child
    if not child.is_discrete and child.name in bound.continuous:
        value = bound.continuous[child.name]
        out.append((value.array, value.batched))
    for param in term.params.values():
        names = (param.name,) if isinstance(param, InputRef) else \
            param.names if isinstance(param, FormulaParam) else ()
        for name in names:
            known = (bound.continuous.get(name) if name in program.variables
                     else bound.inputs.get(name))
            if known is not None:
                out.append((known.array, known.batched))
    rows = bound.ablated.get(str(term.expression))
    if rows is not None:
        out.append((rows, True))
    return out


def _field(term: Term, bound: Bound) -> ParamValue | None:
    """The field ``term`` reads cell by cell, when its factor is computed again cell by cell:
    a real child indexed by a discrete variable, its values batched ``[rows, cells]``, a
    ``pointwise`` form whose parameters are literals that do not vary over the field's
    cells, and a term that no row ablates."""
    child = term.child
    if (not isinstance(child, Continuous) or child.index is None or not term.form.pointwise
            or str(term.expression) in bound.ablated):
        return None
    value = bound.continuous.get(child.name)
    if value is None or not value.batched or value.array.ndim != 2:
        return None
    if not all(isinstance(p, ParamValue) and not p.batched and child.index not in p.axes
               for p in term.params.values()):
        return None
    return value


@dataclass
class _Made:
    """One factor of the last question: copies of what it read, its log values (a field
    term's as its form gave them, ``term_log``; any other's as its factor holds them) and its
    factor (the observed variables not sliced). ``owned``: the log values are an array of
    this state's own, which a later question may change in place."""

    reads: list[tuple[np.ndarray, bool]]
    log: np.ndarray
    factor: Factor
    owned: bool = False
    #: a pointwise field term's log densities by value
    memo: Memo | None = None


@dataclass
class _Product:
    """One operand of the last question (a factor, or the sum of the factors over the same
    variables) in the probability domain (an array of this state's own), and its share of the
    offset; ``layout``: the axes, row axis and shape of each of its parts."""

    layout: tuple[tuple[tuple[str, ...], bool, tuple[int, ...]], ...]
    operand: Factor | None
    share: np.ndarray


@dataclass
class _Last:
    """What a layout's last question computed, for the next one with as many rows."""

    size: int
    terms: list[_Made]
    soft: list[_Made]
    discrete: dict[str, np.ndarray]
    products: list[_Product]


def _copies(reads: list[tuple[np.ndarray, bool]]) -> list[tuple[np.ndarray, bool]]:
    return [(np.array(a), batched) for a, batched in reads]


class Recurring:
    """A layout's factors that read evidence or inputs, kept from one question to the next
    (see the module). A question takes the kept state for itself while it runs (a question
    asked meanwhile by another thread finds none and computes afresh), updates it in place,
    and leaves it for the next once it has used the operands it got (:meth:`leave`): they
    are arrays of that state, which the next question changes in place, so a state left
    before its question was contracted would let a thread sharing the program overwrite the
    operands another is contracting."""

    def __init__(self) -> None:
        self.last: _Last | None = None
        #: questions in a row that reused nothing, and questions left to compute afresh
        self.idle, self.resting = 0, 0
        self._taking = threading.Lock()  # one thread takes the kept state at a time

    def __getstate__(self) -> dict:
        return {k: v for k, v in self.__dict__.items() if k != "_taking"}

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._taking = threading.Lock()

    def operands(self, program: ProgramLike, terms: list[Term], bound: Bound
                 ) -> tuple[list[Factor], np.ndarray, _Last | None]:
        """The factors of ``terms`` and of the soft evidence of ``bound``, sliced at the
        observed discrete variables and rescaled (:func:`~bayesprog.inference.factors.rescaled`),
        and the logs of what they were divided by, per row: what the last question with as
        many rows computed, computed again where what they read changed. Third, the state to
        keep for the next question (None: nothing), which the caller gives to :meth:`leave`
        once it has done with the operands (they are arrays of that state)."""
        size = bound.size
        with self._taking:
            last, self.last = self.last, None
        read = sum(v.array.size for kind in (bound.continuous, bound.inputs, bound.soft)
                   for v in kind.values())
        if self.resting or not bound.batch_shape or read > KEPT_SHARE * limit("entries"):
            self.resting = max(self.resting - 1, 0)
            return (*rescaled(question_factors(program, terms, bound), size), None)
        if last is not None and last.size != size:
            last = None
        observed = self._observed(bound, last)
        factors: list[Factor] = []
        changes: list[np.ndarray | None] = []
        terms_made: list[_Made] = []
        reused = False
        for i, term in enumerate(terms):
            made, changed, again = self._term(program, term, bound,
                                              last.terms[i] if last else None)
            reused |= again
            terms_made.append(made)
            factors.append(slice_factor(made.factor, bound))
            changes.append(self._sliced(made.factor, changed, observed, size))
        soft_made: list[_Made] = []
        for i, (name, value) in enumerate(bound.soft.items()):
            made, changed = self._soft(name, value, last.soft[i] if last and i < len(
                last.soft) else None)
            soft_made.append(made)
            factors.append(slice_factor(made.factor, bound))
            changes.append(self._sliced(made.factor, changed, observed, size))
        products, again = self._products(factors, changes, size, last)
        offset = np.zeros(size)
        operands: list[Factor] = []
        for product in products:
            offset += product.share
            if product.operand is not None:
                operands.append(product.operand)
        self.idle = 0 if reused or again else self.idle + 1
        if self.idle >= IDLE:
            self.idle, self.resting = 0, REST
            return operands, offset, None
        kept = sum(m.log.size + sum(a.size for a, _ in m.reads) for m in terms_made + soft_made)
        kept += sum(p.operand.log.size for p in products if p.operand is not None)
        if kept > KEPT_SHARE * limit("entries"):
            return operands, offset, None
        return operands, offset, _Last(size, terms_made, soft_made,
                                       {k: np.array(v) for k, v in bound.discrete.items()},
                                       products)

    def leave(self, last: _Last) -> None:
        """Keep ``last`` (what :meth:`operands` gave) for the layout's next question, once the
        operands it was given with are contracted: the next question changes its arrays in
        place. (A plain assignment: a state left while another thread's question of the
        layout runs is replaced by the one that question leaves, or replaces it; either
        serves the next question.)"""
        self.last = last

    # the factors of the terms ------------------------------------------------------------------
    @staticmethod
    def _term(program: ProgramLike, term: Term, bound: Bound, last: _Made | None
              ) -> tuple[_Made, np.ndarray | None, bool]:
        """The factor of ``term`` for ``bound``, the rows where it changed since ``last``
        (``[size]`` booleans; None: every row, or nothing to compare with) and whether some
        of what ``last`` made was taken again."""
        reads = _reads(program, term, bound)
        comparable = last is not None and len(last.reads) == len(reads) and all(
            a.shape == b.shape and a.dtype == b.dtype and batched == was
            for (a, batched), (b, was) in zip(reads, last.reads, strict=True))
        field = _field(term, bound)
        if field is not None:
            return Recurring._field_term(program, term, bound, field, reads,
                                         last if comparable else None)
        size = bound.size
        if not comparable:
            factor = term_factor(program, term, bound)
            return _Made(_copies(reads), factor.log, factor), None, False
        assert last is not None
        rows = np.zeros(size, bool)
        for (a, batched), (b, _) in zip(reads, last.reads, strict=True):
            if batched:
                rows |= _row_changes(a, b)
            elif unequal(a, b).any():
                factor = term_factor(program, term, bound)
                return _Made(_copies(reads), factor.log, factor), None, False
        count = int(np.count_nonzero(rows))
        if count == 0:
            return last, rows, True
        index = np.flatnonzero(rows)
        for (a, batched), (b, _) in zip(reads, last.reads, strict=True):
            if batched and count > WHOLE * size:
                np.copyto(b, a)
            elif batched:
                b[index] = a[index]
        if count > WHOLE * size or not last.factor.batched:
            factor = term_factor(program, term, bound)
            return _Made(last.reads, factor.log, factor), rows, count < size
        part = term_factor(program, term, bound.take(index))
        log = last.log if last.owned else np.array(last.factor.log)
        log[index] = part.log
        return _Made(last.reads, log, Factor(last.factor.axes, log, True), True), rows, True

    @staticmethod
    def _field_term(program: ProgramLike, term: Term, bound: Bound, field: ParamValue,
                    reads: list[tuple[np.ndarray, bool]], last: _Made | None
                    ) -> tuple[_Made, np.ndarray | None, bool]:
        """The factor of a pointwise field term (see :func:`_field`), computed again at the
        cells whose values changed since ``last``, each changed value's log densities looked
        up by value (:class:`~bayesprog.inference.memo.Memo`) while the term's values
        repeat."""
        size = bound.size
        if last is None:
            log, batched = term_log(program, term, bound)
            made = _Made(_copies(reads), log, as_factor(program, term, log, batched, size))
            return made, None, False
        values = last.reads[0][0]
        cells = unequal(field.array, values)
        flat = np.flatnonzero(cells)
        if not flat.size:
            return last, np.zeros(size, bool), True
        rows = np.asarray(cells.any(axis=1))
        child = term.child
        assert isinstance(child, Continuous) and child.index is not None
        # the log values have the rows' axis, then one per axis of the term: the field's cells
        # on the axis of the variable that indexes it
        at = 1 + term.axes.index(child.index)
        card = cells.shape[1]
        log = last.log
        if not last.owned:  # an array of its own, of the field's shape at least
            shape = list(log.shape)
            shape[0], shape[at] = size, card
            log = np.array(np.broadcast_to(log, np.broadcast_shapes(log.shape, tuple(shape))))
        others = log.shape[1:at] + log.shape[at + 1:]
        params = term_params(program, term, bound)

        def densities(x: np.ndarray) -> np.ndarray:
            """The log densities at the values ``x`` [n]: [n, the other axes' entries]."""
            value, missing = observed_part(term, ParamValue((), x, True))
            part = log_values(program, term, params, value, missing)
            # (a value's cell is its own axis: 1 on the field's; a density that does not read
            # the value has 1 on the rows' axis too)
            part = np.broadcast_to(part, (len(x),) + log.shape[1:at] + (1,) + log.shape[at + 1:])
            return np.take(part, 0, axis=at).reshape(len(x), -1)

        memo = last.memo
        if memo is None:
            from bayesprog.inference.memo import Memo

            memo = Memo(int(np.prod(others, dtype=np.int64)))

        def lookup(x: np.ndarray) -> np.ndarray:
            return memo.lookup(x, densities) if memo.useful else densities(x)

        if flat.size > WHOLE * cells.size:  # every cell: the values as they come, in order
            np.copyto(values, field.array)
            found = lookup(field.array.reshape(-1))
            log = np.moveaxis(found.reshape((size, card) + others), 1, at)
        else:
            changed = field.array.reshape(-1)[flat]
            values.reshape(-1)[flat] = changed
            found = lookup(changed)
            if not others and log.flags.c_contiguous:  # (one index into the flat cells)
                log.reshape(-1)[flat] = found[:, 0]
            else:
                row, cell = np.divmod(flat, card)
                index: list[slice | np.ndarray] = [row] + [slice(None)] * (log.ndim - 1)
                index[at] = cell
                log[tuple(index)] = found.reshape((len(flat),) + others)
        made = _Made(last.reads, log, as_factor(program, term, log, True, size), True, memo)
        # (a value found by value is reused too: the memo's own count decides whether it helps)
        return made, rows, flat.size < cells.size or memo.useful

    @staticmethod
    def _soft(name: str, value: ParamValue, last: _Made | None
              ) -> tuple[_Made, np.ndarray | None]:
        """The factor of the soft evidence on ``name`` given with the question (the log of its
        likelihoods), and the rows where it changed since ``last``."""
        with np.errstate(divide="ignore"):
            factor = Factor((name,), np.log(value.array), value.batched)
        made = _Made([(np.array(value.array), value.batched)], factor.log, factor)
        before = last.reads[0] if last is not None else None
        if before is None or before[0].shape != value.array.shape or before[1] != value.batched:
            return made, None
        if not value.batched:
            return made, None if unequal(value.array, before[0]).any() else np.zeros(1, bool)
        return made, np.asarray(_row_changes(value.array, before[0]))

    # slicing and products ----------------------------------------------------------------------
    @staticmethod
    def _observed(bound: Bound, last: _Last | None) -> dict[str, np.ndarray | None]:
        """The rows where each observed discrete variable changed since ``last`` (None: every
        row)."""
        out: dict[str, np.ndarray | None] = {}
        for name, value in bound.discrete.items():
            before = last.discrete.get(name) if last is not None else None
            if before is None or np.shape(before) != np.shape(value):
                out[name] = None
            elif isinstance(value, np.ndarray) and value.ndim:
                out[name] = unequal(value, before)
            else:
                out[name] = None if unequal(np.asarray(value), before).any() else \
                    np.zeros(bound.size, bool)
        return out

    @staticmethod
    def _sliced(factor: Factor, changed: np.ndarray | None,
                observed: dict[str, np.ndarray | None], size: int) -> np.ndarray | None:
        """The rows where ``factor`` sliced at the observed variables changed: where it
        changed, or where the values it is sliced at did."""
        if changed is None:
            return None
        if changed.shape != (size,):  # (an unchanged factor without the rows' axis)
            changed = np.zeros(size, bool)
        for axis in factor.axes:
            if axis in observed:
                moved = observed[axis]
                if moved is None:
                    return None
                changed = changed | moved
        return changed

    @staticmethod
    def _products(factors: list[Factor], changes: list[np.ndarray | None], size: int,
                  last: _Last | None) -> tuple[list[_Product], bool]:
        """:func:`~bayesprog.inference.factors.rescaled` of ``factors``, one product (or lone
        factor) at a time, each computed again on the rows where one of its factors changed
        (all of them: ``changes`` None); and whether some rows were taken as they were."""
        groups: dict[frozenset[str], list[int]] = {}
        for i, f in enumerate(factors):
            groups.setdefault(frozenset(f.axes), []).append(i)
        # as _same_axes_summed pairs them: factors without axes one by one, the others summed
        members: list[list[int]] = []
        for group in groups.values():
            if len(group) == 1 or not factors[group[0]].axes:
                members.extend([i] for i in group)
            else:
                members.append(group)
        before = last.products if last is not None and len(last.products) == len(members) \
            else None
        out: list[_Product] = []
        reused = False
        for k, parts in enumerate(members):
            fs = [factors[i] for i in parts]
            layout = tuple((f.axes, f.batched, f.log.shape) for f in fs)
            kept = before[k] if before is not None and before[k].layout == layout else None
            batched = any(f.batched for f in fs)
            rows: np.ndarray | None = None
            if kept is not None:
                for i in parts:
                    change = changes[i]
                    if change is None:
                        rows = None
                        break
                    rows = change if rows is None else rows | change
            count = -1 if rows is None else int(np.count_nonzero(rows))
            if kept is not None and count == 0:
                out.append(kept)
                reused = True
                continue
            if kept is None or rows is None or not batched or count > WHOLE * size:
                operand, share = Recurring._rescaled(fs, size)
                out.append(_Product(layout, operand, np.array(share)))
                continue
            reused = True
            index = np.flatnonzero(rows)
            operand, share = Recurring._rescaled(
                [Factor(f.axes, f.log[index], True) if f.batched else f for f in fs],
                len(index))
            kept.share[index] = share
            if operand is not None:
                assert kept.operand is not None
                kept.operand.log[index] = operand.log
            out.append(kept)
        return out, reused

    @staticmethod
    def _rescaled(fs: list[Factor], size: int) -> tuple[Factor | None, np.ndarray]:
        """One product of :func:`~bayesprog.inference.factors.rescaled`: ``fs`` summed (one
        factor: itself) and rescaled, and its share of the offset."""
        if len(fs) == 1:
            return rescale_one(fs[0], fs, size)
        ((total, parts),) = _same_axes_summed(fs)
        return rescale_one(total, parts, size)
