"""Batched evaluation of questions: posteriors and MAP over a compiled program.

A question ``P(searched | known)`` becomes, for bound evidence, a product of factors over the
unobserved discrete variables; each factor is rescaled in log space before it is contracted with
a cached opt_einsum expression. Evidence arrays carry leading batch dimensions, so N evidence sets
are one contraction with a batch index. Rows whose scaled contraction underflows are recomputed
exactly in log space; rows whose evidence truly has probability zero raise
:class:`~bayesprog.errors.ZeroEvidenceError` for posteriors, and get a seeded uniform choice for MAP.

A discrete question over fixed tables whose observed and searched variables span at most
``TABLE_LIMIT`` joint states is compiled, at its first call, into the table
``P(observed, searched)``; later evidence sets are lookups in it.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
import opt_einsum
from scipy.special import logsumexp

from bayesprog.errors import QuestionError, ZeroEvidenceError
from bayesprog.forms import ParamValue, TermContext
from bayesprog.spec.check import InputRef, Term
from bayesprog.variables import Continuous, Discrete

if TYPE_CHECKING:
    from bayesprog.program import Program, Question

TIE_RTOL = 1e-12


@dataclass
class Posterior:
    """``P(searched | evidence)``: ``probabilities`` has shape ``batch + cards of variables``."""

    question: str
    variables: tuple[str, ...]
    states: dict[str, tuple[str, ...]]
    probabilities: np.ndarray
    log_evidence: np.ndarray
    batch_shape: tuple[int, ...]
    ablated: tuple[str, ...] = ()

    def to_json(self) -> dict[str, Any]:
        return {
            "question": self.question,
            "variables": list(self.variables),
            "states": {v: list(s) for v, s in self.states.items()},
            "probabilities": self.probabilities.tolist(),
            "ablated": list(self.ablated),
        }


@dataclass
class MapResult:
    """The joint argmax of the searched variables (others summed out), ties broken by an RNG.

    ``indices`` has shape ``batch + (len(variables),)``; ``probability`` is the posterior
    probability of the chosen assignment; ``ties`` counts the assignments that shared the maximum.
    """

    question: str
    variables: tuple[str, ...]
    states: dict[str, tuple[str, ...]]
    indices: np.ndarray
    probability: np.ndarray
    ties: np.ndarray
    zero_evidence: np.ndarray
    posterior: Posterior
    ablated: tuple[str, ...] = ()

    @property
    def assignment(self) -> dict[str, Any]:
        """State names of the argmax (arrays of names when batched)."""
        out = {}
        for i, var in enumerate(self.variables):
            names = np.asarray(self.states[var], dtype=object)
            chosen = names[self.indices[..., i]]
            out[var] = chosen if self.indices.ndim > 1 else str(chosen)
        return out

    def to_json(self) -> dict[str, Any]:
        assignment = self.assignment
        return {
            "question": self.question,
            "map": {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in assignment.items()},
            "probability": self.probability.tolist(),
            "ties": self.ties.tolist(),
            "zero_evidence": self.zero_evidence.tolist(),
            "ablated": list(self.ablated),
        }


@dataclass
class _Factor:
    axes: tuple[str, ...]
    log: np.ndarray  # [B] + cards if batched, else cards
    batched: bool


@dataclass
class _Bound:
    """Evidence, inputs and soft evidence bound to flat batch arrays."""

    batch_shape: tuple[int, ...]
    discrete: dict[str, np.ndarray | int] = field(default_factory=dict)
    continuous: dict[str, ParamValue] = field(default_factory=dict)
    inputs: dict[str, ParamValue] = field(default_factory=dict)
    soft: dict[str, ParamValue] = field(default_factory=dict)

    @property
    def size(self) -> int:
        return int(np.prod(self.batch_shape)) if self.batch_shape else 1


def _flatten(arr: np.ndarray, own: tuple[int, ...], batch_shape: tuple[int, ...], trailing: int):
    """Broadcast ``arr`` (batch ``own`` + trailing dims) to the common batch, flattened to one axis."""
    if not own:
        return arr, False
    tail = arr.shape[arr.ndim - trailing :] if trailing else ()
    full = np.broadcast_to(arr, batch_shape + tail)
    return full.reshape((-1,) + tail), True


def bind(
    program: Program,
    question: Question,
    evidence: Mapping[str, Any] | None,
    inputs: Mapping[str, Any] | None,
    soft: Mapping[str, Any] | None,
) -> _Bound:
    expr = question.expression
    variables = program.variables
    values: dict[str, Any] = dict(expr.values)
    for name, value in (evidence or {}).items():
        if name not in variables:
            raise QuestionError(f"evidence for unknown variable {name!r} "
                                f"(declared: {', '.join(variables)})")
        if name not in expr.right:
            raise QuestionError(f"evidence for {name!r}, which is not known in {expr}: expected "
                                f"evidence for {', '.join(expr.right) or 'no variable'}")
        if name in expr.values:
            raise QuestionError(f"{name} is fixed to {expr.values[name]!r} by the question "
                                "and given again as evidence")
        values[name] = value
    missing = [n for n in expr.right if n not in values]
    if missing:
        raise QuestionError(f"missing evidence for {', '.join(missing)} in {expr}")

    staged: list[tuple[str, str, np.ndarray, tuple[int, ...], int]] = []
    for name, value in values.items():
        var = variables[name]
        if isinstance(var, Discrete):
            idx = _state_indices(var, value)
            staged.append(("discrete", name, idx, idx.shape, 0))
        else:
            arr = _continuous_values(var, value, variables)
            trailing = 1 if var.index is not None else 0
            staged.append(("continuous", name, arr, arr.shape[: arr.ndim - trailing], trailing))
    for name, value in (inputs or {}).items():
        decl = program.inputs.get(name)
        if decl is None:
            raise QuestionError(f"unknown input {name!r} (declared inputs: "
                                f"{', '.join(program.inputs) or 'none'})")
        arr = _input_array(program, decl, value)
        staged.append(("input", name, arr, arr.shape[: arr.ndim - decl.ndim], decl.ndim))
    for name, value in (soft or {}).items():
        var = variables.get(name)
        if not isinstance(var, Discrete):
            raise QuestionError(f"soft evidence needs a declared discrete variable, found {name!r}")
        arr = np.asarray(value, dtype=float)
        if arr.ndim < 1 or arr.shape[-1] != var.card or np.any(arr < 0) or not np.all(np.isfinite(arr)):
            raise QuestionError(f"soft evidence on {name}: expected {var.card} non-negative "
                                f"likelihoods (one per state), found shape {arr.shape}")
        staged.append(("soft", name, arr, arr.shape[:-1], 1))
    try:
        batch_shape = tuple(np.broadcast_shapes(*(s[3] for s in staged))) if staged else ()
    except ValueError:
        shapes = ", ".join(f"{s[1]}: {s[3]}" for s in staged)
        raise QuestionError(f"batch shapes do not broadcast together ({shapes})") from None
    bound = _Bound(batch_shape)
    for kind, name, arr, own, trailing in staged:
        flat, batched = _flatten(arr, own, batch_shape, trailing)
        if kind == "discrete":
            bound.discrete[name] = flat if batched else int(flat)
        elif kind == "continuous":
            var = variables[name]
            axes = (var.index,) if var.index else ()  # type: ignore[union-attr]
            bound.continuous[name] = ParamValue(axes, flat, batched)
        elif kind == "input":
            bound.inputs[name] = ParamValue(program.inputs[name].axes, flat, batched)
        else:
            bound.soft[name] = ParamValue((name,), flat, batched)
    return bound


def _state_indices(var: Discrete, value: Any) -> np.ndarray:
    arr = np.asarray(value)
    if arr.dtype.kind in "iu":
        if var.values is not None:
            lookup = {int(v): i for i, v in enumerate(var.values)}
            bad = [v for v in np.unique(arr) if int(v) not in lookup]
            if bad:
                raise QuestionError(f"unknown value {bad[0]} of {var.name} (expected "
                                    f"{var.values[0]}..{var.values[-1]})")
            return np.vectorize(lookup.__getitem__, otypes=[np.intp])(arr) if arr.size else arr
        if arr.size and (arr.min() < 0 or arr.max() >= var.card):
            bad = arr[(arr < 0) | (arr >= var.card)].ravel()[0]
            raise QuestionError(f"state index {bad} of {var.name} is out of range "
                                f"(0..{var.card - 1})")
        return arr.astype(np.intp)
    if arr.dtype.kind in "USO":
        names, inverse = np.unique(arr.astype(str), return_inverse=True)
        codes = np.empty(len(names), dtype=np.intp)
        for i, item in enumerate(names):
            try:
                codes[i] = var.index_of(str(item))
            except KeyError:
                raise QuestionError(f"unknown state {str(item)!r} of {var.name} (expected one "
                                    f"of {var.describe_states()})") from None
        return codes[inverse].reshape(arr.shape)
    raise QuestionError(f"evidence for {var.name}: expected state names or indices, "
                        f"found {arr.dtype} values")


def _continuous_values(var: Continuous, value: Any, variables: Mapping) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise QuestionError(f"evidence for {var.name}: expected numbers, found {value!r}") from None
    if var.index is not None:
        card = variables[var.index].card
        if arr.ndim < 1 or arr.shape[-1] != card:
            raise QuestionError(f"evidence for field {var.name}: expected a last dimension of "
                                f"{card} (one value per state of {var.index}), found shape "
                                f"{arr.shape}")
    missing = np.isnan(arr)
    if missing.any() and var.index is None:
        raise QuestionError(f"evidence for {var.name}: expected numbers, found NaN (a variable "
                            "that is not observed is left out of the evidence)")
    if not np.all(np.isfinite(arr[~missing])) and np.isfinite(var.width):
        raise QuestionError(f"evidence for {var.name}: expected finite values")
    with np.errstate(invalid="ignore"):
        outside = (arr < var.low) | (arr > var.high)
    if np.any(outside):
        raise QuestionError(f"evidence {var.name}={arr[outside].ravel()[0]:g} is outside its "
                            f"support [{var.low:g}, {var.high:g}]")
    return arr


def _input_array(program: Program, decl: Any, value: Any) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise QuestionError(f"input {decl.name!r}: expected an array of numbers") from None
    want: list[int | str] = [program.variables[a].card for a in decl.axes] + list(decl.event)
    declared = list(decl.axes) + list(decl.event)
    ok = arr.ndim >= len(want)
    symbols: dict[str, int] = {}
    if ok:
        for w, got in zip(want, arr.shape[arr.ndim - len(want) :], strict=False):
            if isinstance(w, int):
                ok &= w == got
            else:
                ok &= symbols.setdefault(w, got) == got
    if not ok:
        raise QuestionError(f"input {decl.name!r}: expected trailing shape {declared} "
                            f"(= {[w if isinstance(w, int) else '?' for w in want]}), found "
                            f"{list(arr.shape)}")
    if not np.all(np.isfinite(arr)):
        raise QuestionError(f"input {decl.name!r}: expected finite values")
    return arr


def relevant_terms(program: Program, question: Question, bound: _Bound) -> list[Term]:
    """The terms that matter: those of ancestors of searched, observed or soft-evidence variables.

    A barren variable (no observed descendant, not searched) sums out to one with its term,
    unless a term is unnormalised (a potential): those children are always kept.
    """
    targets = set(question.expression.left) | set(bound.discrete) | set(bound.continuous)
    targets |= set(bound.soft)
    terms = program.active_terms
    for t in terms:
        if t.soft or not t.form.is_normalized(t.child):
            targets.add(t.child.name)
    keep = set(targets)
    for name in targets:
        keep |= program.ancestors(name)
    for name in keep:
        var = program.variables[name]
        if not var.is_discrete and name not in bound.continuous:
            raise QuestionError(f"continuous variable {name!r} is neither known nor barren in "
                                f"{question.expression}: give it as evidence")
    return [t for t in terms if t.child.name in keep]


def _is_static(term: Term) -> bool:
    """A term whose factor does not depend on the question's evidence or inputs."""
    return (
        term.child.is_discrete
        and term.form.name != "program"
        and not any(isinstance(v, InputRef) for v in term.params.values())
    )


