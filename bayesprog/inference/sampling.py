"""Drawing from a program: forward (ancestral) sampling, with the known variables fixed to their
evidence and each draw weighted by their likelihood (likelihood weighting).

Draws are kept as arrays ``[rows, n]`` (a row per evidence set of the batch): a discrete
variable as state indices, a continuous one as values. Row ``r`` draws its uniforms from its
own generator, so its draws do not depend on the other rows of the batch.

Every term is used as a factor over its discrete variables (:func:`term_factor`, the engine's
own): a discrete child is drawn from the term's row at its drawn parents, normalised, and the
draw is weighted by the row's total (one for a normalised term; a potential's mass else); a
known variable is not drawn, and the draw is weighted by its term's factor at the drawn parents.
Continuous variables that are not known are drawn by their form (:meth:`Form.draw`: for most
forms :meth:`Form.sample` of the parameters at each draw), inside their declared support: a
bounded variable is drawn from its term truncated to the support (the density at its drawn
parents, renormalised there), by the quantile function between the CDF at the bounds where the
form has one (``quantile_sample``), by drawing again the values that fell outside otherwise.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from bayesprog.errors import QuestionError
from bayesprog.forms import FormulaParam, ParamValue, TermContext
from bayesprog.inference.answers import generator_of, seed_of
from bayesprog.inference.binding import Bound
from bayesprog.inference.factors import Factor, _bound_param, term_factor
from bayesprog.inference.formulas import formula_value
from bayesprog.inference.protocol import ProgramLike
from bayesprog.limits import check_size
from bayesprog.model import Term
from bayesprog.support.extras import LazyModule
from bayesprog.vocabulary.variables import Continuous, Discrete

#: scipy.special, imported by the first computation that reads it
special = LazyModule("scipy.special")


@dataclass
class Draws:
    """``values[name]``: ``[rows, n]`` state indices (discrete) or values (continuous);
    ``log_weights``: ``[rows, n]`` (zeros for draws that need no weight)."""

    values: dict[str, np.ndarray]
    log_weights: np.ndarray

    @property
    def weights(self) -> np.ndarray:
        """Weights normalised per row (sum to one over the draws of a row)."""
        top = np.max(self.log_weights, axis=1, keepdims=True)
        top = np.where(np.isfinite(top), top, 0.0)
        w = np.exp(self.log_weights - top)
        total = w.sum(axis=1, keepdims=True)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(total > 0, w / total, 0.0)

    @property
    def ess(self) -> np.ndarray:
        """Effective sample size per row, ``(sum w)^2 / sum w^2`` (n when unweighted)."""
        w = self.weights
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(w.sum(axis=1) > 0, 1.0 / (w**2).sum(axis=1), 0.0)


def generators(rng: Any, rows: int) -> list[np.random.Generator]:
    """One generator per row: from a seed ``s`` (row ``r`` uses ``default_rng([s, r])``), from
    a sequence of seeds or generators, one per row, or spawned from one generator."""
    if isinstance(rng, Sequence) and not isinstance(rng, (str, bytes)):
        if len(rng) != rows:
            raise QuestionError(f"rng: expected one seed or generator per batch row ({rows}), "
                                f"found {len(rng)}")
        return [generator_of(r) for r in rng]
    if isinstance(rng, np.random.Generator):
        return list(rng.spawn(rows))
    seed = seed_of(0 if rng is None else rng)
    return [np.random.default_rng([seed, r]) for r in range(rows)]


def _order(program: ProgramLike, terms: list[Term]) -> list[Term]:
    """The decomposition's terms parents first; soft-evidence terms after their variable."""
    import networkx as nx

    by_child = {t.child.name: t for t in terms if not t.soft}
    graph = nx.DiGraph()
    for t in by_child.values():
        graph.add_node(t.child.name)
        for p in t.parents:
            if p.name in by_child:
                graph.add_edge(p.name, t.child.name)
    ordered = [by_child[name] for name in nx.lexicographical_topological_sort(graph)]
    return ordered + [t for t in terms if t.soft]


def _gather(log: np.ndarray, batched: bool, axes: tuple[str, ...], values: dict[str, np.ndarray],
            rows: int, n: int, keep: str | None = None) -> np.ndarray:
    """``log`` (``[rows] + cards`` if batched, else ``cards``) at each draw's states of
    ``axes`` -> ``[rows, n]`` (``[rows, n, card]`` with the axis ``keep`` left whole)."""
    index: list[Any] = []
    if batched:
        index.append(np.arange(rows)[:, None])
    for a in axes:
        index.append(slice(None) if a == keep else values[a])
    if keep is not None:  # move the kept axis last, then take the draws
        k = (1 if batched else 0) + axes.index(keep)
        log = np.moveaxis(log, k, -1)
        index = [i for i in index if not isinstance(i, slice)]
        out = log[tuple(index)] if index else log
        return np.broadcast_to(out, (rows, n, log.shape[-1]))
    out = log[tuple(index)] if index else log
    return np.broadcast_to(out, (rows, n))


