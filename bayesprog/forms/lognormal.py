"""The log-normal form, ``log X ~ N(mu[parents], sigma[parents])``: a form added as one class
(its density, CDF, sampling and estimator declared together) and its tests, as
``docs/architecture.md`` shows.

>>> import bayesprog
>>> program = bayesprog.loads('''
... bayesprog: 1
... variables:
...   Q: {states: [fine, coarse]}
...   D: {continuous: [0, .inf]}
... decomposition:
...   - {term: P(Q), form: uniform}
...   - {term: P(D | Q), form: lognormal, mu: {fine: -1.0, coarse: 0.5}, sigma: 0.4}
... ''')
>>> program.ask("P(Q | D)", {"D": 0.4}).probabilities.round(3).tolist()
[0.998, 0.002]
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from bayesprog.forms.base import (
    Estimator,
    Form,
    LearnOptions,
    Param,
    Params,
    Stats,
    Term,
    TermContext,
    positive,
    real,
    register_form,
)
from bayesprog.forms.estimators import FitProblem, NormalEstimator
from bayesprog.support.extras import LazyModule
from bayesprog.vocabulary.variables import Variable

#: scipy.special, imported by the first computation that reads it
special = LazyModule("scipy.special")

_LOG_2PI = float(np.log(2 * np.pi))


class LogNormalEstimator(NormalEstimator):
    """Maximum likelihood: a Normal's on the logarithms of the values (``shared`` pools mu or
    sigma)."""

    learned = ("mu", "sigma")

    def statistics(self, term: Term, x: np.ndarray, weights: np.ndarray, params: Params) -> Stats:
        if np.any(x <= 0):
            raise FitProblem(f"{term.label}: a log-normal variable is > 0, found "
                             f"{float(np.min(x)):g} in the data")
        return super().statistics(term, np.log(x), weights, params)

    def estimate(self, term: Term, stats: Stats, options: LearnOptions, params: Params) -> Params:
        shared = tuple("mean" if name == "mu" else name for name in options.shared)
        normal = super().estimate(term, stats, LearnOptions(shared=shared), params)
        return {"mu": normal["mean"], "sigma": normal["sigma"]}


@register_form
class LogNormal(Form):
    """``LogNormal(x; mu[parents], sigma[parents])``: ``log x`` is Normal with mean ``mu`` and
    standard deviation ``sigma`` (``exp(mu)`` is the median); density 0 at x <= 0."""

    location_scale = ("mu", "sigma")

    name = "lognormal"
    pointwise = True
    title = "LogNormal"
    child_kinds = ("continuous",)
    quantile_sample = True
    params = (
        Param("mu", real, doc="mean of log x, a literal or a table keyed by parent states"),
        Param("sigma", positive, doc="standard deviation of log x, > 0"),
    )

    def estimator(self, child: Variable) -> Estimator | None:
        return LogNormalEstimator()

    def log_factor(self, ctx: TermContext) -> np.ndarray:
        x, mu, sigma = ctx.child_value(), ctx.param("mu"), ctx.param("sigma")
        positive_x = x > 0
        log_x = np.log(np.where(positive_x, x, 1.0))
        z = (log_x - mu) / sigma
        out = -0.5 * z * z - np.log(sigma) - 0.5 * _LOG_2PI - log_x
        return np.where(positive_x, out, -np.inf)

    def cdf(self, ctx: TermContext) -> np.ndarray:
        x, mu, sigma = ctx.child_value(), ctx.param("mu"), ctx.param("sigma")
        positive_x = x > 0
        return np.where(positive_x, special.ndtr((np.log(np.where(positive_x, x, 1.0)) - mu) / sigma),
                        0.0)

    def sample(self, params: Mapping[str, np.ndarray], child: Variable,
               u: np.ndarray) -> np.ndarray:
        return np.exp(params["mu"] + params["sigma"] * special.ndtri(u[..., 0]))