def _bound_param(term: Term, key: str, ref: InputRef, bound: _Bound) -> ParamValue:
    """An input bound to a parameter, checked against the parameter's declaration."""
    if ref.name not in bound.inputs:
        decl = f" {ref.name!r}"
        raise QuestionError(f"missing input{decl}, needed by term {term.label}")
    value = bound.inputs[ref.name]
    declared = {p.name: p for p in term.form.params}.get(key)
    if declared is None:
        return value
    arr = value.array
    ndim = term.form.event_ndim(declared, term.child)
    expected = term.form.event_shape(declared, term.child)
    if expected is not None and arr.shape[arr.ndim - ndim :] != expected:
        raise QuestionError(f"input {ref.name!r} for {term.form.name} parameter {key!r} of "
                            f"{term.label}: expected trailing shape {list(expected)}, found "
                            f"{list(arr.shape[arr.ndim - ndim:])}")
    if not declared.constraint.ok(arr):
        raise QuestionError(f"input {ref.name!r} for {term.form.name} parameter {key!r} of "
                            f"{term.label}: expected values {declared.constraint}")
    return value


def _observed_part(term: Term, value: ParamValue | None
                   ) -> tuple[ParamValue | None, ParamValue | None]:
    """A field's value with its missing (NaN) entries moved into the support, and where they
    are. A missing entry is marginalised: the term's factor is 1 there, which needs a form that
    integrates to one over the child."""
    if value is None or not np.isnan(value.array).any():
        return value, None
    child = term.child
    assert isinstance(child, Continuous)
    if not term.form.is_normalized(child):
        raise QuestionError(f"evidence for {child.name}: a missing (NaN) field value needs a "
                            f"normalised form, but {term.label} is a {term.form.name} potential")
    missing = np.isnan(value.array)
    low, high = (b if np.isfinite(b) else None for b in (child.low, child.high))
    inside = (low + high) / 2 if low is not None and high is not None else (low or high or 0.0)
    return (ParamValue(value.axes, np.where(missing, inside, value.array), value.batched),
            ParamValue(value.axes, missing, value.batched))


