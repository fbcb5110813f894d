"""Contraction of rescaled factors with cached opt_einsum expressions, and the exact log-space
elimination used for rows whose scaled contraction underflows."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy.special import logsumexp

from bayesprog.inference.core import Factor
from bayesprog.inference.protocol import ProgramLike
from bayesprog.variables import discrete

#: Below this, a row's normaliser is recomputed in log space (underflow, or subnormal precision).
TINY = 1e-280


def contract(program: ProgramLike, operands: list[Factor], searched: tuple[str, ...],
             batched_out: bool, size: int) -> np.ndarray:
    """Contract the (rescaled) ``operands`` down to ``searched``, with a batch axis of ``size``
    rows when ``batched_out``; searched variables without a factor are uniform."""
    if not operands:
        cards = tuple(discrete(program.variables[v]).card for v in searched)
        return np.ones(((size,) if batched_out else ()) + cards)
    present = {a for f in operands for a in f.axes}
    missing = [v for v in searched if v not in present]
    if missing:  # a searched variable with no factor left: uniform over its states
        for v in missing:
            operands.append(Factor((v,), np.ones(discrete(program.variables[v]).card), False))
    if batched_out and not any(f.batched for f in operands):
        operands.append(Factor((), np.ones(size), True))
    expr = program.inference_cache.plans.get(operands, searched, batched_out)
    return expr(*(f.log for f in operands))


def log_contract(factors: list[tuple[tuple[str, ...], np.ndarray]],
                 output: tuple[str, ...]) -> np.ndarray:
    """Exact log-space variable elimination, for rows whose scaled contraction underflowed."""
    pool = [(tuple(a), np.asarray(v, dtype=float)) for a, v in factors]
    names = {a for axes, _ in pool for a in axes} - set(output)
    while names:
        var = min(names, key=lambda n: len({a for axes, _ in pool if n in axes for a in axes}))
        names.discard(var)
        take = [f for f in pool if var in f[0]]
        pool = [f for f in pool if var not in f[0]]
        axes, arr = _log_product(take)
        pool.append((tuple(a for a in axes if a != var), logsumexp(arr, axis=axes.index(var))))
    axes, arr = _log_product(pool, output)
    return arr


def _log_product(factors: list[tuple[tuple[str, ...], np.ndarray]],
                 order: Sequence[str] | None = None) -> tuple[tuple[str, ...], np.ndarray]:
    axes = list(order) if order is not None else []
    for f_axes, _ in factors:
        axes += [a for a in f_axes if a not in axes]
    total: Any = 0.0
    for f_axes, arr in factors:
        perm = [f_axes.index(a) for a in axes if a in f_axes]
        shape = [arr.shape[f_axes.index(a)] if a in f_axes else 1 for a in axes]
        total = total + arr.transpose(perm).reshape(shape)
    total = np.asarray(total, dtype=float)
    if total.ndim < len(axes):
        total = total.reshape((1,) * len(axes))
    return tuple(axes), total
