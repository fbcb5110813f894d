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

What depends only on the question's layout (its searched and known variables, not their
values) is worked out once and kept with the layout: the terms solved together, and, when every
one of them has one affine mean of numbers and a literal sigma (a linear-Gaussian network: no
discrete parent nor runtime input), the conditioning as one affine map of the known values
(:class:`LinearLayout`). A question asked again with other values, or a batch of them, is then
one matrix product.
"""

from __future__ import annotations

from dataclasses import dataclass

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
from bayesprog.inference.protocol import ProgramLike
from bayesprog.limits import check_size
from bayesprog.model import Term
from bayesprog.vocabulary.formula import Formula
from bayesprog.vocabulary.variables import Discrete

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
    program is not conditional linear-Gaussian (found once per layout: it reads the names of
    the known variables, not their values)."""
    found = plan.layout.prepared.get("gaussian block")
    if found is None:
        found = plan.layout.prepared["gaussian block"] = _find_block(plan)
    return found


def _find_block(plan: QuestionPlan) -> tuple[list[Term], str | None]:
    latent = set(plan.latent)
    chosen = [t for t in plan.terms if not t.child.is_discrete and (
        t.child.name in latent or any(p.name in latent for p in t.parents))]
    names = {t.child.name for t in chosen}
    for t in plan.terms:
        if t.child.name not in names and any(p.name in latent for p in t.parents):
            return [], (f"{t.label} has a discrete child of the unknown real "
                        f"{', '.join(p.name for p in t.parents if p.name in latent)}")
    for t in chosen:
        if t.form.subprogram:
            return [], (f"{t.label} is another program's answer (a {t.form.name} term), "
                        "which the Gaussian algebra does not take: where "
                        f"{t.child.name} or its real parents are unknown, the grid method (on "
                        "a bounded support) and likelihood weighting ('lw', for discrete "
                        "searched variables) use its density; where they are known, every "
                        "discrete method does")
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
                if _affine(plan.program, formula) is None and not formula.affine_in(names):
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
    linear = LinearLayout.of(plan, block)
    if linear is not None:
        loglik, means, covs = linear.condition(bound)
        if not linear.whole:
            return _joined(plan, names, [], [], loglik, means, covs)
        rows = bound.size
        log_z = np.broadcast_to(loglik[:, 0], (rows,))
        return Density(str(plan.question.expression), plan.searched, bound.batch_shape,
                       np.array(log_z), ablated=program.ablated, method="gaussian",
                       weights=np.ones((rows, 1)), means=np.ascontiguousarray(means),
                       covariances=np.broadcast_to(covs, (rows, *covs.shape[1:])).copy())
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
    pick = [unknown.index(names.index(v)) for v in plan.searched if v in names]
    return _joined(plan, names, mixing, cards, loglik, cond_mean[..., pick],
                   cond_cov[..., pick, :][..., :, pick])


def _joined(plan: QuestionPlan, names: list[str], mixing: list[str], cards: list[int],
            loglik: np.ndarray, means: np.ndarray, covs: np.ndarray) -> Density:
    """The answer: the likelihood of each configuration ``loglik`` ``[r, k]`` joined to the
    other terms' factors; ``means`` ``[r, k, p]`` and ``covs`` ``[r, k, p, p]``: the searched
    real variables' conditional Gaussian in each configuration."""
    program, bound = plan.program, plan.bound
    rows = bound.size
    k = int(np.prod(cards)) if cards else 1
    solved = set(names)
    rest = [t for t in plan.terms if t.child.name not in solved]
    factors = question_factors(program, rest, bound)
    loglik = np.broadcast_to(loglik, (rows, k))
    factors.append(Factor(tuple(mixing), loglik.reshape([rows] + cards), True))
    searched = plan.searched
    if not searched or searched[0] not in names:  # discrete (or none): the Gaussians a factor
        probs, log_z = contract_factors(plan, factors, searched)
        return answer(plan, probs, log_z, method="gaussian")  # type: ignore[return-value]
    probs, log_z = contract_factors(plan, factors, tuple(mixing))
    weights = probs.reshape(rows, k)
    p = means.shape[-1]
    means = np.broadcast_to(means, (rows, k, p))
    covs = np.broadcast_to(covs, (rows, k, p, p))
    return Density(str(plan.question.expression), searched, bound.batch_shape, log_z,
                   ablated=program.ablated, method="gaussian", weights=weights,
                   means=np.ascontiguousarray(means), covariances=np.ascontiguousarray(covs))


