"""Approximate, on a grid: every unknown real variable answered on bins, with an error estimate.

Each unknown real variable that matters is discretised as ``discretise: {bins: n}`` would (see
the language reference): ``n`` equal bins over its support, each bin's probability the
integral of its term's density over it (a CDF difference), formulas that name it evaluated at
the bin's midpoint. The discretised program is discrete and is answered exactly by
contraction. The question is answered twice, with ``n`` and ``2n`` bins; the answer is the
finer one and its ``error`` the change between the two, an estimate of the discretisation error
(for a smooth density the error of a midpoint grid falls as ``1 / n^2``, so the estimate is,
if anything, pessimistic for the finer answer).

The cost model chooses it by itself only when no exact method applies (a program that is not
linear-Gaussian); ``bins`` (option) sets ``n``, 128 by default.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from bayesprog.forms import FormulaParam
from bayesprog.inference.answers import Posterior
from bayesprog.inference.contraction import contract_question
from bayesprog.inference.core import InferenceCache
from bayesprog.inference.density import QUANTILES, Density
from bayesprog.inference.methods.base import Cost, Method, register_method
from bayesprog.inference.plan import QuestionPlan
from bayesprog.model import InputDecl, Term
from bayesprog.vocabulary.formula import substitute
from bayesprog.vocabulary.variables import Continuous, Variable, binned_variable

#: Bins per unknown real variable of the coarser of the two answers.
DEFAULT_BINS = 128


@register_method
class GridMethod(Method):
    name = "grid"
    title = "on a grid"
    exact = False
    continuous = True
    fallback = True
    uncertainty = "bound"

    def describe(self, answer: Any) -> str:
        bins = ", ".join(f"{n} bins for {v}" for v, n in answer.resolution.items())
        fewer = ", ".join(str(n // 2) for n in answer.resolution.values())
        return (f"{self.title} of {bins}: +- an estimated bound of the discretisation error, the "
                f"change from {fewer} bins")

    def why_not(self, plan: QuestionPlan) -> str | None:
        if not plan.latent:
            return "no unknown real variable"
        replaced = {t.child.name for t in plan.terms if _substitutable(t)} - set(plan.searched)
        unbounded = [v for v in plan.latent if v not in replaced and not np.isfinite(
            plan.program.variables[v].width)]  # type: ignore[union-attr]
        if unbounded:
            return (f"{', '.join(unbounded)} {'has' if len(unbounded) == 1 else 'have'} an "
                    "unbounded support: declare a bounded one ([low, high]) to answer on a "
                    "grid, or discretise it in the file")
        return None

    def estimate(self, plan: QuestionPlan) -> Cost | None:
        if self.why_not(plan) is not None:
            return None
        fine = _derived_plan(plan, 2 * _bins(plan))
        operations, largest = fine.contraction_cost(fine.searched)
        size = float(plan.bound.size)
        return Cost(operations=1.5 * size * operations, memory=size * largest)

    def posterior(self, plan: QuestionPlan) -> Posterior | Density:
        n = _bins(plan)
        coarse = contract_question(_derived_plan(plan, n))
        fine = contract_question(_derived_plan(plan, 2 * n))
        if not plan.searched or plan.searched[0] not in plan.latent:
            fine.method = "grid"
            fine.error = np.abs(fine.probabilities - coarse.probabilities)
            fine.uncertainty = self.uncertainty
            fine.resolution = {v: 2 * n for v in plan.latent}
            return fine
        answers = [_density(plan, p, m) for p, m in ((coarse, n), (fine, 2 * n))]
        error: dict[str, dict[str, np.ndarray]] = {"mean": {}, "sd": {}, "map": {},
                                                   "quantiles": {}}
        for v in plan.searched:
            a, b = answers
            error["mean"][v] = np.abs(b.mean(v) - a.mean(v))
            error["sd"][v] = np.abs(b.sd(v) - a.sd(v))
            # a mode moves by up to a coarse bin between the two: that is its resolution
            error["map"][v] = np.maximum(np.abs(b.map(v) - a.map(v)),
                                         np.diff(a.edges[v]).max() / 2)  # type: ignore[index]
            q = np.array(QUANTILES)
            error["quantiles"][v] = np.abs(b.quantile(v, q) - a.quantile(v, q)).max(-1)
        result = answers[1]
        result.error = error
        result.uncertainty = self.uncertainty
        return result


def _bins(plan: QuestionPlan) -> int:
    n = plan.options.get("bins", DEFAULT_BINS)
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 2:
        from bayesprog.errors import QuestionError
        raise QuestionError(f"bins: expected an integer >= 2, found {n!r}")
    return int(n)


def _density(plan: QuestionPlan, posterior: Posterior, bins: int) -> Density:
    variables = plan.program.variables
    edges = {}
    for v in plan.searched:
        var = variables[v]
        assert isinstance(var, Continuous)
        edges[v] = np.linspace(var.low, var.high, bins + 1)
    rows = plan.bound.size
    return Density(str(plan.question.expression), plan.searched, plan.bound.batch_shape,
                   posterior.log_evidence.reshape(-1), ablated=plan.program.ablated,
                   method="grid", edges=edges,
                   masses=posterior.probabilities.reshape((rows,) + (bins,) * len(edges)),
                   resolution={v: bins for v in plan.searched})


@dataclass
class _Discretised:
    """A program with some real variables answered on bins (what inference needs of it)."""

    name: str
    variables: dict[str, Variable]
    inputs: dict[str, InputDecl]
    ablated: tuple[str, ...]
    inference_cache: InferenceCache
    terms: list[Term]
    original: Any

    @property
    def active_terms(self) -> list[Term]:
        return self.terms

    @property
    def conditioning(self) -> tuple[str, ...]:
        return self.original.conditioning

    def ancestors(self, name: str) -> set[str]:
        return self.original.ancestors(name)


def _derived_plan(plan: QuestionPlan, bins: int) -> QuestionPlan:
    program = plan.program
    latent = tuple(sorted(plan.latent))
    key = ("grid", latent, plan.searched, bins)
    derived = program.inference_cache.derived.get(key)
    if derived is None:
        variables = dict(program.variables)
        terms = list(program.active_terms)
        # a deterministic variable is replaced by its formula wherever it is used: exact,
        # where bins of it would add their own error
        for term in [t for t in terms if t.child.name in latent and _substitutable(t)
                     and t.child.name not in plan.searched]:
            terms = [_substituted(t, term, program) for t in terms if t is not term]
            latent = tuple(n for n in latent if n != term.child.name)
        for name in latent:
            var = variables[name]
            assert isinstance(var, Continuous)
            variables[name] = binned_variable(name, np.linspace(var.low, var.high, bins + 1),
                                              (var.low, var.high), var.description)
        terms = [dataclasses.replace(t, child=variables[t.child.name],
                                     parents=tuple(variables[p.name] for p in t.parents))
                 for t in terms]
        derived = _Discretised(program.name, variables, program.inputs, program.ablated,
                               InferenceCache(), terms, program)
        program.inference_cache.derived[key] = derived
    return QuestionPlan(derived, plan.question, plan.bound, plan.options)


def _substitutable(term: Term) -> bool:
    """A deterministic term with one formula (not a table by discrete parents)."""
    if not term.form.deterministic or term.form.mean_param is None:
        return False
    value = term.params.get(term.form.mean_param)
    return not isinstance(value, FormulaParam) or not value.axes


def _substituted(term: Term, dirac: Term, program: Any) -> Term:
    """``term`` with the deterministic variable of ``dirac`` replaced by its formula."""
    name = dirac.child.name
    if name not in (p.name for p in term.parents):
        return term
    assert dirac.form.mean_param is not None
    value = dirac.params[dirac.form.mean_param]
    text = (str(value.formulas.flat[0]) if isinstance(value, FormulaParam)
            else f"{float(np.asarray(value.array)):r}")  # type: ignore[union-attr]
    params = dict(term.params)
    for key, param in term.params.items():
        if isinstance(param, FormulaParam) and name in param.names:
            table = np.empty(param.formulas.shape, dtype=object)
            for index in np.ndindex(*table.shape):
                table[index] = substitute(param.formulas.item(index), name, text)
            params[key] = FormulaParam(param.axes, table)
    parents = [p for p in term.parents if p.name != name]
    parents += [p for p in dirac.parents if p.name not in {q.name for q in parents}]
    return dataclasses.replace(term, params=params, parents=tuple(parents))