def _uniforms(gens: list[np.random.Generator], n: int, k: int = 1) -> np.ndarray:
    """``[rows, n]`` (or ``[rows, n, k]``) uniforms on [0, 1), row ``r`` from ``gens[r]``."""
    shape = (n,) if k == 1 else (n, k)
    return np.stack([g.random(shape) for g in gens])


def draw(program: ProgramLike, terms: list[Term], bound: Bound, n: int,
         gens: list[np.random.Generator]) -> Draws:
    """``n`` draws per row of ``bound`` from the program restricted to ``terms`` (closed
    under parents), the known variables fixed to their evidence and weighted."""
    rows = bound.size
    check_size(float(rows) * n * max(1, len(terms)), f"{n:,} draws of {len(terms)} terms")
    values: dict[str, np.ndarray] = {}
    log_w = np.zeros((rows, n))
    inputs_only = Bound(bound.batch_shape, inputs=bound.inputs)
    for name, idx in bound.discrete.items():
        values[name] = np.broadcast_to(np.asarray(idx).reshape(-1, 1), (rows, n))
    for term in _order(program, terms):
        child = term.child
        name = child.name
        drawn = _drawn_parents(term, bound)
        if term.soft or name in bound.discrete or name in bound.continuous:
            given = bound if not child.is_discrete or term.soft else inputs_only
            log_w = log_w + _at_draws(program, term, given, drawn, values, rows, n)
            continue
        if isinstance(child, Discrete):
            check_size(float(rows) * n * child.card, f"drawing {name} ({child.card:,} states) "
                       f"{n:,} times")
            row = _at_draws(program, term, inputs_only, drawn, values, rows, n, keep=name)
            total = special.logsumexp(row, axis=-1)
            if not np.all(np.isfinite(total)):
                raise QuestionError(f"term {term.label} gives no state of {name} a positive "
                                    "probability for some drawn parents: it cannot be sampled")
            cdf = np.cumsum(np.exp(row - total[..., None]), axis=-1)
            u = _uniforms(gens, n)
            values[name] = np.minimum((cdf < u[..., None] * cdf[..., -1:]).sum(-1),
                                      child.card - 1)
            if not term.form.is_normalized(child):
                log_w = log_w + total
            continue
        assert isinstance(child, Continuous)
        if child.index is not None:
            raise QuestionError(f"field {name} (one value per state of {child.index}) cannot "
                                "be sampled: give it as evidence")
        params = {}
        for key, param in term.params.items():
            declared = {p.name: p for p in term.form.params}.get(key)
            event = term.form.event_ndim(declared, child) if declared else 0
            if isinstance(param, FormulaParam):
                flat = _per_draw(bound, values, drawn, rows, n) if drawn else bound
                value = formula_value(program.variables, param, flat, f"term {term.label}")
                arr = value.aligned(term.axes, event)
                if value.batched and drawn:  # one row per draw
                    params[key] = _gather_param(arr.reshape((rows, n) + arr.shape[1:]), True,
                                                term.axes, values, rows, n, event, per_draw=True)
                    continue
            else:
                value = param if isinstance(param, ParamValue) else _bound_param(
                    term, key, param, bound)
                arr = value.aligned(term.axes, event)
            params[key] = _gather_param(arr, value.batched, term.axes, values, rows, n, event)
        values[name] = _draw_within(program, term, child, params, gens, n)
    for name, pv in bound.soft.items():  # soft evidence given with the question
        with np.errstate(divide="ignore"):
            log_w = log_w + _gather(np.log(pv.array), pv.batched, (name,), values, rows, n)
    return Draws(values, log_w)


#: how many times the values of a form without a quantile function that fell outside a bounded
#: support are drawn again (each time the fraction left is the mass outside, so that a term with
#: a tenth of its mass inside leaves one draw in 10^4 of a million outside at the end)
REDRAWS = 200


