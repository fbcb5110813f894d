"""Learning a program's parameters from data: maximum likelihood (or the posterior mean under
Dirichlet pseudo-counts), and EM over the whole program where discrete values are missing or a
variable is hidden (no column), or a mixture is learned.

Rows are grouped by which discrete variables they miss. For each group the E-step evaluates
every term of the decomposition on the group's rows over the joint states of the missing
variables, so the posterior of each learned term's family, and each row's likelihood, are
exact. Rows that miss nothing the fit needs are not enumerated: each table's family is
counted once (np.bincount of its configurations' mixed-radix codes), its statistics are those
counts and its share of the log-likelihood is their dot product with its log values. The
M-step hands the expected statistics to each form's estimator. Statistics add up over data
sets: a fit continues from a fitted file's statistics with more data.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from bayesprog.errors import QuestionError
from bayesprog.forms import FormulaParam, InputRef, ParamValue, TermContext, is_binned
from bayesprog.forms.estimators import (
    Estimator,
    FitProblem,
    Params,
    Stats,
    parent_cards,
)
from bayesprog.inference.binding import Bound
from bayesprog.inference.factors import observed_part
from bayesprog.inference.formulas import formula_value, log_factor
from bayesprog.inference.relevance import Family
from bayesprog.learning.csv_rows import BadRow
from bayesprog.learning.data import Data, DataError, load_data
from bayesprog.model import LearnOptions, Term
from bayesprog.model.records import FitRecord
from bayesprog.vocabulary.variables import Continuous, Discrete, Variable

#: Most entries of one chunk's joint table over the missing variables (rows x joint states).
JOINT_LIMIT = 1 << 23


@dataclass
class Estimate:
    """Learned parameters by term label, the fit's record for the fitted file, and the bad rows
    of the data set aside (``on_bad_lines``)."""

    params: dict[str, Params]
    record: FitRecord
    log_likelihood: float
    iterations: int
    converged: bool
    set_aside: list[BadRow] = field(default_factory=list)
    #: why EM stopped (converged, or the iterations allowed were made, with the last change)
    stopped: str = ""


@dataclass
class _Learned:
    term: Term
    estimator: Estimator
    options: LearnOptions
    prior: Stats | None


def _missing_patterns(columns: Sequence[np.ndarray], rows: int
                      ) -> list[tuple[np.ndarray, np.ndarray]]:
    """The patterns of missing values among ``columns`` (coded, -1 where missing), each with its
    rows, in np.unique's order of the patterns; only the columns missing in some rows but not
    all tell the groups apart."""
    missing = [c < 0 for c in columns]
    constant = np.array([bool(m[0]) if rows else False for m in missing], dtype=bool)
    partial = [j for j, m in enumerate(missing) if m.any() and not m.all()]
    if not partial:
        return [(constant, np.arange(rows))]
    packed = np.packbits(np.stack([missing[j] for j in partial], axis=1), axis=1)
    patterns, inverse = np.unique(packed, axis=0, return_inverse=True)
    inverse = inverse.ravel()
    out = []
    for g, bits in enumerate(patterns):
        pattern = constant.copy()
        pattern[partial] = np.unpackbits(bits, count=len(partial)).astype(bool)
        out.append((pattern, np.nonzero(inverse == g)[0]))
    return out


@dataclass
class Stop:
    """Whether EM has converged, and why it stopped or goes on (a sentence)."""

    converged: bool
    why: str


@dataclass
class Run:
    """What EM gives: the parameters, the log-likelihood at them, the iterations made, why it
    stopped, and the statistics the parameters were estimated from."""

    params: dict[str, Params]
    log_likelihood: float
    iterations: int
    stop: Stop
    statistics: dict[str, Stats]


#: a change of the objective this small, relative, is rounding: the iterations have stopped
#: moving it
ROUNDING = 1e-13


def stopping(objectives: Sequence[float], rows: int, tol: float) -> Stop:
    """Whether EM has converged, from its objectives (the log-likelihood, plus the log-prior
    with pseudo-counts) at each iteration so far: when the objective per row is estimated
    within ``tol`` of its limit, or no longer changes beyond rounding.

    EM converges linearly near an optimum: each gain is about ``r`` times the one before, so
    the objective's limit is ``l_k + d_k r / (1 - r)`` (Aitken's acceleration, as mclust and
    McNicholas et al. 2010 stop EM), with ``d_k = l_k - l_k-1`` and ``r = d_k / d_k-1``. A
    small gain alone does not stop it: on a plateau, where the gains still grow (``r >= 1``),
    the optimum may be far.

    >>> limit = -1.0
    >>> slow = [limit - 0.9**k for k in range(1, 200)]  # a gap that shrinks tenfold slowly
    >>> stopping(slow[:50], 1, 1e-8).converged, stopping(slow, 1, 1e-8).converged
    (False, True)
    """
    if len(objectives) < 2:
        return Stop(False, "fewer than two iterations")
    last, gain = objectives[-1], objectives[-1] - objectives[-2]
    if abs(gain) <= ROUNDING * max(abs(last), 1.0):
        return Stop(True, f"the log-likelihood no longer changes (by {gain / rows:.3g} per row)")
    change = f"the last iteration changed the log-likelihood by {gain / rows:.3g} per row"
    if len(objectives) < 3 or gain < 0:
        return Stop(False, change)
    before = objectives[-2] - objectives[-3]
    rate = gain / before if before > 0 else np.inf
    if not 0 <= rate < 1:
        return Stop(False, f"{change}, and its gains still grow")
    distance = gain * rate / (1 - rate) / rows
    if distance <= tol:
        return Stop(True, f"{change}; estimated {distance:.3g} per row from its limit")
    return Stop(False, f"{change}; estimated {distance:.3g} per row from its limit "
                       f"(tol {tol:g})")


class _Group:
    """Rows that miss the same discrete variables."""

    def __init__(self, rows: np.ndarray, hidden: tuple[str, ...], cards: tuple[int, ...],
                 terms: list[Term]):
        self.rows, self.hidden, self.cards, self.terms = rows, hidden, cards, terms


def fit_terms(variables: Mapping[str, Variable], terms: Sequence[Term],
              learned: Sequence[FitRecord], source: Any, *, freeze: Sequence[str] = (),
              max_iter: int = 10_000, tol: float = 1e-8,
              columns: Mapping[str, str] | None = None, on_bad_lines: str = "error",
              other_columns: str = "refuse"
              ) -> Estimate:
    """Learn the parameters of ``terms`` (those not frozen) from the data at ``source``
    (``columns``: the variable each differently named column holds; ``on_bad_lines``: what
    is done with a bad row, see :func:`~bayesprog.learning.data.load_data`)."""
    if not (np.isfinite(tol) and tol >= 0):
        raise DataError(f"tol: expected a number >= 0, found {tol}")
    if max_iter < 1:
        raise DataError(f"max_iter: expected at least 1, found {max_iter}")
    data = load_data(source, variables, columns, on_bad_lines=on_bad_lines,
                     other_columns=other_columns)
    seen = [r for r in learned if r.sha256 == data.sha256]
    if seen:
        raise DataError(f"{data.source}: these data (SHA-256 {data.sha256[:12]}...) were already "
                        f"learned into this program (its learned: record of {seen[0].data}); "
                        "learning them again would count every row twice")
    model = [t for t in terms if not t.soft]
    todo = _learnable(model, freeze, learned)
    if not todo:
        raise DataError("nothing to learn: every term is frozen or has no parameters")
    present = np.zeros(data.rows, bool)
    for column in list(data.discrete.values()):
        present |= column >= 0
    for values in data.continuous.values():
        present |= ~np.isnan(values)
    used = np.nonzero(present)[0]
    if len(used) == 0:
        aside = f" ({len(data.set_aside)} bad rows set aside)" if data.set_aside else ""
        raise DataError(f"{data.source}: no row has a value in a column of the program{aside}")
    _check_given(variables, model, data, used, columns or {})
    em = _Em(variables, model, todo, data, used)
    params = {t.label: {k: v for k, v in t.params.items() if isinstance(v, ParamValue)}
              for t in model}  # runtime inputs were refused above
    choices = []
    for item in todo:
        label = item.term.label
        candidates = item.options.components
        if item.estimator.mixture and item.prior is not None and "count" in item.prior:
            candidates = (item.prior["count"].shape[-1],)  # continue with the fitted mixture
        if not candidates:
            continue
        if len(candidates) == 1:
            params[label] = em.start(item, candidates[0], params[label])
            continue
        best, failed = None, []
        for k in candidates:  # the number of components with the lowest BIC, others as now
            trial = dict(params)
            try:
                trial[label] = em.start(item, k, params[label])
                result = em.run(trial, max_iter, tol)
            except DataError as exc:
                failed.append(f"{k} ({exc})")
                continue
            bic = -2 * result.log_likelihood + em.free(result.params) * np.log(len(used))
            if best is None or bic < best[0]:
                best = (bic, k, trial[label])
        if best is None:
            raise DataError(f"term {label}: no number of components could be fitted: "
                            + "; ".join(failed))
        params[label] = best[2]
        skipped = f", {len(failed)} candidate(s) could not be fitted" if failed else ""
        choices.append(f"{label}: {best[1]} components by BIC ({best[0]:.6g}){skipped}")
    run = em.run(params, max_iter, tol)
    final, ll, iterations, stats = run.params, run.log_likelihood, run.iterations, run.statistics
    iterative = em.iterative
    method = "EM" if iterative else "maximum likelihood"
    if any(i.options.pseudo_counts is not None for i in todo):
        method += ", Dirichlet pseudo-counts"
    if choices:
        method += "; " + "; ".join(choices)
    if learned and any(i.prior is not None for i in todo):
        method += "; continued from the statistics of the previous fit"
    # the rows behind the values: these, and those of the fits whose statistics it continues
    supporting = int(len(used)) + sum(r.rows_supporting or r.rows_used for r in learned
                                      if any(i.prior is not None and i.term.label in r.terms
                                             for i in todo))
    record = FitRecord(
        data=Path(data.source).name if data.source[0] != "<" else data.source,
        sha256=data.sha256, rows=data.rows, rows_used=int(len(used)),
        log_likelihood=float(ll), method=method, iterations=iterations,
        rows_supporting=supporting,
        rows_set_aside=None if data.set_aside is None else len(data.set_aside),
        columns=dict(columns or {}), terms=[i.term.label for i in todo],
        statistics={i.term.label: {k: v.tolist() for k, v in stats[i.term.label].items()}
                    for i in todo},
        ranges=_ranges(variables, [i.term for i in todo], data, used))
    out = {i.term.label: {k: v for k, v in final[i.term.label].items()
                          if k in i.estimator.learned} for i in todo}
    return Estimate(out, record, float(ll), iterations, run.stop.converged,
                    list(data.set_aside or ()), run.stop.why)


def _check_given(variables: Mapping[str, Variable], model: Sequence[Term], data: Any,
                 used: np.ndarray, columns: Mapping[str, str]) -> None:
    """A variable without a term (the program is conditioned on it) is read as evidence,
    never learned: every row used gives its value, as every question does."""
    defined = {t.child.name for t in model}
    column_of = {variable: column for column, variable in columns.items()}
    for name, var in variables.items():
        if name in defined:
            continue
        why = (f"{name} has no term in the decomposition (the program is conditioned on it), "
               "so every row gives its value, as every question does")
        coded = data.discrete.get(name) if var.is_discrete else data.continuous.get(name)
        if coded is None:
            raise DataError(f"{data.source}: no column {column_of.get(name, name)!r}: {why}")
        missing = coded[used] < 0 if var.is_discrete else np.isnan(coded[used])
        if missing.any():
            row = int(used[np.argmax(missing)])
            raise DataError(f"{data.where(row, column_of.get(name, name))}: no value, but "
                            f"{why} (rows without it: {int(missing.sum())})")


def _ranges(variables: Mapping[str, Variable], terms: Sequence[Term], data: Any,
            used: np.ndarray) -> dict[str, dict[str, list[float]]]:
    """The least and greatest value of each real child of ``terms`` in the rows ``used``:
    over every row (``"*"``) and per state of each of its discrete parents observed in the
    data (``"M=steel"``), skipping missing values."""
    out: dict[str, dict[str, list[float]]] = {}
    for term in terms:
        name = term.child.name
        if name not in data.continuous or name in out:
            continue
        values = np.asarray(data.continuous[name], float)[used]
        seen = ~np.isnan(values)
        if not seen.any():
            continue
        spans = {"*": [float(values[seen].min()), float(values[seen].max())]}
        for parent in term.parents:
            codes = data.discrete.get(parent.name)
            states = getattr(variables[parent.name], "states", None)
            if codes is None or states is None:
                continue
            codes = np.asarray(codes)[used]
            for code, state in enumerate(states):
                rows = seen & (codes == code)
                if rows.any():
                    spans[f"{parent.name}={state}"] = [float(values[rows].min()),
                                                       float(values[rows].max())]
        out[name] = spans
    return out


def _previous(label: str, learned: Sequence[FitRecord]) -> Stats | None:
    """The statistics of ``label`` in the latest fit that learned it, as arrays."""
    for record in reversed(learned):
        if label in record.statistics:
            stats = {}
            for key, value in record.statistics[label].items():
                try:
                    stats[key] = np.asarray(value, dtype=float)
                except (TypeError, ValueError):
                    raise DataError(f"cannot continue the fit of {label}: its statistic {key!r} "
                                    f"in the learned: record of {record.data} is not an array "
                                    "of numbers") from None
            return stats
    return None


def _learnable(model: Sequence[Term], freeze: Sequence[str],
               learned: Sequence[FitRecord]) -> list[_Learned]:
    out = []
    for term in model:
        if term.learn is None or term.label in freeze or not term.form.params:
            continue
        if term.form.deterministic and term.form.scale_param is None and len(term.params) == 1:
            continue  # the child is a function of its parents: nothing to learn
        formulas = [k for k, v in term.params.items() if isinstance(v, FormulaParam)]
        if formulas:
            raise DataError(f"term {term.label}: its {formulas[0]!r} is a formula of its parents, "
                            "whose coefficients are not learned from data: freeze the term "
                            "(learn: false, or --freeze)")
        if is_binned(term.child):
            raise DataError(f"term {term.label}: {term.child.name} is discretised, and the "
                            "parameters of its density are not learned from its bins: freeze "
                            "the term (learn: false, or --freeze)")
        estimator = term.form.estimator(term.child)
        if estimator is None:
            raise DataError(f"term {term.label} (form {term.form.name}) cannot be learned from "
                            "data: freeze it (learn: false) or with --freeze")
        out.append(_Learned(term, estimator, term.learn, _previous(term.label, learned)))
    return out


class _Em:
    def __init__(self, variables: Mapping[str, Variable], model: Sequence[Term],
                 todo: list[_Learned], data: Data, used: np.ndarray):
        everything = len(used) == data.rows  # complete rows are not copied
        self.variables, self.model, self.todo, self.data, self.used = (
            variables, model, todo, data if everything else data.take(used), used)
        discrete = [n for n, v in variables.items() if isinstance(v, Discrete)]
        rows = self.data.rows
        self.codes = {n: self.data.discrete.get(n, np.full(rows, -1)) for n in discrete}
        for term in model:
            parents = {p.name for p in term.parents}
            inputs = [n for n, v in term.params.items() if isinstance(v, InputRef) or (
                isinstance(v, FormulaParam) and any(x not in parents for x in v.names))]
            if inputs:
                raise DataError(f"term {term.label} takes its {inputs[0]!r} from a runtime "
                                "input, so the program cannot be evaluated on data rows")
        # the decomposition's DAG: which missing variables a row's likelihood depends on
        self.graph = Family()
        for term in model:
            self.graph.parents.setdefault(term.child.name, []).extend(
                p.name for p in term.parents)
        observed_continuous = set(self.data.continuous)
        self.groups = []
        for pattern, rows_of in _missing_patterns([self.codes[n] for n in discrete], rows):
            missing = {n for n, miss in zip(discrete, pattern, strict=True) if miss}
            seen = {n for n in discrete if n not in missing} | {
                n for n in observed_continuous
                if np.any(~np.isnan(self.data.continuous[n][rows_of]))}
            needed = self._needed(seen)
            hidden = tuple(n for n in discrete if n in missing and n in needed)
            cards = tuple(variables[n].card for n in hidden)  # type: ignore[union-attr]
            joint = math.prod(cards)
            if joint > JOINT_LIMIT:
                raise DataError(
                    f"{data.source}: rows that miss {', '.join(hidden)} leave {joint:,} joint "
                    f"states to sum over (more than {JOINT_LIMIT:,}); give values for some of "
                    "them, or freeze the terms that tie them to the data")
            terms = [t for t in model if t.child.name in needed or t.child.name in seen]
            self.groups.append(_Group(rows_of, hidden, cards, terms))
        learns_mixture = any(i.estimator.mixture for i in todo)
        self.iterative = learns_mixture or any(g.hidden for g in self.groups)
        #: counts of a family's configurations on a chunk of a group's rows, by (group,
        #: first row, family): what the data say, whatever the parameters, so counted once
        self._counts: dict[tuple[int, int, tuple[str, ...]], np.ndarray] = {}

    def _needed(self, seen: set[str]) -> set[str]:
        """The variables a row's likelihood and the learned terms' posteriors depend on: the
        observed ones, the learned terms' families, and their ancestors. A missing variable
        outside them sums out of normalised terms to one, so it is not enumerated."""
        roots = set(seen)
        for item in self.todo:
            roots |= {item.term.child.name} | {p.name for p in item.term.parents}
        for term in self.model:  # potentials do not sum to one: keep their variables
            if not term.form.is_normalized(term.child):
                roots |= {term.child.name} | {p.name for p in term.parents}
        return self.graph.ancestors(roots)

    def start(self, item: _Learned, k: int, params: Params) -> Params:
        """Starting values of a mixture with ``k`` components: the file's when it has ``k``."""
        if item.estimator.components(item.term, params) == k and item.estimator.mixture \
                and all(isinstance(params.get(n), ParamValue) for n in item.estimator.learned):
            return params
        x = self.data.continuous.get(item.term.child.name)
        if x is None:
            raise DataError(f"{self.data.source}: no column {item.term.child.name!r} to learn "
                            f"{item.term.label} from")
        rows = int(np.sum(~np.isnan(x)))
        if k > rows:
            raise DataError(f"{self.data.source}: term {item.term.label}: {k} components for "
                            f"{rows} values; expected at most one component per value")
        weights = self._known_weights(item.term, x)
        try:
            return item.estimator.initial(item.term, np.nan_to_num(x), weights, k, params)
        except FitProblem as exc:
            raise DataError(f"{self.data.source}: term {item.term.label}: {exc}") from None

    def _known_weights(self, term: Term, x: np.ndarray) -> np.ndarray:
        """Rows' weights per parent configuration where the parents are observed (uniform
        over the configurations where they are not): for starting values only."""
        cards = parent_cards(term)
        w = np.ones((len(x),) + cards)
        for axis, parent in enumerate(p for p in term.parents if p.is_discrete):
            code = self.codes[parent.name]
            onehot = np.ones((len(x), parent.card)) / parent.card  # type: ignore[union-attr]
            onehot[code >= 0] = np.eye(parent.card)[code[code >= 0]]  # type: ignore[union-attr]
            shape = [len(x)] + [1] * len(cards)
            shape[axis + 1] = parent.card  # type: ignore[union-attr]
            w = w * onehot.reshape(shape)
        w[np.isnan(x)] = 0
        return w

    def free(self, params: dict[str, Params]) -> int:
        return sum(i.estimator.free_parameters(i.term, params[i.term.label], i.options)
                   for i in self.todo)

    def run(self, params: dict[str, Params], max_iter: int, tol: float) -> Run:
        """EM from ``params`` (one M-step when nothing is missing and no mixture is learned),
        until the objective per row is within ``tol`` of its limit (:func:`stopping`) or
        ``max_iter`` iterations. The parameters returned are the last M-step's, and the
        statistics those it estimated them from (so that the record's statistics give the
        values written); the log-likelihood is taken at these parameters."""
        objectives: list[float] = []
        stop: Stop = Stop(not self.iterative, "one pass over complete rows")
        iterations = 0
        bar = None
        if self.iterative and sys.stderr.isatty():  # tqdm imported only to be shown
            from tqdm import tqdm

            bar = tqdm(total=max_iter, desc="EM", unit="iteration", leave=False)
        rows = max(len(self.used), 1)
        for iterations in range(1, max_iter + 1):  # noqa: B007 - the count is returned
            if bar is not None:
                bar.update(1)
            # one pass needs no starting values: rows are not checked against them, nor its
            # log-likelihood (the one at the fitted values is taken below)
            ll, stats = self.e_step(params, strict=self.iterative)
            if self.iterative:
                objectives.append(ll + self.log_prior(params))
            params = self.m_step(params, stats)
            if not self.iterative:
                break
            stop = stopping(objectives, rows, tol)
            if stop.converged:
                break
        if bar is not None:
            bar.close()
        if not self.iterative:  # complete rows: the statistics do not depend on the values
            ll, stats = self.e_step(params)
        else:
            ll, _ = self.e_step(params)
            if not stop.converged:
                stop = Stop(False, f"the {max_iter} iterations allowed were made (max_iter): "
                                   f"{stop.why}")
        total = {i.term.label: self._merged(i, stats[i.term.label]) for i in self.todo}
        return Run(params, ll, iterations, stop, total)

    def log_prior(self, params: dict[str, Params]) -> float:
        return sum(i.estimator.log_prior(i.term, params[i.term.label], i.options)
                   for i in self.todo)

    def _merged(self, item: _Learned, stats: Stats) -> Stats:
        if item.prior is None:
            return stats
        problem = item.estimator.check_statistics(item.prior, stats)
        if problem:
            raise DataError(f"cannot continue the fit of {item.term.label}: in the previous "
                            f"fit's statistics, {problem}")
        return item.estimator.merge(item.prior, stats)

    def m_step(self, params: dict[str, Params], stats: dict[str, Stats]) -> dict[str, Params]:
        out = dict(params)
        for item in self.todo:
            label = item.term.label
            try:
                new = item.estimator.estimate(item.term, self._merged(item, stats[label]),
                                              item.options, params[label])
            except FitProblem as exc:
                raise DataError(f"{self.data.source}: term {label}: {exc}") from None
            out[label] = {**params[label], **new}
        return out

    # the E-step ---------------------------------------------------------------------------------
    def e_step(self, params: dict[str, Params], strict: bool = True
               ) -> tuple[float, dict[str, Stats]]:
        """(log-likelihood of the rows at ``params``, each learned term's statistics);
        ``strict`` False for one pass over rows that need no inference: each row counts for
        what it shows, checked against no parameters, and the log-likelihood is not taken
        (0)."""
        total = 0.0
        stats: dict[str, Stats] = {}
        for g, group in enumerate(self.groups):
            size = max(1, math.prod(group.cards), self._row_width(params, bool(group.hidden)))
            step = max(1, JOINT_LIMIT // size)
            for start in range(0, len(group.rows), step):
                rows = group.rows[start:start + step]
                total += self._chunk(rows, group, params, stats, strict, (g, start))
        return total, stats

    def _row_width(self, params: dict[str, Params], hidden: bool = True) -> int:
        """The most entries one row takes in a term's table (parent states x components); where
        the rows miss nothing (not ``hidden``), only the tables that differ from row to row
        count."""
        widest = 1
        for term in self.model:
            if not hidden and term.child.is_discrete and not any(
                    isinstance(v, FormulaParam) for v in term.params.values()):
                continue  # one table for every row, its counts taken by np.bincount
            width = math.prod(v.card for v in term.parents if isinstance(v, Discrete))
            estimator = term.form.estimator(term.child)
            if estimator is not None:
                width *= estimator.components(term, params[term.label])
            widest = max(widest, width)
        return widest

    def _chunk(self, rows: np.ndarray, group: _Group, params: dict[str, Params],
               stats: dict[str, Stats], strict: bool = True,
               key: tuple[int, int] | None = None) -> float:
        if not group.hidden and key is not None:
            total = self._complete_chunk(rows, group, params, stats, key, likelihood=strict)
            if total is not None:
                return total
        n, hidden, cards = len(rows), group.hidden, group.cards
        if not (strict or hidden):  # nothing to infer: each row counts for what it shows
            post = np.ones((n,) + cards)
            for item in self.todo:
                self._accumulate(item, rows, post, hidden, cards, params, stats)
            return 0.0
        joint = np.zeros((n,) + cards)
        for term in group.terms:
            joint = joint + self._gather(self._log_table(term, rows, params[term.label]),
                                         term, rows, hidden, cards)
        axes = tuple(range(1, joint.ndim))
        top = joint.max(axis=axes, keepdims=True) if axes else joint
        with np.errstate(divide="ignore", invalid="ignore"):
            row_ll = (np.log(np.exp(joint - top).sum(axis=axes, keepdims=True)) + top) if axes \
                else joint
        impossible = ~np.isfinite(row_ll.reshape(n))
        if np.any(impossible):
            row = int(self.used[rows[np.argmax(impossible)]])
            raise DataError(f"{self.data.place(row)} has probability zero under "
                            "the program's current parameters (a state a table rules out, or a "
                            "value a density gives zero); start EM from values without zeros, "
                            "or give pseudo_counts")
        post = np.exp(joint - row_ll)
        for item in self.todo:
            self._accumulate(item, rows, post, hidden, cards, params, stats)
        return float(row_ll.sum())

    def _complete_chunk(self, rows: np.ndarray, group: _Group, params: dict[str, Params],
                        stats: dict[str, Stats], key: tuple[int, int],
                        likelihood: bool = True) -> float | None:
        """Rows that miss no variable the fit needs: a table the same for every row adds its
        log values times the counts of its cells, and a learned table's statistics are its
        family's counts (a row's posterior is the row itself). None, with nothing added, when
        a row has probability zero: the general E-step says which. ``likelihood`` False: the
        statistics only (0 added)."""
        total = 0.0
        per_row = None
        for term in group.terms if likelihood else ():
            table = self._log_table(term, rows, params[term.label])
            if table.shape[0] == 1:
                counts = self._family_counts(key, term.axes, rows)
                cells = counts > 0
                logs = table[0][cells]
                if not np.all(np.isfinite(logs)):
                    return None
                total += float(counts[cells] @ logs)
            else:
                values = self._gather(table, term, rows, (), ())
                per_row = values if per_row is None else per_row + values
        if per_row is not None:
            if not np.all(np.isfinite(per_row)):
                return None
            total += float(per_row.sum())
        ones = np.ones(len(rows))
        for item in self.todo:
            term = item.term
            if not term.child.is_discrete:
                self._accumulate(item, rows, ones, (), (), params, stats)
                continue
            new = item.estimator.counts(term, self._family_counts(key, term.axes, rows))
            old = stats.get(term.label)
            stats[term.label] = new if old is None else item.estimator.merge(old, new)
        return total

    def _family_counts(self, key: tuple[int, int], axes: tuple[str, ...],
                       rows: np.ndarray) -> np.ndarray:
        """How many of ``rows`` (observed on ``axes``) show each configuration of ``axes``:
        np.bincount of the configurations' mixed-radix codes, counted once per chunk."""
        counts = self._counts.get((*key, axes))
        if counts is None:
            cards = [self.variables[a].card for a in axes]  # type: ignore[union-attr]
            every = len(rows) == self.data.rows  # the rows in order: no copy of the columns
            code = np.zeros(len(rows), dtype=np.int64)
            for a, card in zip(axes, cards, strict=True):
                code *= card
                code += self.codes[a] if every else self.codes[a][rows]
            counts = np.bincount(code, minlength=math.prod(cards)).reshape(cards).astype(float)
            self._counts[(*key, axes)] = counts
        return counts

    def _log_table(self, term: Term, rows: np.ndarray, params: Params) -> np.ndarray:
        """The term's log values on these rows: ``[rows or 1, *cards of term.axes]`` (0 where a
        continuous child has no value: its density integrates to one)."""
        value = missing = None
        if isinstance(term.child, Continuous):
            column = self.data.continuous.get(term.child.name)
            if column is None:
                return np.zeros((1,) * (1 + len(term.axes)))
            # a missing value is marginalised, as the engine does for a missing field value
            try:
                value, missing = observed_part(term, ParamValue((), column[rows], batched=True))
            except QuestionError as exc:
                raise DataError(f"{self.data.source}: {exc}") from None
        axes = term.axes
        cards = tuple(self.variables[a].card for a in axes)  # type: ignore[union-attr]
        formulas = {k: self._formula_on_rows(term, k, v, rows)
                    for k, v in term.params.items() if isinstance(v, FormulaParam)}
        ctx = TermContext(term.child, term.parents, axes, cards,
                          {**params, **formulas}, value, self.variables, term.extra)
        with np.errstate(divide="ignore", invalid="ignore"):
            log = log_factor(term.form, ctx)
        log = np.broadcast_to(log, np.broadcast_shapes(log.shape, (log.shape[0],) + cards))
        if missing is not None:
            log = np.where(missing.aligned(axes, 0), 0.0, log)
        return log

    def _formula_on_rows(self, term: Term, key: str, param: FormulaParam,
                         rows: np.ndarray) -> ParamValue:
        """A frozen term's formula evaluated on the data rows: its real parents need a value
        in every row (a missing one would have to be integrated out)."""
        continuous = {}
        for name in param.names:
            if isinstance(self.variables[name], Discrete):
                continue
            column = self.data.continuous.get(name)
            if column is None or np.isnan(column[rows]).any():
                raise DataError(f"{self.data.source}: term {term.label} uses {name} in its "
                                f"{key!r}, and {'no column' if column is None else 'some rows'}"
                                f" of the data {'gives' if column is None else 'miss'} it: "
                                "a real parent must be observed in every row to fit a program "
                                "that uses it")
            continuous[name] = ParamValue((), column[rows], batched=True)
        bound = Bound((len(rows),), continuous=continuous)
        return formula_value(self.variables, param, bound, f"term {term.label}")

    def _index(self, axes: Sequence[str], rows: np.ndarray, hidden: tuple[str, ...],
               cards: tuple[int, ...]) -> list[np.ndarray]:
        """Index arrays, one per axis, broadcasting to ``[rows, *cards of hidden]``."""
        m = len(hidden)
        out = []
        for a in axes:
            if a in hidden:
                j = hidden.index(a)
                shape = [1] * (m + 1)
                shape[j + 1] = cards[j]
                out.append(np.arange(cards[j]).reshape(shape))
            else:
                out.append(self.codes[a][rows].reshape((len(rows),) + (1,) * m))
        return out

    def _gather(self, table: np.ndarray, term: Term, rows: np.ndarray,
                hidden: tuple[str, ...], cards: tuple[int, ...]) -> np.ndarray:
        m = len(hidden)
        batch = (np.arange(len(rows)) if table.shape[0] > 1 else np.zeros(len(rows), int))
        index = [batch.reshape((len(rows),) + (1,) * m)] + self._index(term.axes, rows, hidden, cards)
        return table[tuple(index)]

    def _accumulate(self, item: _Learned, rows: np.ndarray, post: np.ndarray,
                    hidden: tuple[str, ...], cards: tuple[int, ...], params: dict[str, Params],
                    stats: dict[str, Stats]) -> None:
        term = item.term
        label = term.label
        family = term.axes if term.child.is_discrete else tuple(
            p.name for p in term.parents if p.is_discrete)
        drop = tuple(j + 1 for j, h in enumerate(hidden) if h not in family)
        reduced = post.sum(axis=drop, keepdims=True) if drop else post
        index = self._index(family, rows, hidden, cards)
        if term.child.is_discrete:
            counts = np.zeros(tuple(self.variables[a].card for a in family))  # type: ignore[union-attr]
            shape = np.broadcast_shapes(reduced.shape, *(i.shape for i in index))
            np.add.at(counts, tuple(np.broadcast_to(i, shape) for i in index),
                      np.broadcast_to(reduced, shape))
            new = item.estimator.counts(term, counts)
        else:
            column = self.data.continuous.get(term.child.name)
            if column is None:
                raise DataError(f"{self.data.source}: no column {term.child.name!r} to learn "
                                f"{label} from (freeze the term, or add the column)")
            x = column[rows]
            n = len(rows)
            weights = np.zeros((n,) + parent_cards(term))
            lead = np.arange(n).reshape((n,) + (1,) * len(hidden))
            shape = np.broadcast_shapes(reduced.shape, lead.shape, *(i.shape for i in index))
            np.add.at(weights, tuple(np.broadcast_to(i, shape) for i in [lead] + index),
                      np.broadcast_to(reduced, shape))
            keep = ~np.isnan(x)
            try:
                new = item.estimator.statistics(term, x[keep], weights[keep], params[label])
            except FitProblem as exc:
                where = ""
                if exc.row is not None:
                    row = int(self.used[rows[np.nonzero(keep)[0][exc.row]]])
                    where = self.data.where(row, term.child.name) + ": "
                raise DataError(f"{where or self.data.source + ': '}term {label}: {exc}") from None
        old = stats.get(label)
        stats[label] = new if old is None else item.estimator.merge(old, new)

