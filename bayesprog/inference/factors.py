"""The factors of a question: which terms matter, and each term as a log-factor over the
question's unobserved discrete variables, for bound evidence (batched or not)."""

from __future__ import annotations

import math
from collections.abc import Collection, Iterable

import numpy as np

from bayesprog.errors import QuestionError
from bayesprog.forms import FormulaParam, InputRef, ParamValue, TermContext, get_form
from bayesprog.forms.standard import Categorical
from bayesprog.inference.binding import Bound
from bayesprog.inference.core import Factor
from bayesprog.inference.formulas import formula_value, log_factor
from bayesprog.inference.protocol import ProgramLike
from bayesprog.inference.relevance import family
from bayesprog.model import Term
from bayesprog.vocabulary.variables import Continuous, discrete


def relevant_names(program: ProgramLike, searched: Iterable[str], observed: Iterable[str],
                   soft: Iterable[str] = ()) -> set[str]:
    """The searched, observed and soft-evidence variables and all their ancestors.

    A barren variable (no observed descendant, not searched) sums out to one with its term,
    unless a term is unnormalised (a potential): those children are always kept.
    """
    graph = family(program)
    return graph.ancestors({*searched, *observed, *soft, *graph.unnormalised})


def terms_of(program: ProgramLike, names: Collection[str]) -> list[Term]:
    """The program's terms (ablations applied) of the variables ``names``, in its order (with
    the soft-evidence terms it writes on them)."""
    return [t for t in program.active_terms if t.child.name in names]


def relevant_terms(program: ProgramLike, searched: Iterable[str], observed: Iterable[str],
                   soft: Iterable[str] = ()) -> list[Term]:
    """The terms of :func:`relevant_names`."""
    return terms_of(program, relevant_names(program, searched, observed, soft))


def latent_continuous(terms: list[Term], observed: Collection[str]) -> list[str]:
    """The continuous variables of ``terms`` that the question neither knows (``observed``)
    nor sums out by itself (searched, or parents of a relevant term): the discrete methods
    cannot answer."""
    return [t.child.name for t in terms
            if not t.child.is_discrete and t.child.name not in observed]


def is_static(term: Term) -> bool:
    """A term whose factor does not depend on the question's evidence or inputs."""
    discrete = {p.name for p in term.parents if p.is_discrete}
    return (
        term.child.is_discrete
        and not term.form.subprogram
        and not any(isinstance(v, InputRef) or (isinstance(v, FormulaParam) and any(
            name not in discrete for name in v.names))  # a real parent, or an input
            for v in term.params.values())
    )


def given_table(term: Term) -> ParamValue | None:
    """The table of a term written as one (a categorical form with one table over its
    parents' axes, then the child's, not batched), or None."""
    param = next(iter(term.params.values()), None) if len(term.params) == 1 else None
    if (isinstance(term.form, Categorical) and isinstance(param, ParamValue)
            and not param.batched and param.axes == tuple(p.name for p in term.parents)):
        return param
    return None


def static_table(program: ProgramLike, term: Term) -> tuple[np.ndarray, float]:
    """A static term's factor (axes ``term.axes``) in the probability domain, divided by its
    largest entry, and the log of that entry (0 for a factor of zeros); made once per program.
    A table given as probabilities is read as it is, not through its logarithm."""
    cache = program.inference_cache.static_tables
    found = cache.get(id(term))
    if found is not None:
        return found
    param = given_table(term)
    if param is not None:
        table = np.moveaxis(np.asarray(param.array, dtype=float), -1, 0)
        top = float(table.max()) if table.size else 0.0
        found = (table / top, math.log(top)) if top > 0 else (table.copy(), 0.0)
    else:
        f = term_factor(program, term, Bound(()))
        top = float(np.max(f.log)) if f.log.size else 0.0
        top = top if np.isfinite(top) else 0.0
        found = (np.exp(f.log - top), top)
    cache[id(term)] = found
    return found


def plain_table(program: ProgramLike, term: Term
                ) -> tuple[tuple[str, ...], np.ndarray, float] | None:
    """A static term's table with its axes and the log of what it was divided by: a table
    given as probabilities as the program holds it (parents' axes, then the child's: nothing
    made), any other static term as :func:`static_table` makes it; None for a term that reads
    evidence values or inputs."""
    if not is_static(term):
        return None
    param = given_table(term)
    if param is not None and param.array.dtype == np.float64:
        return param.axes + (term.child.name,), param.array, 0.0
    table, top = static_table(program, term)
    return term.axes, table, top


def _bound_param(term: Term, key: str, ref: InputRef, bound: Bound) -> ParamValue:
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