def _term_factor(program: Program, term: Term, bound: _Bound) -> _Factor:
    static = _is_static(term)
    if static:
        cached = program._static_factors.get(id(term))
        if cached is not None:
            return cached
    params = {}
    for key, value in term.params.items():
        params[key] = _bound_param(term, key, value, bound) if isinstance(value, InputRef) else value
    value = bound.continuous.get(term.child.name) if not term.child.is_discrete else None
    value, missing = _observed_part(term, value)
    axes = term.axes
    cards = tuple(program.variables[a].card for a in axes)  # type: ignore[union-attr]
    ctx = TermContext(term.child, term.parents, axes, cards, params, value, program.variables,
                      term.extra)
    try:
        log = np.asarray(term.form.log_factor(ctx), dtype=float)
        full = np.broadcast_shapes(log.shape, (log.shape[0],) + cards)
    except ValueError as exc:
        raise QuestionError(f"term {term.label}: {exc}") from None
    batched = full[0] != 1 or any(p.batched for p in params.values()) or bool(
        value is not None and value.batched
    )
    log = np.broadcast_to(log, full)
    if missing is not None:
        # a field value that is not observed: the density integrates to one over it
        log = np.where(missing.aligned(axes, 0), 0.0, log)
    if not batched:
        log = log[0]
    elif log.shape[0] != bound.size:
        log = np.broadcast_to(log, (bound.size,) + cards)
    factor = _Factor(axes, log, batched)
    if static:
        program._static_factors[id(term)] = factor
    return factor