@dataclass
class LinearLayout:
    """A linear-Gaussian block's algebra for one layout: every term of the block a normal (or
    dirac) term whose mean is a number or one affine formula of numbers and whose sigma is a
    number, so that its joint Gaussian depends on the known real values ``u`` outside the
    block only through its mean:

        x = M (b + C u + e)  =>  mean(u) = M b + M C u,  cov = M diag(s) M^T

    Conditioning on the known block variables ``o`` gives the searched ones ``p`` the mean
    ``mean_p + G^T (x_o - mean_o)``, ``G = cov_oo^-1 cov_op``, a covariance that no value
    changes, and the likelihood of ``x_o`` from its residuals whitened by the inverse ``W`` of
    ``cov_oo``'s Cholesky factor. When the question's other terms are of the same kind (known
    real children of known parents) and it searches real variables only, their standardised
    residuals join (``whole``: the answer then needs no contraction). All of these are affine
    in the known values ``v``: one matrix, found here once, gives them all at each question,

        [W (x_o - mean_o), (x_rest - mean_rest) / sigma_rest, cond. mean_p] = v A + c,

    the log-likelihood being ``norm - |first columns|^2 / 2``.
    """

    given: list[str]  #: the known real variables whose values are read, ``v``
    weights: np.ndarray  #: [g, q + p] A
    offset: np.ndarray  #: [q + p] c
    standardised: int  #: q: the columns of standardised residuals
    norm: float  #: their log-likelihood's constant
    cond_cov: np.ndarray  #: [p, p]
    whole: bool  #: whether the other terms' log densities are in

    @classmethod
    def of(cls, plan: QuestionPlan, block: list[Term]) -> LinearLayout | None:
        """The layout's, made at its first question; None when a term is not of that kind."""
        prepared = plan.layout.prepared
        if "gaussian linear" not in prepared:
            prepared["gaussian linear"] = cls._make(plan, block)
        return prepared["gaussian linear"]

    @classmethod
    def _make(cls, plan: QuestionPlan, block: list[Term]) -> LinearLayout | None:
        bound, variables = plan.bound, plan.program.variables
        if bound.ablated:
            return None
        names = [t.child.name for t in block]
        at = {name: i for i, name in enumerate(names)}
        n = len(names)
        check_size(3.0 * n * n, f"the joint Gaussian of {n} real variables")

        def outside(name: str) -> bool:  # a known real value
            return name in bound.continuous and not isinstance(variables.get(name), Discrete)

        given = {name: None for name in names if name in bound.continuous}
        weights, intercepts, noise = np.zeros((n, n)), np.zeros(n), np.zeros(n)
        slopes: list[dict[str, float]] = []
        for i, t in enumerate(block):
            found = _linear_term(plan.program, t)
            if found is None or not all(v in at or outside(v) for v in found[1]):
                return None
            intercepts[i], coefficients, noise[i] = found
            slopes.append({v: c for v, c in coefficients.items() if v not in at})
            given.update(dict.fromkeys(slopes[-1]))
            for v, c in coefficients.items():
                if v in at:
                    weights[i, at[v]] += c
        rest = [t for t in plan.terms if t.child.name not in at]
        folded = [_linear_term(plan.program, t) for t in rest]
        whole = (not bound.soft and bool(plan.searched) and all(v in at for v in plan.searched)
                 and all(f is not None and f[2] > 0 and outside(t.child.name)
                         and all(outside(v) for v in f[1]) and not t.soft
                         and getattr(t.child, "index", None) is None
                         for t, f in zip(rest, folded, strict=True)))
        if whole:
            for t, f in zip(rest, folded, strict=True):
                given.update(dict.fromkeys([t.child.name, *f[1]]))  # type: ignore[index]
        column = {v: j for j, v in enumerate(given)}
        slope = np.zeros((n, len(column)))
        for i, row in enumerate(slopes):
            for v, c in row.items():
                slope[i, column[v]] += c
        solve = np.linalg.inv(np.eye(n) - weights)
        base, slope = solve @ intercepts, solve @ slope  # the block's mean: base + slope v
        cov = (solve * noise) @ solve.T
        known = [i for i, v in enumerate(names) if v in bound.continuous]
        pick = [at[v] for v in plan.searched if v in at]
        cov_oo, cov_op = cov[np.ix_(known, known)], cov[np.ix_(known, pick)]
        try:
            chol = np.linalg.cholesky(cov_oo)
        except np.linalg.LinAlgError:
            raise QuestionError(f"{plan.question.expression}: the known values "
                                f"{', '.join(names[i] for i in known)} are tied exactly "
                                "(a singular covariance)") from None
        whiten = np.linalg.inv(chol)  # (o is a few known variables)
        gain = whiten.T @ (whiten @ cov_op)
        # x_o - mean_o = v R + r
        pick_known = np.zeros((len(column), len(known)))
        pick_known[[column[names[i]] for i in known], range(len(known))] = 1.0
        resid_weights, resid_offset = pick_known - slope[known].T, -base[known]
        blocks = [(resid_weights @ whiten.T, resid_offset @ whiten.T)]
        norm = -float(np.log(np.diagonal(chol)).sum()) - 0.5 * len(known) * _LOG_2PI
        if whole:
            matrix, offset, scale = (np.zeros((len(column), len(rest))), np.zeros(len(rest)),
                                     np.zeros(len(rest)))
            for k, (t, f) in enumerate(zip(rest, folded, strict=True)):
                offset[k], coefficients, variance = f  # type: ignore[misc]
                matrix[column[t.child.name], k] += 1.0
                for v, c in coefficients.items():
                    matrix[column[v], k] -= c
                scale[k] = 1.0 / np.sqrt(variance)
            blocks.append((matrix * scale, -offset * scale))
            norm += float(np.log(scale).sum()) - 0.5 * len(rest) * _LOG_2PI
        blocks.append((slope[pick].T + resid_weights @ gain, base[pick] + resid_offset @ gain))
        return cls(list(given), np.hstack([w for w, _ in blocks]),
                   np.concatenate([c for _, c in blocks]), sum(c.size for _, c in blocks[:-1]),
                   norm, cov[np.ix_(pick, pick)] - cov_op.T @ gain, whole)

    def condition(self, bound: Bound) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """For the bound values: the log-likelihood of the known values ``[r or 1, 1]`` (those
        of the block, and of the other terms when ``whole``), the searched variables'
        conditional means ``[r, 1, p]`` and their covariance ``[1, 1, p, p]``."""
        values = _values(bound, self.given)
        out = values @ self.weights + self.offset
        z = out[:, : self.standardised]
        loglik = self.norm - 0.5 * np.einsum("ij,ij->i", z, z)[:, np.newaxis]
        cond_mean = np.broadcast_to(out[:, self.standardised :],
                                    (bound.size, out.shape[1] - self.standardised))
        return loglik, cond_mean[:, np.newaxis, :], self.cond_cov[np.newaxis, np.newaxis]


