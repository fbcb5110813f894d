"""Estimators: a form's expected sufficient statistics, and its parameters from them.

Each form declares its estimator (:meth:`bayesprog.forms.Form.estimator`), so adding a form
that can be learned is one class here and one there. The E-step of
:mod:`bayesprog.learning.fit` hands each learned term what the data say about
its family: expected counts over the term's discrete variables (a discrete child), or, for a
continuous child, the child's values with one weight per row and parent configuration. An
estimator turns that into statistics that add up over data sets (so a fit can continue with
more data), and the statistics into parameters. Every array is laid out parent axes first (in
the term's order), then the form's own trailing axes.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from bayesprog.forms.base import Estimator, LearnOptions, Params, ParamValue, Stats, Term
from bayesprog.support.extras import LazyModule
from bayesprog.vocabulary.variables import Discrete

#: scipy.special, imported by the first computation that reads it
special = LazyModule("scipy.special")

__all__ = ["Estimator", "FitProblem", "LearnOptions", "Params", "Stats", "Term"]  # and below


class FitProblem(Exception):
    """Parameters cannot be estimated from these data (``row``: the offending data row)."""

    def __init__(self, message: str, row: int | None = None):
        super().__init__(message)
        self.row = row


def parent_axes(term: Term) -> tuple[str, ...]:
    return tuple(p.name for p in term.parents if p.is_discrete)


def parent_cards(term: Term) -> tuple[int, ...]:
    return tuple(p.card for p in term.parents if isinstance(p, Discrete))


def full(term: Term, value: ParamValue, event_ndim: int, event: tuple[int, ...] = ()) -> np.ndarray:
    """A parameter as an array over every parent configuration: ``[*parent cards, *event]``."""
    arr = value.aligned(parent_axes(term), event_ndim)[0]
    return np.broadcast_to(arr, parent_cards(term) + (event or arr.shape[arr.ndim - event_ndim:]))


def _configs(term: Term, mask: np.ndarray) -> str:
    """The parent configurations where ``mask`` holds, as ``A=a, B=b`` (the first three)."""
    names = [p for p in term.parents if isinstance(p, Discrete)]
    found = list(zip(*np.nonzero(mask), strict=False)) if np.ndim(mask) else [()]
    shown = ["(" + ", ".join(f"{v.name}={v.states[i]}" for v, i in zip(names, idx, strict=True))
             + ")" if names else "the term" for idx in found[:3]]
    more = f" and {len(found) - 3} more" if len(found) > 3 else ""
    return "; ".join(shown) + more


class TableEstimator(Estimator):
    """Tables and categoricals: the posterior mean under Dirichlet pseudo-counts (maximum
    likelihood without them)."""

    options = frozenset({"pseudo_counts"})

    def __init__(self, name: str):
        self.learned = (name,)

    def counts(self, term: Term, counts: np.ndarray) -> Stats:
        return {"counts": np.moveaxis(counts, 0, -1)}  # [*parent cards, child states]

    def estimate(self, term: Term, stats: Stats, options: LearnOptions, params: Params) -> Params:
        counts = stats["counts"]
        pseudo = options.pseudo_counts
        if pseudo is None:
            alpha = np.zeros_like(counts)
        elif pseudo.array.ndim == 0:
            alpha = np.full_like(counts, float(pseudo.array))
        else:
            alpha = np.broadcast_to(full(term, pseudo, 1), counts.shape)
        total = counts + alpha
        sums = total.sum(-1, keepdims=True)
        if np.any(sums <= 0):
            raise FitProblem(f"too few rows: no row has {_configs(term, sums[..., 0] <= 0)}, so "
                             f"{term.label} there is undefined; give "
                             "learn: {pseudo_counts: ...} or freeze the term (learn: false)")
        return {self.learned[0]: ParamValue(parent_axes(term), total / sums)}

    def free_parameters(self, term: Term, params: Params, options: LearnOptions) -> int:
        return int(np.prod(parent_cards(term), dtype=np.int64)) * (term.child.card - 1)  # type: ignore[union-attr]

    def log_prior(self, term: Term, params: Params, options: LearnOptions) -> float:
        if options.pseudo_counts is None:
            return 0.0
        theta = full(term, params[self.learned[0]], 1)
        pseudo = options.pseudo_counts
        alpha = (np.full(theta.shape, float(pseudo.array)) if pseudo.array.ndim == 0
                 else np.broadcast_to(full(term, pseudo, 1), theta.shape))
        with np.errstate(divide="ignore", invalid="ignore"):
            return float(np.where(alpha > 0, alpha * np.log(theta), 0.0).sum())


def _weighted(x: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    w = weights.reshape(len(x), int(np.prod(weights.shape[1:])))  # no row: no -1 to infer
    n = w.sum(0)
    return n, x @ w, (x * x) @ w


def _moments(x: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Weighted count, mean and sum of squared deviations per column of ``weights`` [n, m]:
    centred, so that values far from zero keep their precision."""
    w = weights.reshape(len(x), int(np.prod(weights.shape[1:])))  # no row: no -1 to infer
    n = w.sum(0)
    safe = np.where(n > 0, n, 1.0)
    mean = (x @ w) / safe
    m2 = ((x[:, None] - mean) ** 2 * w).sum(0)
    return n, np.where(n > 0, mean, 0.0), m2


