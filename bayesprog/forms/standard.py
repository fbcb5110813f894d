"""The standard parametric forms: table, categorical, uniform, normal, beta, gmm, dirac."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from bayesprog.forms.base import (
    Form,
    Param,
    ParamValue,
    TermContext,
    formula_values,
    positive,
    real,
    register_form,
    simplex,
    unit_interval,
)
from bayesprog.forms.estimators import (
    BetaEstimator,
    Estimator,
    GmmEstimator,
    NormalEstimator,
    TableEstimator,
)
from bayesprog.support.extras import LazyModule
from bayesprog.vocabulary.variables import Continuous, Discrete, Variable

#: scipy.special, imported by the first computation that reads it
special = LazyModule("scipy.special")

_LOG_2PI = float(np.log(2 * np.pi))


@register_form
class Categorical(Form):
    """``P(X = x | parents) = p[parents][x]``; ``probabilities`` may be a runtime input."""

    name = "categorical"
    child_kinds = ("discrete",)
    params = (
        Param(
            "probabilities",
            simplex,
            event_ndim=1,
            doc="one probability per child state (a list, or a mapping by child state), "
            "per parent configuration",
            keyed_by_child_states=True,
        ),
    )

    soft_evidence = True

    def estimator(self, child: Variable) -> Estimator | None:
        return TableEstimator(self.params[0].name) if child.is_discrete else None

    def event_shape(self, param: Param, child: Variable) -> tuple[int, ...] | None:
        return (child.card,) if isinstance(child, Discrete) else None

    def log_factor(self, ctx: TermContext) -> np.ndarray:
        p = ctx.param(self.params[0].name, 1)[:, 0]
        with np.errstate(divide="ignore"):
            log = np.log(p)
        # the child's axis (last) moved after the batch's
        return log.transpose((0, log.ndim - 1) + tuple(range(1, log.ndim - 1)))


@register_form
class Table(Categorical):
    """A conditional probability table: one row over the child's states per parent configuration."""

    name = "table"
    soft_evidence = False
    params = (
        Param(
            "table",
            simplex,
            event_ndim=1,
            doc="nested by parent states (mapping or list, in parent order), then one "
            "probability per child state",
            keyed_by_child_states=True,
        ),
    )


@register_form
class Uniform(Form):
    """The same value for every child value: ``1/card`` (discrete) or ``1/(high-low)``.

    On an unbounded support the uniform is improper; it is then the constant 1, which leaves
    every posterior unchanged.
    """

    name = "uniform"
    pointwise = True

    def log_factor(self, ctx: TermContext) -> np.ndarray:
        child = ctx.child
        if isinstance(child, Discrete):
            value = -np.log(child.card)
        else:
            value = -np.log(child.width) if np.isfinite(child.width) else 0.0
        return np.full((1,) + (1,) * len(ctx.axes), value)

    def cdf(self, ctx: TermContext) -> np.ndarray | None:
        low, high = _support(ctx.child)
        if not (np.isfinite(low) and np.isfinite(high)):
            return None  # improper: no distribution to integrate
        return np.clip((ctx.child_value() - low) / (high - low), 0.0, 1.0)

    def sample(self, params: Mapping[str, np.ndarray], child: Variable,
               u: np.ndarray) -> np.ndarray:
        assert isinstance(child, Continuous)
        if not np.isfinite(child.width):
            return super().sample(params, child, u)  # improper: nothing to draw from
        return child.low + u[..., 0] * child.width


@register_form
class Normal(Form):
    """``N(x; mean[parents], sigma[parents])`` (not truncated to the variable's support)."""

    name = "normal"
    pointwise = True
    child_kinds = ("continuous",)
    params = (
        Param("mean", real, doc="mean, a literal or a table keyed by parent states"),
        Param("sigma", positive, doc="standard deviation, > 0"),
    )
    mean_param, scale_param = "mean", "sigma"
    location_scale = ("mean", "sigma")
    quantile_sample = True

    def estimator(self, child: Variable) -> Estimator | None:
        return NormalEstimator()

    def log_factor(self, ctx: TermContext) -> np.ndarray:
        x, mu, sigma = ctx.child_value(), ctx.param("mean"), ctx.param("sigma")
        z = (x - mu) / sigma
        return -0.5 * z * z - np.log(sigma) - 0.5 * _LOG_2PI

    def cdf(self, ctx: TermContext) -> np.ndarray:
        return special.ndtr((ctx.child_value() - ctx.param("mean")) / ctx.param("sigma"))

    def sample(self, params: Mapping[str, np.ndarray], child: Variable,
               u: np.ndarray) -> np.ndarray:
        return params["mean"] + params["sigma"] * special.ndtri(u[..., 0])


