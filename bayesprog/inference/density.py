"""What a question on real variables answers: a density, with its mean, standard deviation,
quantiles and MAP.

Two representations, one interface:

* a **Gaussian mixture** (exact answers of linear-Gaussian programs, one component per
  configuration of the unknown discrete variables the Gaussians depend on): ``weights``
  ``[rows, K]``, ``means`` ``[rows, K, d]``, ``covariances`` ``[rows, K, d, d]``;
* **bins** (answers on a grid): the probability of each bin of each searched variable, the
  density uniform within a bin, and the estimated error of every summary.

>>> import numpy as np
>>> d = Density("P(X)", ("X",), (), np.zeros(1), weights=np.ones((1, 1)),
...             means=np.full((1, 1, 1), 2.0), covariances=np.full((1, 1, 1, 1), 4.0))
>>> float(d.mean("X")), float(d.sd("X")), round(float(d.quantile("X", 0.975)), 4)
(2.0, 2.0, 5.9199)
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from bayesprog.errors import QuestionError
from bayesprog.support import rich
from bayesprog.support.extras import LazyModule

#: scipy.special, imported by the first computation that reads it
special = LazyModule("scipy.special")

#: The quantiles a summary reports.
QUANTILES = (0.05, 0.25, 0.5, 0.75, 0.95)
_SQRT_2PI = float(np.sqrt(2 * np.pi))
_LOG_2PI = float(np.log(2 * np.pi))


def per_row(values: Any, batch_shape: tuple[int, ...]) -> np.ndarray:
    """``values``, one number per row of evidence, shaped as the batch (flat rows reshaped,
    one number for every row broadcast): every answer's ``log_evidence`` has its batch's shape,
    ``()`` for a question asked once.

    >>> per_row(np.zeros(1), ()).shape, per_row(np.zeros(6), (2, 3)).shape
    ((), (2, 3))
    """
    array = np.asarray(values, dtype=float)
    if array.shape == batch_shape:
        return array
    if array.size == int(np.prod(batch_shape)):
        return array.reshape(batch_shape)
    return np.broadcast_to(array, batch_shape).copy()


@dataclass
class Density:
    """``P(searched | evidence)`` over real variables (see the module's docstring)."""

    question: str
    variables: tuple[str, ...]
    batch_shape: tuple[int, ...]
    log_evidence: np.ndarray
    ablated: tuple[str, ...] = ()
    method: str = ""
    weights: np.ndarray | None = None
    means: np.ndarray | None = None
    covariances: np.ndarray | None = None
    #: bins: each searched variable's edges, and the joint probability of each bin
    #: ``[rows] + bins of each variable``
    edges: dict[str, np.ndarray] | None = None
    masses: np.ndarray | None = None
    #: bins: how many bins the grid had per variable, and each summary's estimated error
    #: (the change when every bin is halved), ``{"mean": {var: [batch]}, ...}``
    resolution: dict[str, int] = field(default_factory=dict)
    error: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)
    #: a particle filter's effective sample size per row (step), before it resampled
    ess: np.ndarray | None = None
    #: what the +- of an approximate answer is (``"bound"``: ``error``, an estimated bound of
    #: each summary's error); None when it has none
    uncertainty: str | None = None

    def __post_init__(self) -> None:
        self.batch_shape = tuple(self.batch_shape)
        self.log_evidence = per_row(self.log_evidence, self.batch_shape)

    @property
    def kind(self) -> str:
        """How the density is held: ``gaussian`` (one Gaussian per row: a linear-Gaussian
        answer, Kalman and RTS, a particle filter's moments), ``gaussian mixture`` (one per
        configuration of the discrete variables summed out) or ``bins``."""
        if self.weights is None:
            return "bins"
        return "gaussian" if self.weights.shape[-1] == 1 else "gaussian mixture"

    def _repr_html_(self) -> str | None:
        return rich.html("density", self)

    # the marginal of one variable, flat over rows --------------------------------------------
    def _index(self, variable: str) -> int:
        if variable not in self.variables:
            raise QuestionError(f"{variable!r} is not searched by {self.question} (searched: "
                                f"{', '.join(self.variables)})")
        return self.variables.index(variable)

    def _gaussian(self, variable: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Weights, means and standard deviations of the marginal's components ``[rows, K]``."""
        i = self._index(variable)
        assert self.weights is not None and self.means is not None
        assert self.covariances is not None
        sd = np.sqrt(np.maximum(self.covariances[..., i, i], 0.0))
        return self.weights, self.means[..., i], np.broadcast_to(sd, self.weights.shape)

    def _bins(self, variable: str) -> tuple[np.ndarray, np.ndarray]:
        """Edges ``[n + 1]`` and the marginal probability of each bin ``[rows, n]``."""
        i = self._index(variable)
        assert self.masses is not None and self.edges is not None
        axes = tuple(1 + j for j in range(len(self.variables)) if j != i)
        return self.edges[variable], self.masses.sum(axis=axes) if axes else self.masses

    def _shape(self, values: np.ndarray) -> Any:
        """``[rows] + rest`` as ``batch + rest``; a number (a numpy float) when that is empty."""
        out = values.reshape(self.batch_shape + values.shape[1:])
        return out[()] if out.ndim == 0 else out

    # summaries ---------------------------------------------------------------------------------
    def mean(self, variable: str) -> Any:
        """The mean per batch row (a number when the question is not batched)."""
        if self.weights is not None:
            w, m, _ = self._gaussian(variable)
            return self._shape((w * m).sum(-1))
        edges, p = self._bins(variable)
        return self._shape(p @ ((edges[:-1] + edges[1:]) / 2))

    def sd(self, variable: str) -> Any:
        """The standard deviation per batch row (a number when not batched)."""
        if self.weights is not None:
            w, m, s = self._gaussian(variable)
            mean = (w * m).sum(-1, keepdims=True)
            return self._shape(np.sqrt(np.maximum((w * (s**2 + (m - mean) ** 2)).sum(-1), 0)))
        edges, p = self._bins(variable)
        mid, width = (edges[:-1] + edges[1:]) / 2, np.diff(edges)
        mean = p @ mid
        # exact for a density uniform within each bin
        second = p @ (mid**2 + width**2 / 12)
        return self._shape(np.sqrt(np.maximum(second - mean**2, 0.0)))

    def cdf(self, variable: str, x: Any) -> Any:
        """``P(variable <= x)``, shaped ``batch + shape of x`` (a number for a number when the
        question is not batched), as ``pdf`` and ``quantile``."""
        x = np.asarray(x, float)
        rows = int(np.prod(self.batch_shape))
        points = np.broadcast_to(x.reshape(1, -1), (rows, x.size))
        return self._shape(self._cdf(variable, points).reshape((rows,) + x.shape))

    def _cdf(self, variable: str, x: np.ndarray) -> np.ndarray:
        """CDF at ``x`` ``[rows, m]``."""
        if self.weights is not None:
            w, m, s = self._gaussian(variable)
            return _mixture_cdf(w[:, None, :], m[:, None, :], s[:, None, :], x)
        edges, p = self._bins(variable)
        cum = np.concatenate([np.zeros((p.shape[0], 1)), np.cumsum(p, axis=1)], axis=1)
        return np.stack([np.interp(x[r], edges, cum[r]) for r in range(p.shape[0])])

    def pdf(self, variable: str, x: Any) -> Any:
        """The marginal density at ``x``, shaped ``batch + shape of x`` (a number for a number
        when the question is not batched)."""
        given = np.asarray(x, float)
        rows = int(np.prod(self.batch_shape))
        return self._shape(self._pdf(variable, given.ravel()).reshape((rows,) + given.shape))

    def _pdf(self, variable: str, x: np.ndarray) -> np.ndarray:
        """The density at the points ``x`` ``[m]``, ``[rows, m]``."""
        if self.weights is not None:
            w, m, s = self._gaussian(variable)
            with np.errstate(divide="ignore", invalid="ignore"):
                z = (x[None, :, None] - m[:, None, :]) / s[:, None, :]
                comp = np.exp(-0.5 * z * z) / (s[:, None, :] * _SQRT_2PI)
            comp = np.where(s[:, None, :] > 0, comp, 0.0)
            return (w[:, None, :] * comp).sum(-1)
        edges, p = self._bins(variable)
        inside = (x >= edges[0]) & (x <= edges[-1])
        k = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, len(edges) - 2)
        return np.where(inside, p[:, k] / np.diff(edges)[k], 0.0)

    def quantile(self, variable: str, q: Any) -> Any:
        """The ``q``-quantile(s), shaped ``batch + shape of q`` (a number for a number when the
        question is not batched)."""
        q = np.asarray(q, float)
        if np.any((q < 0) | (q > 1)) or np.any(np.isnan(q)):
            raise QuestionError(f"quantiles must be in [0, 1], found {q.tolist()}")
        qs = np.atleast_1d(q).ravel()
        if not qs.size:
            return self._shape(np.zeros((int(np.prod(self.batch_shape)),) + q.shape))
        if self.weights is not None:
            w, m, s = self._gaussian(variable)
            rows = w.shape[0]
            lo = np.broadcast_to((m - 40 * s).min(-1)[:, None] - 1e-300, (rows, qs.size)).copy()
            hi = np.broadcast_to((m + 40 * s).max(-1)[:, None], (rows, qs.size)).copy()
            for _ in range(200):  # bisection to the float resolution of the interval
                mid = (lo + hi) / 2
                below = self._cdf(variable, mid) < qs[None, :]
                lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
                if np.all(hi - lo <= 4 * np.finfo(float).eps * np.maximum(1, np.abs(hi))):
                    break
            out = (lo + hi) / 2
            # the ends of a mixture of Gaussians are infinite, as scipy's ppf gives them
            out = np.where(qs[None, :] >= 1, np.inf, np.where(qs[None, :] <= 0, -np.inf, out))
        else:
            edges, p = self._bins(variable)
            cum = np.concatenate([np.zeros((p.shape[0], 1)), np.cumsum(p, axis=1)], axis=1)
            out = np.stack([np.interp(qs, cum[r], edges) for r in range(p.shape[0])])
        return self._shape(out.reshape((-1,) + q.shape))

    def map(self, variable: str) -> Any:
        """The mode of the marginal density per row (for several searched Gaussian variables
        with one component, the joint mode is the vector of these)."""
        if self.weights is not None:
            w, m, s = self._gaussian(variable)
            if w.shape[1] == 1:
                return self._shape(m[:, 0])
            return self._shape(_mixture_mode(w, m, s))
        edges, p = self._bins(variable)
        dens = p / np.diff(edges)
        return self._shape(((edges[:-1] + edges[1:]) / 2)[dens.argmax(axis=1)])

    def covariance(self) -> np.ndarray:
        """The covariance of the searched variables per row, ``batch + [d, d]`` (mixtures:
        the mixture's; bins: from the joint bins)."""
        if self.weights is not None:
            assert self.means is not None and self.covariances is not None
            w = self.weights[..., None, None]
            mean = (self.weights[..., None] * self.means).sum(1)
            dev = self.means - mean[:, None, :]
            cov = (w * (self.covariances + dev[..., :, None] * dev[..., None, :])).sum(1)
            return self._shape(cov)
        assert self.masses is not None and self.edges is not None
        rows, d = self.masses.shape[0], len(self.variables)
        mids = [(self.edges[v][:-1] + self.edges[v][1:]) / 2 for v in self.variables]
        grids = np.meshgrid(*mids, indexing="ij")
        p = self.masses.reshape(rows, -1)
        x = np.stack([g.ravel() for g in grids], axis=1)
        mean = p @ x
        cov = np.einsum("rn,ni,nj->rij", p, x, x) - mean[:, :, None] * mean[:, None, :]
        widths = [np.diff(self.edges[v]) for v in self.variables]
        for i in range(d):
            cov[:, i, i] += self._bins(self.variables[i])[1] @ (widths[i] ** 2 / 12)
        return self._shape(cov)

    # one point per row: where another program's term reads this answer (form: program) -----
    def log_pdf_at(self, variable: str, x: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """The log of the marginal density of flat row ``rows[i]`` at ``x[i]`` (``x`` and
        ``rows`` of one shape), computed in log space (a value far in the tail keeps its
        logarithm where the density itself underflows).

        >>> d = Density("P(X | S)", ("X",), (2,), np.zeros(2), weights=np.ones((2, 1)),
        ...             means=np.array([0.0, 3.0]).reshape(2, 1, 1),
        ...             covariances=np.ones((2, 1, 1, 1)))
        >>> d.log_pdf_at("X", np.array([0.0, 40.0]), np.array([0, 1])).round(4).tolist()
        [-0.9189, -685.4189]
        """
        x = np.asarray(x, float)
        if self.weights is None:
            edges, p = self._bins(variable)
            k = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, len(edges) - 2)
            inside = (x >= edges[0]) & (x <= edges[-1])
            with np.errstate(divide="ignore"):
                return np.where(inside, np.log(p[rows, k] / np.diff(edges)[k]), -np.inf)
        w, m, s = (a[rows] for a in self._gaussian(variable))
        at = x[..., None]
        with np.errstate(divide="ignore", invalid="ignore"):
            z = (at - m) / s
            log = np.where(s > 0, -0.5 * z * z - np.log(s) - 0.5 * _LOG_2PI,
                           np.where(at == m, np.inf, -np.inf))  # sd 0: a point mass
            log = np.where(w > 0, log + np.log(w), -np.inf)
            top = log.max(axis=-1, keepdims=True)
            top = np.where(np.isfinite(top), top, 0.0)
            return np.log(np.exp(log - top).sum(-1)) + top[..., 0]

    def cdf_at(self, variable: str, x: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """``P(variable <= x[i])`` in flat row ``rows[i]`` (``x`` and ``rows`` of one shape)."""
        x = np.asarray(x, float)
        if self.weights is not None:
            w, m, s = (a[rows] for a in self._gaussian(variable))
            return _mixture_cdf(w, m, s, x)
        edges, p = self._bins(variable)
        cum = np.concatenate([np.zeros((p.shape[0], 1)), np.cumsum(p, axis=1)], axis=1)
        k = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, len(edges) - 2)
        with np.errstate(invalid="ignore"):
            within = np.clip((x - edges[k]) / np.diff(edges)[k], 0.0, 1.0)
        return cum[rows, k] + within * p[rows, k]

    def quantile_at(self, variable: str, q: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """The ``q[i]``-quantile of flat row ``rows[i]`` (``q`` and ``rows`` of one shape, ``q``
        in [0, 1]): the inverse of :meth:`cdf_at`, by which a draw is made from the answer."""
        q = np.asarray(q, float)
        if self.weights is None:
            edges, p = self._bins(variable)
            cum = np.concatenate([np.zeros((p.shape[0], 1)), np.cumsum(p, axis=1)], axis=1)
            # the bin whose cumulative interval holds q (empty bins hold none)
            k = (cum[rows, 1:-1] < q[..., None]).sum(-1)
            mass = p[rows, k]
            with np.errstate(divide="ignore", invalid="ignore"):
                within = np.where(mass > 0, (q - cum[rows, k]) / mass, 0.0)
            return edges[k] + np.clip(within, 0.0, 1.0) * np.diff(edges)[k]
        w, m, s = (a[rows] for a in self._gaussian(variable))
        lo = (m - 40 * s).min(-1) - 1e-300
        hi = (m + 40 * s).max(-1)
        for _ in range(200):  # bisection to the float resolution of the interval
            mid = (lo + hi) / 2
            below = _mixture_cdf(w, m, s, mid) < q
            lo, hi = np.where(below, mid, lo), np.where(below, hi, mid)
            if np.all(hi - lo <= 4 * np.finfo(float).eps * np.maximum(1, np.abs(hi))):
                break
        return np.where(q >= 1, np.inf, np.where(q <= 0, -np.inf, (lo + hi) / 2))

    def summary(self, quantiles: tuple[float, ...] = QUANTILES) -> dict[str, dict[str, Any]]:
        """Mean, sd, quantiles and MAP of each searched variable (arrays over the batch)."""
        return {v: {"mean": self.mean(v), "sd": self.sd(v), "map": self.map(v),
                    "quantiles": dict(zip(quantiles, np.moveaxis(
                        self.quantile(v, np.array(quantiles)), -1, 0), strict=True))}
                for v in self.variables}

    def to_json(self) -> dict[str, Any]:
        summary = self.summary()
        out: dict[str, Any] = {
            "question": self.question,
            "variables": list(self.variables),
            "mean": {v: _plain(s["mean"]) for v, s in summary.items()},
            "sd": {v: _plain(s["sd"]) for v, s in summary.items()},
            "quantiles": {v: {f"{q:g}": _plain(x) for q, x in s["quantiles"].items()}
                          for v, s in summary.items()},
            "map": {v: _plain(s["map"]) for v, s in summary.items()},
            "density": self.kind,
            "log_evidence": _plain(self.log_evidence),
            "ablated": list(self.ablated),
            "method": self.method,
        }
        if self.ess is not None:
            out["ess"] = _plain(self.ess.reshape(self.batch_shape))
        if self.uncertainty is not None:
            out["uncertainty"] = self.uncertainty
        if self.resolution:
            out["bins"] = dict(self.resolution)
            out["error"] = {k: {v: _plain(e) for v, e in by.items()}
                            for k, by in self.error.items()}
        return out


def _plain(values: Any) -> Any:
    array = np.asarray(values, float)
    out = np.where(np.isfinite(array), array, np.nan).tolist()
    if isinstance(out, float):
        return None if out != out else out
    return _none(out)


def _none(values: list) -> list:
    return [_none(v) if isinstance(v, list) else (None if v != v else v) for v in values]


def _mixture_cdf(w: np.ndarray, m: np.ndarray, s: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``sum_k w_k Phi((x - m_k) / s_k)`` at ``x`` ``[...]`` for components ``[..., K]`` (a
    component of standard deviation 0 is a step at its mean)."""
    at = x[..., None]
    with np.errstate(divide="ignore", invalid="ignore"):
        z = (at - m) / s
    z = np.where(s > 0, z, np.where(at >= m, np.inf, -np.inf))
    return (w * special.ndtr(z)).sum(-1)


def _mixture_mode(w: np.ndarray, m: np.ndarray, s: np.ndarray) -> np.ndarray:
    """The global mode of 1-D Gaussian mixtures ``[rows, K]``: fixed-point (mean-shift)
    iterations started from every component's mean, the best end point kept. Mean-shift
    increases the density at every step, and a mode of a Gaussian mixture lies within the
    span of the means, so one start climbs to each mode that is a component's nearest."""
    s = np.where(s > 0, s, np.finfo(float).tiny)
    x = m.copy()  # [rows, starts]
    for _ in range(500):
        z = (x[:, :, None] - m[:, None, :]) / s[:, None, :]
        r = w[:, None, :] * np.exp(-0.5 * z * z) / s[:, None, :] ** 3
        new = (r * m[:, None, :]).sum(-1) / np.maximum(r.sum(-1), np.finfo(float).tiny)
        done = np.all(np.abs(new - x) <= 1e-13 * np.maximum(1, np.abs(x)))
        x = new
        if done:
            break
    z = (x[:, :, None] - m[:, None, :]) / s[:, None, :]
    dens = (w[:, None, :] * np.exp(-0.5 * z * z) / s[:, None, :]).sum(-1)
    return x[np.arange(x.shape[0]), dens.argmax(axis=1)]