def _slice(f: _Factor, bound: _Bound) -> _Factor:
    observed = [i for i, a in enumerate(f.axes) if a in bound.discrete]
    if not observed:
        return f
    rest = [i for i in range(len(f.axes)) if i not in observed]
    index = [bound.discrete[f.axes[i]] for i in observed]
    any_batched = f.batched or any(isinstance(i, np.ndarray) for i in index)
    if f.batched:
        arr = f.log.transpose([0] + [1 + i for i in observed] + [1 + i for i in rest])
        sliced = arr[(np.arange(bound.size),) + tuple(index)]
    else:
        arr = f.log.transpose(observed + rest)
        sliced = arr[tuple(index)]
        if any_batched and sliced.shape[0] != bound.size:
            sliced = np.broadcast_to(sliced, (bound.size,) + sliced.shape[1:])
    return _Factor(tuple(f.axes[i] for i in rest), sliced, any_batched)


class _Plans:
    """A cache of opt_einsum contraction expressions keyed by the operands' layout."""

    def __init__(self) -> None:
        self._cache: dict[Any, Any] = {}

    def get(self, operands: list[_Factor], output: tuple[str, ...], batched_out: bool):
        # the batch size is left out of the key: a plan serves every batch size (opt_einsum
        # checks ranks, not sizes), so batches that vary from call to call are not replanned
        key = (tuple((f.axes, f.batched, f.log.shape[f.batched:]) for f in operands), output,
               batched_out)
        expr = self._cache.get(key)
        if expr is None:
            names = sorted({a for f in operands for a in f.axes} | set(output))
            sym = {n: opt_einsum.get_symbol(i + 1) for i, n in enumerate(names)}
            batch = opt_einsum.get_symbol(0)
            terms = [(batch if f.batched else "") + "".join(sym[a] for a in f.axes)
                     for f in operands]
            out = (batch if batched_out else "") + "".join(sym[a] for a in output)
            eq = ",".join(terms) + "->" + out
            expr = opt_einsum.contract_expression(eq, *(f.log.shape for f in operands))
            self._cache[key] = expr
        return expr