def _merge_moments(a: Stats, b: Stats) -> Stats:
    """Chan's pairwise update of (count, mean, sum of squared deviations)."""
    na, nb = a["count"], b["count"]
    n = na + nb
    safe = np.where(n > 0, n, 1.0)
    delta = b["mean"] - a["mean"]
    out = dict(a)
    out.update(count=n, mean=np.where(n > 0, a["mean"] + delta * nb / safe, 0.0),
               sum_squared_deviations=a["sum_squared_deviations"] + b["sum_squared_deviations"]
               + delta**2 * na * nb / safe)
    return out


def _moment_stats(x: np.ndarray, weights: np.ndarray, shape: tuple[int, ...]) -> Stats:
    n, mean, m2 = _moments(x, weights)
    return {"count": n.reshape(shape), "mean": mean.reshape(shape),
            "sum_squared_deviations": m2.reshape(shape)}


class _MomentEstimator(Estimator):
    """Forms learned from weighted counts, means and sums of squared deviations."""

    def merge(self, a: Stats, b: Stats) -> Stats:
        return _merge_moments(a, b)


class NormalEstimator(_MomentEstimator):
    """Maximum likelihood per parent configuration (``shared`` pools mean or sigma)."""

    learned = ("mean", "sigma")
    options = frozenset({"shared"})

    def statistics(self, term: Term, x: np.ndarray, weights: np.ndarray, params: Params) -> Stats:
        return _moment_stats(x, weights, weights.shape[1:])

    def estimate(self, term: Term, stats: Stats, options: LearnOptions, params: Params) -> Params:
        n, means, m2 = stats["count"], stats["mean"], stats["sum_squared_deviations"]
        shared = set(options.shared)
        need = 1 if "sigma" in shared else 2
        few = n < need
        if "mean" in shared and "sigma" in shared:
            few = np.asarray(n.sum() < 2)
        if np.any(few):
            raise FitProblem(f"too few rows for {term.label}: "
                             f"{_configs(term, few)} has fewer than {need} rows (a Normal's "
                             "mean and sigma need two)")
        total = n.sum()
        pooled = (n * means).sum() / total
        scale = max(float(np.max(np.abs(means))), 1.0)
        tiny = (1e-12 * scale) ** 2
        if "mean" in shared and "sigma" in shared:
            var = np.asarray((m2.sum() + (n * (means - pooled) ** 2).sum()) / total)
            mean = np.asarray(pooled)
        elif "mean" in shared:
            # one mean, a sigma per state: the mean weights each state by its precision
            mean = np.asarray(pooled)
            for _ in range(200):
                var = np.maximum((m2 + n * (means - mean) ** 2) / n, tiny)
                fresh = (n * means / var).sum() / (n / var).sum()
                if abs(fresh - mean) <= 1e-15 * scale:
                    break
                mean = np.asarray(fresh)
            var = (m2 + n * (means - mean) ** 2) / n
        elif "sigma" in shared:
            mean, var = means, np.asarray(m2.sum() / total)
        else:
            mean, var = means, m2 / n
        flat = np.asarray(var <= tiny)
        if np.any(flat):
            where = _configs(term, flat) if flat.ndim else "every row"
            raise FitProblem(f"degenerate fit of {term.label}: zero variance "
                             f"({where} has one repeated value)")
        axes = parent_axes(term)
        return {"mean": ParamValue(() if "mean" in shared else axes, np.asarray(mean, float)),
                "sigma": ParamValue(() if "sigma" in shared else axes, np.sqrt(var))}

    def free_parameters(self, term: Term, params: Params, options: LearnOptions) -> int:
        configs = int(np.prod(parent_cards(term), dtype=np.int64))
        return sum(1 if name in options.shared else configs for name in self.learned)


