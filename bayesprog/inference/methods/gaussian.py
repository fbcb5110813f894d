"""Exact, by Gaussian algebra: conditional linear-Gaussian programs.

Applies when every unknown real variable that matters, and every known one whose term names
an unknown one, has a ``normal`` term whose mean is affine in its real parents (``mean:
"2*X + 1"``, coefficients per state of discrete parents) or a ``dirac`` term with an affine
value, and no discrete variable has an unknown real parent. For each configuration ``k`` of
the unknown discrete variables those terms depend on, the real variables are jointly Gaussian:

    x = b_k + A_k x + e,  e ~ N(0, diag(s_k))   =>   x ~ N(M b_k, M diag(s_k) M^T),
    M = (I - A_k)^-1

(``A_k`` strictly lower-triangular in a topological order; ``s = 0`` for a dirac term).
Conditioning on the known real values gives each configuration's likelihood, which joins the
discrete factors as one more factor, and the searched variables' conditional Gaussian; the
answer is the mixture over configurations (one component when there are none).
"""

from __future__ import annotations

import numpy as np

from bayesprog.errors import QuestionError
from bayesprog.forms import FormulaParam, InputRef, ParamValue, available_forms, get_form
from bayesprog.inference.binding import Bound
from bayesprog.inference.contraction import contract_factors
from bayesprog.inference.core import Factor
from bayesprog.inference.density import Density
from bayesprog.inference.factors import _bound_param, question_factors, slice_factor
from bayesprog.inference.formulas import formula_value
from bayesprog.inference.methods.base import Cost, Method, answer, register_method
from bayesprog.inference.plan import QuestionPlan
from bayesprog.model import Term

_LOG_2PI = float(np.log(2 * np.pi))


@register_method
class GaussianMethod(Method):
    name = "gaussian"
    continuous = True

    def why_not(self, plan: QuestionPlan) -> str | None:
        return _block(plan)[1] if plan.latent else "no unknown real variable"

    def estimate(self, plan: QuestionPlan) -> Cost | None:
        if not plan.latent:
            return None
        block, why = _block(plan)
        if why is not None:
            return None
        configurations = float(np.prod([plan.card(a) for a in _mixing(plan, block)]))
        n = len(block)
        names = {t.child.name for t in block}
        output = (tuple(_mixing(plan, block)) if plan.searched and plan.searched[0] in names
                  else plan.searched)
        operations, largest = plan.contraction_cost(output)
        size = float(plan.bound.size)
        return Cost(operations=size * (operations + configurations * n**3),
                    memory=size * max(largest, configurations * n * n))

    def posterior(self, plan: QuestionPlan) -> Density | None:
        block, why = _block(plan)
        if why is not None:
            raise QuestionError(f"{plan.question.expression}: {why}")
        return gaussian_answer(plan, block)


def _block(plan: QuestionPlan) -> tuple[list[Term], str | None]:
    """The terms of the real variables solved together, in a topological order, or why the
    program is not conditional linear-Gaussian."""
    latent = set(plan.latent)
    chosen = [t for t in plan.terms if not t.child.is_discrete and (
        t.child.name in latent or any(p.name in latent for p in t.parents))]
    names = {t.child.name for t in chosen}
    for t in plan.terms:
        if t.child.name not in names and any(p.name in latent for p in t.parents):
            return [], (f"{t.label} has a discrete child of the unknown real "
                        f"{', '.join(p.name for p in t.parents if p.name in latent)}")
    for t in chosen:
        if t.form.mean_param is None:
            gaussian = " or ".join(n for n in available_forms()
                                   if getattr(get_form(n), "mean_param", None))
            return [], (f"{t.label} is a {t.form.name} term (expected {gaussian} for exact "
                        "Gaussian answers)")
        if getattr(t.child, "index", None) is not None:
            return [], f"{t.label}: {t.child.name} is a field"
        if t.form.deterministic and t.child.name in plan.bound.continuous:
            return [], (f"{t.child.name} is deterministic (form {t.form.name}): give evidence on its "
                        "parents, or on a noisy sensor of it, not on it")
        for key, param in t.params.items():
            if not isinstance(param, FormulaParam):
                continue
            real = [n for n in param.names if n in names]
            if key != t.form.mean_param and real:
                return [], f"{t.label}: its {key} depends on {', '.join(real)}"
            for formula in param.formulas.flat:
                if not formula.affine_in(names):
                    return [], (f"{t.label}: {key} \"{formula}\" is not affine in "
                                f"{', '.join(n for n in formula.names if n in names)}")
    order: list[Term] = []
    placed: set[str] = set()
    pending = list(chosen)
    while pending:  # the decomposition is acyclic: each pass places at least one term
        for t in list(pending):
            if all(p.name in placed or p.name not in names for p in t.parents):
                order.append(t)
                placed.add(t.child.name)
                pending.remove(t)
    return order, None