def _linear_term(program: ProgramLike, t: Term) -> tuple[float, dict[str, float], float] | None:
    """``(intercept, {name: coefficient}, variance)`` of a term whose mean is a number or one
    affine formula of numbers and whose scale is a number (variance 0 without one: a dirac),
    else None."""
    mean_key, scale_key = t.form.mean_param, t.form.scale_param
    if mean_key is None or set(t.params) - {mean_key, scale_key}:
        return None
    mean = t.params[mean_key]
    if isinstance(mean, FormulaParam) and not mean.axes:
        affine = _affine(program, mean.formulas.flat[0])
        if affine is None:
            return None
        intercept, coefficients = affine
    elif isinstance(mean, ParamValue) and not mean.axes and not mean.batched:
        intercept, coefficients = float(mean.array), {}
    else:
        return None
    if scale_key is None:
        return intercept, coefficients, 0.0
    sigma = t.params[scale_key]
    if not (isinstance(sigma, ParamValue) and not sigma.axes and not sigma.batched):
        return None  # (the loader makes a formula of numbers a number)
    s = float(sigma.array)
    if not s > 0:
        raise QuestionError(f"term {t.label}: {scale_key} must be > 0, got {s:g}")
    return intercept, coefficients, s * s


def _values(bound: Bound, names: list[str]) -> np.ndarray:
    """The known real values of ``names``, ``[rows or 1, len(names)]``."""
    found = [bound.continuous[v] for v in names]
    if not found:
        return np.zeros((1, 0))
    if not any(pv.batched for pv in found):
        return np.array([[float(pv.array) for pv in found]])
    return np.stack([np.broadcast_to(np.asarray(pv.array, float), (bound.size,))
                     for pv in found], axis=-1)


def _affine(program: ProgramLike, formula: Formula) -> tuple[float, dict[str, float]] | None:
    """:meth:`Formula.affine`, kept by the program for each of its formulas (a layout's first
    question reads each twice: to choose the method and to solve)."""
    kept = program.inference_cache.derived
    key = ("gaussian affine", id(formula))
    if key not in kept:
        kept[key] = formula.affine()
    return kept[key]