class BetaEstimator(Estimator):
    """Maximum likelihood per parent configuration: Newton's method on the Beta's sufficient
    statistics (mean log x, mean log(1 - x)), started from the method of moments."""

    learned = ("a", "b")

    def statistics(self, term: Term, x: np.ndarray, weights: np.ndarray, params: Params) -> Stats:
        used = weights.reshape(len(x), -1).sum(1) > 0
        bad = np.nonzero(used & ((x <= 0) | (x >= 1)))[0]
        if len(bad):
            raise FitProblem(f"degenerate fit of {term.label}: the value "
                             f"{x[bad[0]]} is on the edge of a Beta's support (its density there "
                             "is 0 or infinite); expected values strictly inside (0, 1)",
                             row=int(bad[0]))
        n, s1, s2 = _weighted(x, weights)
        safe = np.clip(x, 1e-300, 1 - 1e-16)
        w = weights.reshape(len(x), -1)
        shape = weights.shape[1:]
        return {"count": n.reshape(shape), "sum": s1.reshape(shape), "sum_squares": s2.reshape(shape),
                "sum_log": (np.log(safe) @ w).reshape(shape),
                "sum_log1m": (np.log1p(-safe) @ w).reshape(shape)}

    def estimate(self, term: Term, stats: Stats, options: LearnOptions, params: Params) -> Params:
        if options.shared:
            raise FitProblem("form beta learns a and b per parent configuration; 'shared' is "
                             "not supported for it")
        n = stats["count"]
        few = n < 2
        if np.any(few):
            raise FitProblem(f"too few rows for {term.label}: "
                             f"{_configs(term, few)} has fewer than 2 rows")
        m = stats["sum"] / n
        v = stats["sum_squares"] / n - m * m
        if np.any(v <= 1e-24):
            raise FitProblem(f"degenerate fit of {term.label}: zero variance "
                             f"({_configs(term, v <= 1e-24)} has one repeated value)")
        g1, g2 = stats["sum_log"] / n, stats["sum_log1m"] / n
        common = np.where(v < m * (1 - m), m * (1 - m) / v - 1, 1.0)
        a, b = np.maximum(m * common, 1e-3), np.maximum((1 - m) * common, 1e-3)
        a, b = _beta_newton(a, b, g1, g2)
        axes = parent_axes(term)
        return {"a": ParamValue(axes, a), "b": ParamValue(axes, b)}

    def free_parameters(self, term: Term, params: Params, options: LearnOptions) -> int:
        return 2 * int(np.prod(parent_cards(term), dtype=np.int64))