def _mixing(plan: QuestionPlan, block: list[Term]) -> list[str]:
    """The unknown discrete variables the Gaussian part depends on: one mixture component per
    configuration of them."""
    found: dict[str, None] = {}
    for t in block:
        for name in t.axes:
            if name not in plan.bound.discrete:
                found[name] = None
    return list(found)


def gaussian_answer(plan: QuestionPlan, block: list[Term]) -> Density:
    program, bound = plan.program, plan.bound
    names = [t.child.name for t in block]
    n = len(names)
    mixing = _mixing(plan, block)
    cards = [plan.card(a) for a in mixing]
    rows = bound.size

    def grid(value: ParamValue) -> np.ndarray:
        """``value`` over ``[rows or 1, configurations]``, the known discrete ones sliced."""
        f = slice_factor(Factor(value.axes, np.asarray(value.array, float), value.batched),
                         bound)
        arr = f.log if f.batched else f.log[np.newaxis]
        order = [f.axes.index(a) + 1 for a in mixing if a in f.axes]
        arr = arr.transpose([0] + order)
        shape = [arr.shape[0]] + [c if a in f.axes else 1 for a, c in zip(mixing, cards,
                                                                              strict=True)]
        return np.broadcast_to(arr.reshape(shape), [arr.shape[0]] + cards).reshape(
            arr.shape[0], -1)

    zeros = Bound(bound.batch_shape, bound.discrete, dict(bound.continuous), bound.inputs,
                  bound.soft)
    for name in names:
        zeros.continuous[name] = ParamValue((), np.zeros(()))
    k = int(np.prod(cards)) if cards else 1
    intercept = np.zeros((1, k, n))
    coefficient = np.zeros((1, k, n, n))
    variance = np.zeros((1, k, n))

    def put(target: np.ndarray, index: tuple, values: np.ndarray) -> np.ndarray:
        if values.shape[0] > target.shape[0]:
            target = np.repeat(target, values.shape[0], axis=0)
        target[(slice(None), slice(None)) + index] = values
        return target

    for i, t in enumerate(block):
        key = t.form.mean_param
        assert key is not None  # (checked by _block)
        param = t.params[key]
        if isinstance(param, FormulaParam):
            what = f"term {t.label}"
            base = formula_value(program.variables, param, zeros, what)
            intercept = put(intercept, (i,), grid(base))
            exact = all(f.affine() is not None for f in param.formulas.flat)
            for j, other in enumerate(names):
                if other not in param.names:
                    continue
                if exact:  # numbers only: the coefficients as written
                    coef = ParamValue(param.axes, np.vectorize(
                        lambda f, o=other: f.affine()[1].get(o, 0.0), otypes=[float])(
                            param.formulas))
                else:  # known names (inputs, observed parents) in a coefficient: per row
                    unit = Bound(zeros.batch_shape, zeros.discrete,
                                 {**zeros.continuous, other: ParamValue((), np.ones(()))},
                                 zeros.inputs, zeros.soft)
                    shifted = formula_value(program.variables, param, unit, what)
                    coef = ParamValue(base.axes, shifted.array - base.array, base.batched)
                coefficient = put(coefficient, (i, j), grid(coef))
        else:
            value = _bound_param(t, key, param, bound) if isinstance(param, InputRef) else param
            intercept = put(intercept, (i,), grid(value))
        scale = t.form.scale_param
        if scale is not None:
            sigma = t.params[scale]
            if isinstance(sigma, InputRef):
                sigma = _bound_param(t, scale, sigma, bound)
            elif isinstance(sigma, FormulaParam):
                sigma = formula_value(program.variables, sigma, bound, f"term {t.label}")
            s = grid(sigma)
            if np.any(~(s > 0)):
                raise QuestionError(f"term {t.label}: {scale} must be > 0, got "
                                    f"{float(s.min()):g}")
            variance = put(variance, (i,), s**2)
    # x = M (b + e): the joint Gaussian of the block for each configuration
    solve = np.linalg.inv(np.eye(n) - coefficient)  # [r, k, n, n]
    mean = np.einsum("rkij,rkj->rki", solve, intercept)
    cov = np.einsum("rkij,rkj,rklj->rkil", solve, variance, solve)
    known = [i for i, v in enumerate(names) if v in bound.continuous]
    unknown = [i for i, v in enumerate(names) if v not in bound.continuous]
    loglik = np.zeros((max(mean.shape[0], 1), k))
    if known:
        x = np.stack([np.broadcast_to(np.asarray(bound.continuous[names[i]].array, float),
                                      (rows,)) for i in known], axis=-1)  # [rows, o]
        s_oo = cov[..., known, :][..., :, known]
        s_lo = cov[..., unknown, :][..., :, known]
        try:
            chol = np.linalg.cholesky(s_oo)
        except np.linalg.LinAlgError:
            raise QuestionError(f"{plan.question.expression}: the known values "
                                f"{', '.join(names[i] for i in known)} are tied exactly "
                                "(a singular covariance)") from None
        resid = x[:, None, :] - mean[..., known]  # [rows, k, o]
        white = np.linalg.solve(chol, resid[..., None])[..., 0]
        logdet = 2 * np.log(np.diagonal(chol, axis1=-2, axis2=-1)).sum(-1)
        loglik = -0.5 * (white**2).sum(-1) - 0.5 * logdet - 0.5 * len(known) * _LOG_2PI
        gain = np.linalg.solve(s_oo, np.swapaxes(s_lo, -1, -2))  # [r, k, o, l]
        cond_mean = mean[..., unknown] + np.einsum("rkol,rko->rkl", gain, resid)
        cond_cov = cov[..., unknown, :][..., :, unknown] - np.einsum("rklo,rkom->rklm",
                                                                   s_lo, gain)
    else:
        cond_mean, cond_cov = mean[..., unknown], cov[..., unknown, :][..., :, unknown]
    rest = [t for t in plan.terms if t.child.name not in set(names)]
    factors = question_factors(program, rest, bound)
    loglik = np.broadcast_to(loglik, (rows, k))
    factors.append(Factor(tuple(mixing), loglik.reshape([rows] + cards), True))
    searched = plan.searched
    if not searched or searched[0] not in names:  # discrete (or none): the Gaussians a factor
        probs, log_z = contract_factors(plan, factors, searched)
        return answer(plan, probs, log_z, method="gaussian")  # type: ignore[return-value]
    probs, log_z = contract_factors(plan, factors, tuple(mixing))
    weights = probs.reshape(rows, k)
    pick = [unknown.index(names.index(v)) for v in searched]
    means = np.broadcast_to(cond_mean, (rows, k, len(unknown)))[..., pick]
    covs = np.broadcast_to(cond_cov, (rows, k, len(unknown), len(unknown)))[..., pick, :][
        ..., :, pick]
    return Density(str(plan.question.expression), searched, bound.batch_shape, log_z,
                   ablated=program.ablated, method="gaussian", weights=weights,
                   means=np.ascontiguousarray(means), covariances=np.ascontiguousarray(covs))