@register_form
class Beta(Form):
    """``Beta(x; a[parents], b[parents])`` on [0, 1]."""

    name = "beta"
    pointwise = True
    quantile_sample = True
    child_kinds = ("continuous",)
    params = (
        Param("a", positive, doc="first shape parameter (alpha), > 0"),
        Param("b", positive, doc="second shape parameter (beta), > 0"),
    )

    def estimator(self, child: Variable) -> Estimator | None:
        return BetaEstimator()

    def check(self, child: Variable, parents: tuple[Variable, ...]) -> list[str]:
        problems = super().check(child, parents)
        low, high = _support(child)
        if not problems and (low < 0 or high > 1):
            problems.append(f"form 'beta' needs a support inside [0, 1], found "
                            f"[{low}, {high}] for {child.name!r}")
        return problems

    def log_factor(self, ctx: TermContext) -> np.ndarray:
        x, a, b = ctx.child_value(), ctx.param("a"), ctx.param("b")
        with np.errstate(divide="ignore", invalid="ignore"):
            out = np.broadcast_to(-special.betaln(a, b), np.broadcast_shapes(a.shape, b.shape, x.shape))
            # a shape parameter of 1 contributes nothing: its log term is skipped (cue profiles
            # such as Beta(1, 2.5) and Beta(4, 1) halve their work)
            out = _plus_xlog(out, a - 1, x, np.log, special.xlogy)
            out = _plus_xlog(out, b - 1, -x, np.log1p, special.xlog1py)
        if not (np.min(x, initial=0.0) < 0 or np.max(x, initial=1.0) > 1):  # (two passes)
            return out
        return np.where((x < 0) | (x > 1), -np.inf, out)

    def cdf(self, ctx: TermContext) -> np.ndarray:
        return special.betainc(ctx.param("a"), ctx.param("b"), np.clip(ctx.child_value(), 0.0, 1.0))

    def sample(self, params: Mapping[str, np.ndarray], child: Variable,
               u: np.ndarray) -> np.ndarray:
        return special.betaincinv(params["a"], params["b"], u[..., 0])


def _plus_xlog(out: np.ndarray, c: np.ndarray, v: np.ndarray, log: Any, xlog: Any) -> np.ndarray:
    """``out + c * log(v)`` with ``0 * log(0) = 0``: nothing to add where every ``c`` is 0,
    numpy's (vectorised) log where none is, scipy's ``scipy.special.xlogy``/``scipy.special.xlog1py`` for a mix."""
    if not np.any(c):
        return out
    if np.all(c):
        term = log(v)
        if np.broadcast_shapes(term.shape, np.shape(c), out.shape) != term.shape:
            return out + c * term
        term *= c  # (a new array of the result's shape: the product and the sum in place)
        term += out
        return term
    return out + xlog(c, v)


