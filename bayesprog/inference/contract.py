"""Contraction of rescaled factors with cached opt_einsum expressions, and the exact log-space
elimination used for rows whose scaled contraction underflows."""

from __future__ import annotations

import heapq
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy.special import logsumexp

from bayesprog.inference.core import Factor
from bayesprog.inference.protocol import ProgramLike
from bayesprog.variables import discrete

#: Below this, a row's normaliser is recomputed in log space (underflow, or subnormal precision).
TINY = 1e-280
#: numpy's einsum names axes by letters: a step of :func:`eliminate` joins at most this many.
LETTERS = "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ"
#: numpy's einsum takes at most 32 operands in one call before numpy 2 (64 from it): a step of
#: :func:`eliminate` takes at most this many, whichever numpy is installed.
MAX_OPERANDS = 32


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


def eliminate(factors: list[tuple[tuple[str, ...], np.ndarray]], output: tuple[str, ...],
              cards: dict[str, int], limit: float) -> tuple[np.ndarray, int] | None:
    """The product of ``factors`` (probability tables over their axes) summed down to
    ``output`` (in its order), a new array, and the entries its steps joined (its operations),
    by variable elimination: each step sums out the variable whose factors join into the
    smallest table (of equal ones, the first to appear in the factors, so the same factors give
    the same arithmetic), in one einsum over those factors. The sizes wait in a heap, and a
    step recomputes only those of the variables it joined: choosing costs a logarithm per
    change, not a scan of every variable. None, before the step that would bring the entries
    its steps join past ``limit`` (their work, which bounds what they allocate), or that joins
    more axes or operands than one einsum takes. An output variable in no factor is uniform
    (ones)."""
    pool: dict[int, tuple[tuple[str, ...], np.ndarray]] = dict(enumerate(factors))
    holders: dict[str, dict[int, None]] = {}
    for i, (axes, _) in pool.items():
        for a in axes:
            holders.setdefault(a, {})[i] = None
    rank = {a: r for r, a in enumerate(a for a in holders if a not in output)}

    def joined_by(name: str) -> dict[str, None]:
        return {a: None for i in holders[name] for a in pool[i][0]}

    size_of = {a: math.prod(cards[b] for b in joined_by(a)) for a in rank}
    heap = [(size, rank[a], a) for a, size in size_of.items()]
    heapq.heapify(heap)
    made, work = len(pool), 0
    while heap:
        size, _, name = heapq.heappop(heap)
        if size_of.get(name) != size:
            continue  # eliminated, or its size changed since
        del size_of[name]
        joined = joined_by(name)
        taken = holders.pop(name)
        work += size
        if work > limit or len(joined) > len(LETTERS) or len(taken) > MAX_OPERANDS:
            return None
        letter = dict(zip(joined, LETTERS, strict=False))
        kept = tuple(a for a in joined if a != name)
        operands = [pool.pop(i) for i in taken]
        text = ",".join("".join(letter[a] for a in axes) for axes, _ in operands)
        result = np.einsum(text + "->" + "".join(letter[a] for a in kept),
                           *(table for _, table in operands))
        for a in kept:
            for i in taken:
                holders[a].pop(i, None)
            holders[a][made] = None
        pool[made] = (kept, result)
        made += 1
        for a in kept:
            if a in size_of:
                size_of[a] = math.prod(cards[b] for b in joined_by(a))
                heapq.heappush(heap, (size_of[a], rank[a], a))
    cards_out = [cards[a] for a in output]
    work += math.prod(cards_out)
    if work > limit:
        return None
    operands = list(pool.values())
    operands += [((a,), np.ones(card)) for a, card in zip(output, cards_out, strict=True)
                 if a not in holders]
    if not operands:
        return np.ones(cards_out), work
    if all(axes == output for axes, _ in operands):  # a product, entry by entry
        product = operands[0][1].copy()
        for _, table in operands[1:]:
            product *= table
        return product, work
    if len(operands) > MAX_OPERANDS:
        return None
    letter = dict(zip(output, LETTERS, strict=False))
    text = ",".join("".join(letter[a] for a in axes) for axes, _ in operands)
    found = np.einsum(text + "->" + "".join(letter[a] for a in output),
                      *(table for _, table in operands))
    return (found if found.flags.owndata else found.copy()), work  # never a program's table


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