#: Largest joint table (entries) that a compiled discrete question keeps (see _table_plan).
TABLE_LIMIT = 1 << 20
#: Below this, a row's normaliser is recomputed in log space (underflow, or subnormal precision).
TINY = 1e-280


@dataclass
class _TablePlan:
    """A compiled discrete question: the joint table over observed + searched variables."""

    observed: tuple[str, ...]
    table: np.ndarray
    log_offset: float


def _table_plan(program: Program, question: Question, bound: _Bound) -> _TablePlan | None:
    """For a question over fixed tables (no continuous evidence, inputs or soft evidence),
    ``P(observed, searched)`` is computed once, by the same scaled contraction, if it has at
    most ``TABLE_LIMIT`` entries; every later evidence set is then a lookup in it."""
    if bound.continuous or bound.inputs or bound.soft:
        return None
    searched = question.expression.left
    observed = tuple(sorted(bound.discrete))
    key = (searched, observed)
    if key in program._tables:
        return program._tables[key]
    plan = None
    terms = relevant_terms(program, question, bound)
    cards = [program.variables[v].card for v in observed + searched]  # type: ignore[union-attr]
    if all(_is_static(t) for t in terms) and int(np.prod(cards)) <= TABLE_LIMIT:
        empty = _Bound(())
        offset = 0.0
        operands = []
        for t in terms:
            f = _term_factor(program, t, empty)
            m = float(np.max(f.log)) if f.log.size else 0.0
            m = m if np.isfinite(m) else 0.0
            offset += m
            operands.append(_Factor(f.axes, np.exp(f.log - m), False))
        table = _contract(program, operands, observed + searched, False, 1)
        plan = _TablePlan(observed, np.ascontiguousarray(table), offset)
    program._tables[key] = plan
    return plan