def _draw_within(program: ProgramLike, term: Term, child: Continuous,
                 params: dict[str, np.ndarray], gens: list[np.random.Generator],
                 n: int) -> np.ndarray:
    """``n`` values of ``child`` per row from its term at each draw's ``params``, inside the
    child's support (see the module)."""
    form, low, high = term.form, child.low, child.high
    values = {k: ParamValue((), v, True) for k, v in params.items()}
    at_draws = TermContext(child, (), (), (), values, None, program.variables, term.extra)
    u = _uniforms(gens, n, 2)
    if not (np.isfinite(low) or np.isfinite(high)):
        return form.draw(at_draws, u)
    where = f"[{low:g}, {high:g}]"
    if form.quantile_sample:

        def cdf(x: float) -> np.ndarray:
            at = ParamValue((), np.full(u.shape[:-1], x), True)
            ctx = TermContext(child, (), (), (), values, at, program.variables, term.extra)
            return np.broadcast_to(np.asarray(form.cdf(ctx), float), u.shape[:-1])

        below = cdf(low) if np.isfinite(low) else np.zeros(u.shape[:-1])
        inside = (cdf(high) if np.isfinite(high) else 1.0) - below
        if not np.all(inside > 0):
            raise QuestionError(f"term {term.label} puts no probability inside the support "
                                f"{where} of {child.name} at some of its drawn parents: it "
                                "cannot be drawn there (check the term's parameters or the "
                                "support declared)")
        u = u.copy()
        u[..., 0] = below + u[..., 0] * inside
        return np.clip(form.draw(at_draws, u), low, high)  # (rounding at a bound)
    drawn = form.draw(at_draws, u)
    for _ in range(REDRAWS):
        outside = (drawn < low) | (drawn > high)
        if not outside.any():
            return drawn
        drawn = np.where(outside, form.draw(at_draws, _uniforms(gens, n, 2)), drawn)
    raise QuestionError(f"term {term.label} puts little or no probability inside the support "
                        f"{where} of {child.name}: {REDRAWS} draws in a row fell outside it "
                        "(check the term's parameters or the support declared)")


def _at_draws(program: ProgramLike, term: Term, given: Bound, drawn: tuple[str, ...],
              values: dict[str, np.ndarray], rows: int, n: int,
              keep: str | None = None) -> np.ndarray:
    """The term's log-factor at each draw's states -> ``[rows, n]`` (``[rows, n, card]``
    with ``keep`` whole): evaluated once for ``given``, or draw by draw where its formulas name
    the drawn real variables ``drawn``."""
    if not drawn:
        factor = term_factor(program, term, given)
        return _gather(factor.log, factor.batched, factor.axes, values, rows, n, keep=keep)
    factor = term_factor(program, term, _per_draw(given, values, drawn, rows, n))
    return _gather_draws(factor, values, rows, n, keep=keep)


def _drawn_parents(term: Term, bound: Bound) -> tuple[str, ...]:
    """The real variables that a formula of ``term`` names and that are drawn, not known."""
    real = {p.name for p in term.parents if not p.is_discrete}
    names: dict[str, None] = {}
    for param in term.params.values():
        if isinstance(param, FormulaParam):
            names.update({n: None for n in param.names
                          if n in real and n not in bound.continuous})
    return tuple(names)


def _per_draw(bound: Bound, values: dict[str, np.ndarray], drawn: tuple[str, ...], rows: int,
              n: int) -> Bound:
    """``bound`` with one batch row per draw (``rows * n``), the drawn real variables of
    ``drawn`` given as evidence: a term whose formulas name them is evaluated draw by draw."""
    def spread(pv: ParamValue) -> ParamValue:
        return ParamValue(pv.axes, np.repeat(pv.array, n, axis=0), True) if pv.batched else pv

    continuous = {k: spread(v) for k, v in bound.continuous.items()}
    continuous |= {k: ParamValue((), np.asarray(values[k], float).reshape(-1), True)
                   for k in drawn}
    return Bound((rows * n,), continuous=continuous,
                 inputs={k: spread(v) for k, v in bound.inputs.items()})


def _gather_draws(factor: Factor, values: dict[str, np.ndarray], rows: int, n: int,
                  keep: str | None = None) -> np.ndarray:
    """A factor with one batch row per draw (from :func:`_per_draw`) at each draw's states of
    its axes -> ``[rows, n]`` (``[rows, n, card]`` with the axis ``keep`` left whole)."""
    log = factor.log if factor.batched else factor.log[np.newaxis]
    log = np.broadcast_to(log, (rows * n,) + log.shape[1:]).reshape((rows, n) + log.shape[1:])
    index: list[Any] = [np.arange(rows)[:, None], np.arange(n)[None, :]]
    for a in factor.axes:
        index.append(slice(None) if a == keep else values[a])
    if keep is not None:
        log = np.moveaxis(log, 2 + factor.axes.index(keep), -1)
        index = [i for i in index if not isinstance(i, slice)]
    return np.asarray(log[tuple(index)])