@register_form
class GaussianMixture(Form):
    """A Gaussian mixture with isotropic components (means may be runtime inputs).

    Two uses:

    * continuous child ``X``: ``P(x | parents) = sum_k w_k N(x; mean_k, sigma)``;
    * discrete child ``R`` and a grid parent ``O``: a potential
      ``P(R = r | O = o) = (1 - floor) sum_k w_k N_D(c(o); mean_{r,k}, sigma^2 I) + floor / V``,
      where ``c(o)`` are the cell's D coordinates (D = 2, or 3 in a volume) and ``V`` the grid's
      area (its volume). The ``floor``
      (a uniform component) makes the mixture modulate the other terms instead of vetoing every
      cell away from the means. This term is not normalised over ``R``.
    """

    name = "gmm"
    pointwise = True
    normalized = False
    params = (
        Param("means", real, event_ndim=1, doc="component means: [K] or, over a grid, [K, D]"),
        Param("sigma", positive, doc="isotropic standard deviation of every component"),
        Param("weights", simplex, event_ndim=1, default="equal", doc="component weights [K]"),
        Param("floor", unit_interval, default=0.0, doc="weight of a uniform component"),
    )
    title = "GMM"

    def estimator(self, child: Variable) -> Estimator | None:
        return GmmEstimator() if not child.is_discrete else None

    def is_normalized(self, child: Variable) -> bool:
        return not child.is_discrete  # a density over a real child; a potential over a grid

    def check(self, child: Variable, parents: tuple[Variable, ...]) -> list[str]:
        if child.is_discrete and not any(getattr(p, "coords", None) is not None for p in parents):
            return [
                f"form 'gmm' with a discrete child {child.name!r} needs a grid parent "
                f"(a variable whose states carry coordinates)"
            ]
        return []

    def check_params(self, params: Mapping[str, Any], child: Variable) -> list[tuple[str, str]]:
        means, weights = params.get("means"), params.get("weights")
        floor = params.get("floor")
        if (isinstance(floor, ParamValue) and np.any(floor.array > 0) and not child.is_discrete
                and not np.isfinite(child.width)):  # type: ignore[union-attr]
            return [("floor", "gmm parameter 'floor' needs a bounded support (a uniform over "
                     f"it), found {child.name!r} on [{child.low}, {child.high}]")]  # type: ignore[union-attr]
        if not isinstance(means, ParamValue) or not isinstance(weights, ParamValue):
            return []
        k = means.array.shape[means.array.ndim - self.event_ndim(self.params[0], child)]
        if weights.array.shape[-1] != k:
            return [("weights", f"gmm parameter 'weights': expected {k} weights (one per "
                     f"mean), found {weights.array.shape[-1]}")]
        return []

    @staticmethod
    def _separable(ctx: TermContext, grid: Any, gi: int, coords: np.ndarray, means: np.ndarray,
                   s: np.ndarray, floor: np.ndarray) -> np.ndarray | None:
        """A grid, one sigma per mixture, a floor > 0: the Gaussians factor along the axes, so
        the mixture over all cells is one outer product and one matrix product of per-axis terms
        per mixture (exact: where the product underflows, the floor dominates to double
        precision)."""
        shape = grid.grid_shape
        if (shape is None or len(shape) < 2 or means.shape[gi] != 1 or s.shape[-1] != 1
                or "weights" in ctx.params or not np.all(floor > 0) or floor.shape[gi] != 1):
            return None
        from bayesprog.forms.compiled import floored, gaussian_exponents

        dim = len(shape)
        m = np.take(means, 0, axis=gi)  # [b, ..other.., K, D]
        sig = s[..., 0]  # [b, ..other.., 1]
        on_grid = coords.reshape(*shape, dim)
        along = [on_grid[tuple(slice(None) if b == a else 0 for b in range(dim)) + (a,)]
                 for a in range(dim)]  # the coordinates of the cells along each axis
        lead, k = m.shape[:-2], m.shape[-2]
        rows = int(np.prod(lead, dtype=np.int64))
        deviation = np.ascontiguousarray(np.broadcast_to(sig[..., 0], lead)).reshape(rows)
        g = []  # per axis, exp(-0.5 * ((x - m) / sigma) ** 2): [.., K, n_a]
        for a, x in enumerate(along):
            term = np.empty((rows, k, len(x)))
            gaussian_exponents(np.ascontiguousarray(x, dtype=float),
                               np.ascontiguousarray(m[..., a]).reshape(rows, k), deviation, term)
            g.append(np.exp(term, out=term).reshape(lead + (k, len(x))))
        cells = int(np.prod(shape))
        # the outer product of the leading axes' terms holds K x (all cells but the last axis)
        # values: taken over a few components at a time, it never exceeds the mixture's size
        step = k if dim == 2 else max(1, shape[-1])
        mix: Any = 0.0
        for lo in range(0, k, step):
            head = g[0][..., lo:lo + step, :]
            for factor in g[1:-1]:  # [.., step, n_0 * .. * n_a]
                part = factor[..., lo:lo + step, :]
                head = (head[..., :, None] * part[..., None, :]).reshape(*head.shape[:-1], -1)
            product = np.swapaxes(head, -1, -2) @ g[-1][..., lo:lo + step, :]
            mix = product if lo == 0 else mix + product
        cell = grid.cell or 1.0
        f = np.take(floor, 0, axis=gi)[..., None]  # [b, ..other.., 1]
        # (1 - f) * mix / (k (2 pi sigma^2)^(D/2)) + f / V, then its log, in place
        divisor, keep, uniform = (
            np.ascontiguousarray(np.broadcast_to(np.asarray(v, float)[..., 0], lead)).reshape(rows)
            for v in (k * (2 * np.pi * sig**2) ** (dim / 2), 1 - f, f / (cells * cell**dim)))
        out = np.empty((rows, cells))
        floored(np.ascontiguousarray(mix).reshape(rows, cells), divisor, keep, uniform, out)
        # far from every mean the mixture is below the floor's last bit: the value there is
        # the floor's share itself, whose log is taken once
        floor = out == uniform[:, None]
        np.log(out, out=out, where=~floor)
        np.copyto(out, np.log(uniform)[:, None], where=floor)
        out = out.reshape(lead + (cells,))  # [b, ..other.., cells]
        return np.moveaxis(out[..., None], -2, gi)[..., 0]

    def keyable(self, child: Variable, parents: tuple[Variable, ...]) -> list[Discrete]:
        keys = [p for p in parents if isinstance(p, Discrete)]
        return ([child] if isinstance(child, Discrete) else []) + keys

    def event_ndim(self, param: Param, child: Variable) -> int:
        return 2 if param.name == "means" and child.is_discrete else param.event_ndim

    def log_factor(self, ctx: TermContext) -> np.ndarray:
        child = ctx.child
        sigma = ctx.param("sigma")
        floor = ctx.param("floor")
        if isinstance(child, Discrete):
            grid = next(p for p in ctx.parents if getattr(p, "coords", None) is not None)
            gi = 1 + ctx.axes.index(grid.name)
            # coordinates relative to the grid's centre: no cancellation far from the origin
            centre = grid.coords.mean(axis=0)  # type: ignore[union-attr]
            coords = grid.coords - centre  # type: ignore[union-attr]
            means = ctx.param("means", 2) - centre  # [b, ..axes.., K, D]
            dim = means.shape[-1]
            if coords.shape[1] != dim:
                raise ValueError(
                    f"gmm means have {dim} coordinates, grid {grid.name!r} has {coords.shape[1]}"
                )
            s = np.moveaxis(sigma, gi, -1)[..., None, :]  # [b, ..other.., 1, cells or 1]
            fast = self._separable(ctx, grid, gi, coords, means, s, floor)
            if fast is not None:
                return fast
            if means.shape[gi] == 1:
                # |c - m|^2 = |c|^2 + |m|^2 - 2 c.m, as one matrix product: [b, .., K, cells]
                m = np.take(means, 0, axis=gi)
                sq = (m**2).sum(-1)[..., None] + (coords**2).sum(-1) - 2 * (m @ coords.T)
                sq = np.maximum(sq, 0.0)
            else:  # means that vary by cell: the direct difference
                shape = [1] * (means.ndim - 2) + [dim]
                shape[gi] = coords.shape[0]
                diff = coords.reshape(shape)[..., None, :] - means
                sq = np.moveaxis((diff**2).sum(-1), gi, -1)  # [b, ..other.., K, cells]
            log_comp = -0.5 * sq / s**2 - dim * np.log(s) - 0.5 * dim * _LOG_2PI
            log_comp = np.moveaxis(np.expand_dims(log_comp, gi), -1, gi)[..., 0, :]
            # now [b, ..axes.. (grid axis = cells), K]
            cell = grid.cell or 1.0  # type: ignore[union-attr]
            area = coords.shape[0] * cell**dim
        else:
            means = ctx.param("means", 1)
            x = ctx.child_value()[..., None]
            s = sigma[..., None]
            log_comp = -0.5 * ((x - means) / s) ** 2 - np.log(s) - 0.5 * _LOG_2PI
            area = child.width
        k = log_comp.shape[-1]
        if "weights" in ctx.params:
            weights = ctx.param("weights", 1)
            if weights.shape[-1] != k:
                raise ValueError(f"gmm has {k} means but {weights.shape[-1]} weights")
        else:
            weights = np.full((1,) * (log_comp.ndim - 1) + (k,), 1.0 / k)
        with np.errstate(divide="ignore"):
            top = log_comp.max(axis=-1, keepdims=True)
            top = np.where(np.isfinite(top), top, 0.0)
            mix = np.log((np.exp(log_comp - top) * weights).sum(-1)) + top[..., 0]
            if not np.any(floor > 0):
                return mix
            if not np.isfinite(area):
                raise ValueError("gmm floor needs a bounded support or a grid")
            return np.logaddexp(np.log1p(-floor) + mix, np.log(floor) - np.log(area))

    def sample(self, params: Mapping[str, np.ndarray], child: Variable,
               u: np.ndarray) -> np.ndarray:
        if child.is_discrete:
            return super().sample(params, child, u)
        means = params["means"]
        k = means.shape[-1]
        weights = params["weights"] if "weights" in params else np.full(k, 1.0 / k)
        weights = np.broadcast_to(weights, means.shape)
        floor = params.get("floor", np.zeros(()))
        # the first uniform picks the floor or a component, the second the value within it
        pick = u[..., 0]
        in_floor = pick < floor
        rest = np.where(in_floor, 0.0, (pick - floor) / np.where(floor < 1, 1 - floor, 1))
        component = np.minimum((np.cumsum(weights, -1) <= rest[..., None]).sum(-1), k - 1)
        mean = np.take_along_axis(means, component[..., None], -1)[..., 0]
        value = mean + params["sigma"] * special.ndtri(u[..., 1])
        if np.any(in_floor):
            assert isinstance(child, Continuous)
            value = np.where(in_floor, child.low + u[..., 1] * child.width, value)
        return value