def _from_table(program: Program, question: Question, bound: _Bound,
                plan: _TablePlan) -> Posterior | None:
    searched = question.expression.left
    index = tuple(bound.discrete[v] for v in plan.observed)
    rows = plan.table[index] if index else plan.table
    cards = rows.shape[rows.ndim - len(searched) :]
    rows = rows.reshape((-1,) + cards)
    if rows.shape[0] != bound.size:
        rows = np.broadcast_to(rows, (bound.size,) + cards)
    z = rows.reshape(bound.size, -1).sum(axis=1)
    if not np.all(z > TINY):
        return None  # some row needs the exact log-space path
    probs = rows / z.reshape((-1,) + (1,) * len(cards))
    shape = bound.batch_shape
    return Posterior(
        question=str(question.expression),
        variables=searched,
        states={v: program.variables[v].states for v in searched},  # type: ignore[union-attr]
        probabilities=probs.reshape(shape + cards),
        log_evidence=(np.log(z) + plan.log_offset).reshape(shape),
        batch_shape=shape,
        ablated=program.ablated,
    )


def compute_posterior(program: Program, question: Question, bound: _Bound) -> Posterior:
    plan = _table_plan(program, question, bound)
    if plan is not None:
        answer = _from_table(program, question, bound, plan)
        if answer is not None:
            return answer
    expr = question.expression
    searched = expr.left
    factors = []
    for term in relevant_terms(program, question, bound):
        factors.append(_slice(_term_factor(program, term, bound), bound))
    for name, pv in bound.soft.items():
        with np.errstate(divide="ignore"):
            log = np.log(pv.array)
        factors.append(_slice(_Factor((name,), log, pv.batched), bound))

    size = bound.size
    offset = np.zeros(size)
    operands: list[_Factor] = []
    for f in factors:
        red = tuple(range(1 if f.batched else 0, f.log.ndim))
        with np.errstate(invalid="ignore"):
            m = np.max(f.log, axis=red, keepdims=True) if red else f.log
        if np.any(m == np.inf):
            raise QuestionError(f"an infinite density over {', '.join(f.axes) or 'the evidence'}: "
                                "a value sits on a singular point of its density")
        m = np.where(np.isfinite(m), m, 0.0)
        if not red:
            offset += np.broadcast_to(f.log, (size,)) if f.batched else f.log
            continue
        offset += m.reshape(-1) if f.batched else m.reshape(())
        operands.append(_Factor(f.axes, np.exp(f.log - m), f.batched))
    batched_out = any(f.batched for f in factors) or bool(bound.batch_shape)
    table = _contract(program, operands, searched, batched_out, size)
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
            lt = _log_contract(logs, searched)
            total = logsumexp(lt) if np.isfinite(lt).any() else -np.inf
            log_z[row] = total
            probs[row] = np.exp(lt - total) if np.isfinite(total) else 0.0
    cards = tuple(program.variables[v].card for v in searched)  # type: ignore[union-attr]
    shape = bound.batch_shape
    return Posterior(
        question=str(expr),
        variables=searched,
        states={v: program.variables[v].states for v in searched},  # type: ignore[union-attr]
        probabilities=probs.reshape(shape + cards),
        log_evidence=log_z.reshape(shape),
        batch_shape=shape,
        ablated=program.ablated,
    )