def _gather_param(arr: np.ndarray, batched: bool, axes: tuple[str, ...],
                  values: dict[str, np.ndarray], rows: int, n: int, event: int,
                  per_draw: bool = False) -> np.ndarray:
    """A parameter aligned to ``axes`` (``[b or 1] + [card or 1] + event``) at each draw's
    parent states -> ``[rows, n] + event``; with ``per_draw``, ``arr`` has the two leading
    axes ``[rows, n]`` instead of the batch axis."""
    index: list[Any] = [np.arange(rows)[:, None] if batched else np.zeros((1, 1), np.intp)]
    if per_draw:
        index.append(np.arange(n)[None, :])
    lead = 2 if per_draw else 1
    for i, a in enumerate(axes):
        size = arr.shape[lead + i]
        index.append(values[a] if size > 1 else np.zeros((1, 1), np.intp))
    out = arr[tuple(index)]
    return np.broadcast_to(out, (rows, n) + out.shape[2:])



def sample_program(program: ProgramLike, n: int, evidence: Any, inputs: Any, rng: Any,
                   method: str | None) -> Any:
    """The draws of ``Program.sample`` as a DataFrame (see there)."""
    import pandas as pd

    from bayesprog.errors import expect_mapping
    from bayesprog.inference.binding import bind
    from bayesprog.vocabulary.expressions import Expression, Question

    evidence = expect_mapping(evidence, "evidence", "variable names to values")
    variables = program.variables
    unknown = [name for name in program.conditioning if name not in evidence]
    if unknown:
        names = ", ".join(unknown)
        one = len(unknown) == 1
        raise QuestionError(f"sampling the program needs {names}: "
                            f"{'it has' if one else 'they have'} no term in the decomposition "
                            f"(the program is conditioned on {'it' if one else 'them'}), so "
                            "the draws are made given "
                            f"{'its value' if one else 'their values'}: give "
                            f"{'it' if one else 'them'} as evidence ("
                            + ", ".join(f"{n}=..." for n in unknown) + ")")
    drawn = tuple(name for name, var in variables.items()
                  if name not in evidence and getattr(var, "index", None) is None)
    # the variables without a term are not drawn but given: ancestral sampling takes them
    observed = [name for name in evidence if name not in program.conditioning]
    method = method or ("lw" if observed else "forward")
    if method == "forward" and observed:
        raise QuestionError("forward sampling ignores evidence: use method='lw' or "
                            "'rejection' to condition on it")
    if method == "rejection":
        continuous = [k for k in observed if k in variables and not variables[k].is_discrete]
        if continuous:
            raise QuestionError(f"rejection sampling needs discrete evidence; "
                                f"{', '.join(continuous)} is continuous: use method='lw'")
    question = Question(Expression(drawn or tuple(variables)[:1], tuple(evidence)))
    bound = bind(program, question, evidence, inputs, None)
    if bound.size != 1:
        raise QuestionError(f"sample draws for one evidence set, found a batch of {bound.size}")
    terms = [t for t in program.active_terms
             if getattr(t.child, "index", None) is None or t.child.name in evidence]
    gen = generators(rng, 1)
    weights = None
    if method == "rejection":
        given = set(program.conditioning)
        free = Bound(bound.batch_shape,
                     {k: v for k, v in bound.discrete.items() if k in given},
                     {k: v for k, v in bound.continuous.items() if k in given},
                     inputs=bound.inputs)
        kept: dict[str, list[np.ndarray]] = {name: [] for name in drawn}
        found, tried = 0, 0
        while found < n:
            if tried > 1000 * n:
                raise QuestionError(f"rejection sampling kept {found} of {tried:,} draws: the "
                                    "evidence is too unlikely; use method='lw'")
            batch = max(n - found, 1000)
            d = draw(program, terms, free, batch, gen)
            match = np.ones(batch, bool)
            for name, idx in bound.discrete.items():
                if name not in given:
                    match &= d.values[name][0] == int(np.asarray(idx).reshape(-1)[0])
            for name in drawn:
                kept[name].append(d.values[name][0][match])
            found += int(match.sum())
            tried += batch
        values = {name: np.concatenate(kept[name])[:n] for name in drawn}
    else:
        d = draw(program, terms, bound, n, gen)
        values = {name: d.values[name][0] for name in drawn}
        if method == "lw":
            weights = d.weights[0]
            if not np.any(weights > 0):
                raise QuestionError("every draw has weight zero: the evidence has probability "
                                    "zero under the program")
    columns: dict[str, Any] = {}
    for name in drawn:
        var = variables[name]
        if isinstance(var, Discrete):
            typed = np.asarray(var.values if var.kind == "range" else var.states, dtype=object)
            columns[name] = typed[values[name]]
        else:
            columns[name] = np.asarray(values[name], float)
    if weights is not None:
        if "weight" in columns:
            raise QuestionError("a variable is named 'weight', the column of the draws' weights")
        columns["weight"] = weights
    return pd.DataFrame(columns)