def observed_part(term: Term, value: ParamValue | None
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


def term_factor(program: ProgramLike, term: Term, bound: Bound) -> Factor:
    """The log-factor of ``term`` over its discrete axes for ``bound``'s evidence and inputs
    (the observed axes not yet sliced): ``[size] + cards`` when it varies by row, else
    ``cards``."""
    if bound.ablated:
        rows = bound.ablated.get(str(term.expression))
        if rows is not None:
            return partly_ablated(program, term, bound, rows)
    static = is_static(term)
    if static:
        cached = program.inference_cache.static_factors.get(id(term))
        if cached is not None:
            return cached
    log, batched = term_log(program, term, bound)
    factor = as_factor(program, term, log, batched, bound.size)
    if static:
        program.inference_cache.static_factors[id(term)] = factor
    return factor


def term_params(program: ProgramLike, term: Term, bound: Bound) -> dict[str, ParamValue]:
    """The term's parameters for ``bound``: its inputs bound and checked, its formulas
    evaluated, its literals as they are."""
    params: dict[str, ParamValue] = {}
    for key, param in term.params.items():
        if isinstance(param, InputRef):
            params[key] = _bound_param(term, key, param, bound)
        elif isinstance(param, FormulaParam):
            params[key] = formula_value(program.variables, param, bound, f"term {term.label}")
        else:
            params[key] = param
    return params


def term_log(program: ProgramLike, term: Term, bound: Bound) -> tuple[np.ndarray, bool]:
    """The log values of ``term`` as its form gives them for ``bound`` (``[size or 1]`` then
    one axis per discrete axis of the term, of its card or 1; a missing field value's 0), and
    whether they vary by row."""
    params = term_params(program, term, bound)
    observed = bound.continuous.get(term.child.name) if not term.child.is_discrete else None
    value, missing = observed_part(term, observed)
    log = log_values(program, term, params, value, missing)
    batched = log.shape[0] != 1 or any(p.batched for p in params.values()) or bool(
        value is not None and value.batched)
    return log, batched


def log_values(program: ProgramLike, term: Term, params: dict[str, ParamValue],
               value: ParamValue | None, missing: ParamValue | None) -> np.ndarray:
    """The log values of ``term`` (see :func:`term_log`) for its parameters, the value of its
    child (a real child's, with its missing entries moved into the support) and where that
    value is missing."""
    axes = term.axes
    cards = tuple(discrete(program.variables[a]).card for a in axes)
    ctx = TermContext(term.child, term.parents, axes, cards, params, value, program.variables,
                      term.extra)
    try:
        # a value far out in a tail overflows to a log density of -inf: its exact limit
        with np.errstate(over="ignore"):
            log = log_factor(term.form, ctx)
        if missing is not None:
            # a field value that is not observed: the density integrates to one over it
            # (masked before broadcasting over the axes the value does not vary with)
            log = np.where(missing.aligned(axes, 0), 0.0, log)
        if log.shape[1:] != cards:
            np.broadcast_shapes(log.shape, (log.shape[0],) + cards)
    except ValueError as exc:
        raise QuestionError(f"term {term.label}: {exc}") from None
    return log


def as_factor(program: ProgramLike, term: Term, log: np.ndarray, batched: bool,
              size: int) -> Factor:
    """The factor of ``term`` from its log values (:func:`term_log`), broadcast over its
    axes (a view): ``[size] + cards`` when ``batched``, else ``cards``."""
    cards = tuple(discrete(program.variables[a]).card for a in term.axes)
    if log.shape[1:] != cards:
        log = np.broadcast_to(log, np.broadcast_shapes(log.shape, (log.shape[0],) + cards))
    else:  # read-only as a broadcast view is: a static factor is shared by every question
        log = log.view()
        log.flags.writeable = False
    if not batched:
        log = log[0]
    elif log.shape[0] != size:
        log = np.broadcast_to(log, (size,) + cards)
    return Factor(term.axes, log, batched)


def uniform_term(program: ProgramLike, term: Term) -> Term:
    """``term`` made uniform, as an ablation makes it (:meth:`bayesprog.Program.ablate`);
    made once per program (its factor is then kept as a static term's)."""
    made = program.inference_cache.uniform_terms
    found = made.get(id(term))
    if found is None:
        uniform = get_form("uniform")
        assert uniform is not None
        found = made[id(term)] = Term(term.expression, term.child, term.parents, uniform, {},
                                      term.position, description="ablated: uniform")
    return found


def partly_ablated(program: ProgramLike, term: Term, bound: Bound, rows: np.ndarray) -> Factor:
    """The factor of a term made uniform on the rows ``rows`` (``[size]`` booleans) of the
    batch: there, the uniform's (the factor of an ablated term); on the other rows, the
    term's own, computed for those rows alone (a term whose inputs are not read where it is
    ablated)."""
    uniform = term_factor(program, uniform_term(program, term), Bound(()))
    if rows.all():
        return uniform
    kept = np.flatnonzero(~rows)
    own = term_factor(program, term, bound.take(kept))
    cards = uniform.log.shape
    log = np.empty((bound.size,) + cards)
    log[rows] = uniform.log
    log[kept] = own.log if own.batched else own.log[np.newaxis]
    return Factor(uniform.axes, log, True)


def slice_factor(f: Factor, bound: Bound) -> Factor:
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
    return Factor(tuple(f.axes[i] for i in rest), sliced, any_batched)


def question_factors(program: ProgramLike, terms: list[Term], bound: Bound, *,
                     sliced: bool = True) -> list[Factor]:
    """The log-factors of a question: its relevant terms and the soft evidence given with it,
    sliced at the observed discrete variables (``sliced``; else whole, the evidence left to
    the caller)."""
    factors = [term_factor(program, term, bound) for term in terms]
    for name, pv in bound.soft.items():
        with np.errstate(divide="ignore"):
            log = np.log(pv.array)
        factors.append(Factor((name,), log, pv.batched))
    return [slice_factor(f, bound) for f in factors] if sliced else factors


def _row_max(f: Factor) -> np.ndarray:
    red = tuple(range(1 if f.batched else 0, f.log.ndim))
    with np.errstate(invalid="ignore"):
        return np.max(f.log, axis=red, keepdims=True) if red else f.log


def _same_axes_summed(factors: list[Factor]) -> list[tuple[Factor, list[Factor]]]:
    """Factors over the same set of axes added in log space (one exponential instead of one
    per factor: cue fields over the same grid become one factor), each with its parts."""
    groups: dict[frozenset[str], list[Factor]] = {}
    for f in factors:
        groups.setdefault(frozenset(f.axes), []).append(f)
    out: list[tuple[Factor, list[Factor]]] = []
    for group in groups.values():
        if len(group) == 1 or not group[0].axes:
            out.extend((f, [f]) for f in group)
            continue
        axes = group[0].axes
        total: np.ndarray | None = None
        owned = False  # (whether total is a sum made here, which the next part is added to)
        for f in group:
            lead = 1 if f.batched else 0
            log = f.log if f.axes == axes else np.transpose(
                f.log, list(range(lead)) + [lead + f.axes.index(a) for a in axes])
            if not f.batched and any(g.batched for g in group):
                log = log[np.newaxis]
            if total is None:
                total = log
            elif owned and np.broadcast_shapes(total.shape, log.shape) == total.shape:
                total += log
            else:
                total, owned = total + log, True
        assert total is not None
        out.append((Factor(axes, total, any(f.batched for f in group)), group))
    return out


def rescaled(factors: list[Factor], size: int, merge: bool = True
             ) -> tuple[list[Factor], np.ndarray]:
    """Each factor with axes in the probability domain, divided by its largest value (per
    row when batched), and the logs of those divisors and of the factors without axes summed
    per row (``[size]``). With ``merge``, factors over the same axes are added in log space
    first (a product that contraction would form anyway; loopy belief propagation keeps the
    factor graph as it is)."""
    offset = np.zeros(size)
    operands: list[Factor] = []
    pairs = _same_axes_summed(factors) if merge else [(f, [f]) for f in factors]
    for f, parts in pairs:
        operand, share = rescale_one(f, parts, size)
        offset += share
        if operand is not None:
            operands.append(operand)
    return operands, offset


def rescale_one(f: Factor, parts: list[Factor], size: int
                ) -> tuple[Factor | None, np.ndarray]:
    """One factor of :func:`rescaled`: ``f`` (the sum of ``parts`` in log space) in the
    probability domain, divided by its largest value (per row when batched), and the log of
    that divisor, its share of the offset (``[size]`` when batched); a factor without axes is
    all offset (None, its log)."""
    m = _row_max(f)
    # +inf in a part (shows as +inf, or NaN where another part is -inf)
    if np.any(m == np.inf) or (len(parts) > 1 and np.isnan(m).any()):
        for part in parts:
            if np.any(_row_max(part) == np.inf):
                raise QuestionError(f"an infinite density over "
                                    f"{', '.join(part.axes) or 'the evidence'}: a value "
                                    "sits on a singular point of its density")
    if not f.axes:
        return None, np.broadcast_to(f.log, (size,)) if f.batched else f.log
    m = np.where(np.isfinite(m), m, 0.0)
    scaled = f.log - m  # (a new array: its exponential in place)
    return (Factor(f.axes, exp_shared_floor(scaled, f.batched), f.batched),
            m.reshape(-1) if f.batched else m.reshape(()))


def exp_shared_floor(values: np.ndarray, batched: bool) -> np.ndarray:
    """``exp(values)`` in place. Where a quarter or more of a factor's entries equal its
    smallest (per row when ``batched``; a potential's floor, as a gmm's far from its means),
    those share one exponential: the same number for each, computed once."""
    axes = tuple(range(1 if batched else 0, values.ndim))
    if not axes or values.size < 64:
        return np.exp(values, out=values)
    with np.errstate(invalid="ignore"):
        low = np.min(values, axis=axes, keepdims=True)
        floor = values == low
    if 4 * np.count_nonzero(floor) < values.size:
        return np.exp(values, out=values)
    np.exp(values, out=values, where=~floor)
    np.copyto(values, np.exp(low), where=floor)
    return values