@register_form
class Dirac(Form):
    """A deterministic term: ``X = value`` exactly, ``value`` usually a formula of the parents
    (``value: "sqrt(X**2 + Y**2)"``).

    A real child is known once its parents are: it is not given as evidence (a noisy sensor of
    it is). A discrete child takes the state whose value the formula gives (a range's integer,
    an integer-named state, else the index of the state: ``value: "A == B"`` gives the second
    state of a two-state child where A and B agree): its term is a table of ones and zeros,
    and evidence on it is evidence on its parents (a coherence variable)."""

    name = "dirac"
    params = (Param("value", real, doc="the value, a number or a formula of the parents"),)
    mean_param = "value"  # and no noise: deterministic

    def log_factor(self, ctx: TermContext) -> np.ndarray:
        child = ctx.child
        if not isinstance(child, Discrete):
            raise ValueError(f"{child.name} is deterministic (form dirac): give evidence on "
                             "its parents, or on a noisy sensor of it, not on it")
        value = ctx.param("value")  # [b, ..axes..], of size 1 along the child's
        at = 1 + ctx.axes.index(child.name)
        own = formula_values(child)
        shape = [1] * value.ndim
        shape[at] = child.card
        hit = _is_state(value, own.reshape(shape))
        if not hit.any(axis=at).all():
            row = int(np.argwhere(~hit.any(axis=at))[0][0])
            rest = tuple(a for a in ctx.axes if a != child.name)
            raise ValueError(deterministic_problem(child, rest, np.take(value[row], 0, at - 1),
                                                   ctx.variables))
        return np.where(hit, 0.0, -np.inf)

    def cdf(self, ctx: TermContext) -> np.ndarray:
        return (ctx.child_value() >= ctx.param("value")).astype(float)

    def sample(self, params: Mapping[str, np.ndarray], child: Variable,
               u: np.ndarray) -> np.ndarray:
        return np.broadcast_to(params["value"], u.shape[:-1]).astype(float)