def _beta_newton(a: np.ndarray, b: np.ndarray, g1: np.ndarray, g2: np.ndarray,
                 steps: int = 100) -> tuple[np.ndarray, np.ndarray]:
    """Maximise ``(a-1) g1 + (b-1) g2 - special.betaln(a, b)`` elementwise (concave in (a, b))."""

    def objective(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return (a - 1) * g1 + (b - 1) * g2 - special.betaln(a, b)

    for _ in range(steps):
        dab = special.digamma(a + b)
        ga, gb = g1 - special.digamma(a) + dab, g2 - special.digamma(b) + dab
        t = special.polygamma(1, a + b)
        haa, hbb = t - special.polygamma(1, a), t - special.polygamma(1, b)
        det = haa * hbb - t * t
        da = -(hbb * ga - t * gb) / det
        db = -(haa * gb - t * ga) / det
        step = np.ones_like(a)
        now = objective(a, b)
        for _ in range(60):  # halve the step until it stays positive and does not go down
            na, nb = a + step * da, b + step * db
            ok = (na > 0) & (nb > 0)
            better = ok & (objective(np.where(ok, na, 1.0), np.where(ok, nb, 1.0)) >= now - 1e-15)
            if np.all(better):
                break
            step = np.where(better, step, step / 2)
        a, b = np.where(better, na, a), np.where(better, nb, b)
        if np.all(np.abs(step * da) <= 1e-12 * a) and np.all(np.abs(step * db) <= 1e-12 * b):
            break
    return a, b


class GmmEstimator(_MomentEstimator):
    """EM for a Gaussian mixture over a real child: the component of each row is one more
    hidden variable. One sigma per parent configuration (the form's components share it)."""

    learned = ("means", "sigma", "weights")
    options = frozenset({"components", "shared"})
    mixture = True

    def components(self, term: Term, params: Params) -> int:
        return components_of(params, term) if "means" in params else 1

    def _arrays(self, term: Term, params: Params) -> tuple[np.ndarray, ...]:
        means = full(term, params["means"], 1)
        k = means.shape[-1]
        sigma = full(term, params["sigma"], 0)
        weights = (full(term, params["weights"], 1) if "weights" in params
                   else np.full(means.shape, 1.0 / k))
        floor = full(term, params["floor"], 0) if "floor" in params else np.zeros(sigma.shape)
        return means, sigma, weights, floor

    def statistics(self, term: Term, x: np.ndarray, weights: np.ndarray, params: Params) -> Stats:
        means, sigma, mix, floor = self._arrays(term, params)
        width = term.child.width  # type: ignore[union-attr]
        z = (x[:, None, None] - means.reshape(1, -1, means.shape[-1])) / sigma.reshape(1, -1, 1)
        log_comp = (-0.5 * z * z - np.log(sigma.reshape(1, -1, 1)) - 0.5 * np.log(2 * np.pi)
                    + np.log(np.maximum(mix.reshape(1, -1, mix.shape[-1]), 1e-300)))
        f = floor.reshape(1, -1, 1)
        with np.errstate(divide="ignore"):
            log_comp = log_comp + np.log1p(-f)
            top = log_comp.max(-1, keepdims=True)
            top = np.where(np.isfinite(top), top, 0.0)
            total = np.log(np.exp(log_comp - top).sum(-1, keepdims=True)) + top
            if np.any(f > 0):
                total = np.logaddexp(total, np.log(f) - np.log(width))
        resp = np.exp(log_comp - total) * weights.reshape(len(x), -1, 1)  # [n, configs, K]
        return _moment_stats(x, resp.reshape(len(x), -1), weights.shape[1:] + (means.shape[-1],))

    def estimate(self, term: Term, stats: Stats, options: LearnOptions, params: Params) -> Params:
        n, mean, m2 = stats["count"], stats["mean"], stats["sum_squared_deviations"]
        if set(options.shared) - {"sigma"}:
            raise FitProblem("form gmm shares only 'sigma' across parent configurations")
        total = n.sum(-1)
        if np.any(total < 2):
            raise FitProblem(f"too few rows for {term.label}: "
                             f"{_configs(term, total < 2)} has fewer than 2 rows")
        empty = n <= 1e-10 * np.maximum(total[..., None], 1.0)
        if np.any(empty):
            raise FitProblem(f"degenerate fit of {term.label}: a component of the "
                             f"mixture at {_configs(term, empty.any(-1))} takes no rows; use "
                             "fewer components")
        means = mean
        sq = m2.sum(-1)
        var = np.asarray(sq.sum() / total.sum()) if "sigma" in options.shared else sq / total
        if np.any(var <= 1e-24):
            raise FitProblem(f"degenerate fit of {term.label}: zero variance "
                             "(every component sits on repeated values)")
        axes = parent_axes(term)
        return {"means": ParamValue(axes, means),
                "sigma": ParamValue(() if "sigma" in options.shared else axes, np.sqrt(var)),
                "weights": ParamValue(axes, n / total[..., None])}

    def free_parameters(self, term: Term, params: Params, options: LearnOptions) -> int:
        configs = int(np.prod(parent_cards(term), dtype=np.int64))
        k = full(term, params["means"], 1).shape[-1]
        sigma = 1 if "sigma" in options.shared else configs
        return configs * (2 * k - 1) + sigma

    def initial(self, term: Term, x: np.ndarray, weights: np.ndarray, components: int,
                params: Params) -> Params:
        """Means at the weighted quantiles (i + 1/2)/K of each parent configuration, equal
        weights, sigma the weighted spread over K: deterministic, no random start."""
        w = weights.reshape(len(x), -1)
        order = np.argsort(x, kind="stable")
        xs, ws = x[order], w[order]
        cum = np.cumsum(ws, axis=0)
        configs = w.shape[1]
        means = np.empty((configs, components))
        sigma = np.empty(configs)
        q = (np.arange(components) + 0.5) / components
        none = cum[-1] <= 0
        if np.any(none):
            raise FitProblem(f"too few rows for {term.label}: "
                             f"{_configs(term, none.reshape(weights.shape[1:]))} has none")
        for c in range(configs):
            means[c] = np.interp(q * cum[-1, c], cum[:, c], xs)
            m = ws[:, c] @ xs / cum[-1, c]
            sigma[c] = max(np.sqrt(max(ws[:, c] @ (xs - m) ** 2 / cum[-1, c], 0.0)) / components,
                           1e-6)
        shape = weights.shape[1:]
        axes = parent_axes(term)
        out = dict(params)
        out["means"] = ParamValue(axes, means.reshape(shape + (components,)))
        out["sigma"] = ParamValue(axes, sigma.reshape(shape))
        out["weights"] = ParamValue(axes, np.full(shape + (components,), 1.0 / components))
        return out


def components_of(params: Mapping[str, ParamValue], term: Term) -> int:
    return int(full(term, params["means"], 1).shape[-1])