def _contract(program, operands, searched, batched_out, size):
    if not operands:
        cards = tuple(program.variables[v].card for v in searched)
        return np.ones(((size,) if batched_out else ()) + cards)
    present = {a for f in operands for a in f.axes}
    missing = [v for v in searched if v not in present]
    if missing:  # a searched variable with no factor left: uniform over its states
        for v in missing:
            operands.append(_Factor((v,), np.ones(program.variables[v].card), False))
    if batched_out and not any(f.batched for f in operands):
        operands.append(_Factor((), np.ones(size), True))
    expr = program._plans.get(operands, searched, batched_out)
    return expr(*(f.log for f in operands))


def _log_contract(factors: list[tuple[tuple[str, ...], np.ndarray]], output: tuple[str, ...]):
    """Exact log-space variable elimination, for rows whose scaled contraction underflowed."""
    pool = [(tuple(a), np.asarray(v, dtype=float)) for a, v in factors]
    names = {a for axes, _ in pool for a in axes} - set(output)
    while names:
        var = min(names, key=lambda n: len({a for axes, _ in pool if n in axes for a in axes}))
        names.discard(var)
        take = [f for f in pool if var in f[0]]
        pool = [f for f in pool if var not in f[0]]
        axes, arr = _log_product(take)
        pool.append((tuple(a for a in axes if a != var), logsumexp(arr, axis=axes.index(var))))
    axes, arr = _log_product(pool, output)
    return arr


def _log_product(factors, order: Sequence[str] | None = None):
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


def choose_map(posterior: Posterior, question: str, rng: Any, ablated: tuple[str, ...]) -> MapResult:
    """Joint argmax per batch row; ties (relative 1e-12) broken uniformly by ``rng``.

    ``rng`` is a ``numpy.random.Generator`` (or a seed) shared by the rows, or a sequence of one
    generator per row: then a row's choice does not depend on the rest of the batch.
    """
    shape = posterior.batch_shape
    cards = posterior.probabilities.shape[len(shape) :]
    flat = posterior.probabilities.reshape((-1, int(np.prod(cards))))
    rows = flat.shape[0]
    if isinstance(rng, Sequence) and not isinstance(rng, (str, bytes)):
        if len(rng) != rows:
            raise QuestionError(f"expected one generator per batch row ({rows}), got {len(rng)}")
        gens = [r if isinstance(r, np.random.Generator) else np.random.default_rng(r) for r in rng]
    else:
        gen = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        gens = [gen] * rows
    best = flat.max(axis=1)
    tied = flat >= (best * (1 - TIE_RTOL))[:, None]
    counts = tied.sum(axis=1)
    choice = flat.argmax(axis=1)
    for row in np.flatnonzero(counts > 1):
        candidates = np.flatnonzero(tied[row])
        choice[row] = candidates[gens[row].integers(candidates.size)]
    indices = np.stack(np.unravel_index(choice, cards), axis=-1).reshape(shape + (len(cards),))
    zero = ~(posterior.log_evidence > -np.inf)
    return MapResult(
        question=question,
        variables=posterior.variables,
        states=posterior.states,
        indices=indices,
        probability=flat[np.arange(rows), choice].reshape(shape),
        ties=counts.reshape(shape),
        zero_evidence=np.asarray(zero).reshape(shape),
        posterior=posterior,
        ablated=ablated,
    )


def zero_rows_message(posterior: Posterior) -> str:
    zero = np.argwhere(~(posterior.log_evidence > -np.inf))
    where = ", ".join(str(tuple(int(i) for i in row)) for row in zero[:5]) if posterior.batch_shape else ""
    return (f"the evidence has probability zero under the program for {posterior.question}"
            + (f" (batch rows {where}{', ...' if len(zero) > 5 else ''})" if where else "")
            + ": no posterior exists; check the evidence or use a MAP question")


def check_zero(posterior: Posterior) -> None:
    if np.any(~(posterior.log_evidence > -np.inf)):
        raise ZeroEvidenceError(zero_rows_message(posterior))