def deterministic_problem(child: Discrete, axes: tuple[str, ...], values: np.ndarray,
                          variables: Mapping[str, Variable]) -> str:
    """Why the values of a deterministic discrete term (over ``axes``) are not all values of
    its child's states (see :func:`~bayesprog.forms.base.formula_values`), or ''. ``values``
    may be of size 1 along axes it does not vary over."""
    own = formula_values(child)
    hit = _is_state(values[..., None], own)
    bad = ~hit.any(-1)
    if not bad.any():
        return ""
    index = tuple(int(i) for i in np.argwhere(bad)[0])
    at = ", ".join(f"{a}={variables[a].states[i]}"  # type: ignore[union-attr]
                   for a, i, n in zip(axes, index, values.shape, strict=True) if n > 1)
    shown = (f"{own[0]:g}, ..., {own[-1]:g}" if own.size > 6
             else ", ".join(f"{v:g}" for v in own))
    kind = ("the indices of its states" if child.values is None and child.kind != "grid"
            else "its values")
    return (f"the value {values[index]:g}{' for ' + at if at else ''} is not a state of "
            f"{child.name}: expected one of {kind} ({shown})")


def _is_state(values: np.ndarray, states: np.ndarray) -> np.ndarray:
    """Where ``values`` are the states' values ``states`` (broadcast together), to a relative
    1e-9 (a formula's arithmetic on the states' numbers)."""
    return np.abs(values - states) <= 1e-9 * np.maximum(1.0, np.abs(states))


def _support(var: Variable) -> tuple[float, float]:
    """The support of a continuous variable, or of a discretised one."""
    if isinstance(var, Discrete):
        return var.support if var.support is not None else (-np.inf, np.inf)
    return var.low, var.high
