"""The most likely sequence of states of a chain (Viterbi), its ties counted and broken as a
MAP question's are.

From the belief before the first step and each step's ``log P(x_t, y_t | x_t-1)``, the
max-product recursion finds ``argmax P(x_1..T, y_1..T)`` (the state before the first step
summed out, not maximised). Sequences whose probabilities are equal within the relative
tolerance of a MAP question (:data:`~bayesprog.inference.answers.TIE_RTOL`, compared step by
step as the recursion runs) tie. The recursion counts them: ``n_1(j) = 1`` and
``n_t(j) = sum of n_t-1(i)`` over the states ``i`` whose best path into ``j`` ties for the
best, so the number of tied sequences is the sum of ``n_T(j)`` over the tied last states.
One of them is drawn uniformly by the caller's generator, as a MAP question draws one of
its tied assignments (one integer below the count, never the first by index order): the
sequences are numbered by their last state, then the one before, and so on, and the number
drawn is read back through the counts.

>>> import numpy as np
>>> half = np.log(np.full((2, 2), 0.25))  # two states, every step alike: every sequence ties
>>> path, log_best, ties = most_likely_sequence(np.log([0.5, 0.5]), [half, half, half], 0)
>>> int(ties), round(float(np.exp(log_best)), 6)
(8, 0.015625)
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.special

from bayesprog.inference.answers import TIE_RTOL, row_generators

#: counts of tied sequences at or past this are kept as Python integers (a float holds every
#: integer below it exactly)
EXACT_FLOAT = 2**53


def most_likely_sequence(log_first: np.ndarray, logs: list[np.ndarray],
                         rng: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The most likely sequence, ``[T, batch...]`` state indices; its log-probability with the
    evidence ``[batch...]``; and the number of sequences that tie with it ``[batch...]``.

    ``log_first`` is the belief before the first step, ``[batch..., states]``; ``logs[t]``
    is ``log P(x_t, y_t | x_t-1)``, ``[batch..., before, after]``. ``rng``: a seed, a
    ``numpy.random.Generator``, or one of them per sequence of the batch, as for a MAP
    question. ``ties`` is an integer array (of Python integers past ``2**63`` sequences)."""
    batch = log_first.shape[:-1]
    cutoff = np.log1p(-TIE_RTOL)
    delta = log_first
    pointers: list[np.ndarray] = []  # step t >= 1: the best state before
    near: list[np.ndarray] = []  # step t >= 1: every state before that ties for the best
    counts: list[np.ndarray] = [np.ones(log_first.shape)]  # tied beginnings ending at a state
    log_best = np.zeros(batch)
    for t, log_step in enumerate(logs):
        scores = delta[..., :, None] + log_step
        if t == 0:
            delta = scipy.special.logsumexp(scores, axis=-2)
        else:
            delta = np.max(scores, axis=-2)
            pointers.append(np.argmax(scores, axis=-2))
            tied = scores >= delta[..., None, :] + cutoff
            near.append(tied)
            counts.append(np.where(tied, counts[-1][..., :, None], 0.0).sum(axis=-2))
        top = np.max(delta, axis=-1, keepdims=True)
        log_best = log_best + top[..., 0]
        # a row of probability zero stays -inf (every sequence ties there, as in a MAP)
        with np.errstate(invalid="ignore"):
            delta = np.where(np.isfinite(top), delta - top, -np.inf)
    last = delta >= np.max(delta, axis=-1, keepdims=True) + cutoff
    total = np.where(last, counts[-1], 0.0).sum(axis=-1)
    path = [np.argmax(delta, axis=-1)]
    for t in range(len(logs) - 1, 0, -1):
        path.append(np.take_along_axis(pointers[t - 1], path[-1][..., None], -1)[..., 0])
    indices = np.stack(path[::-1]).reshape(len(logs), -1)
    ties: list[int] = [1] * int(np.prod(batch))
    flat_total = total.reshape(-1)
    tied_rows = np.flatnonzero(flat_total > 1)
    if tied_rows.size:
        gens = row_generators(rng, flat_total.size)
        flat_last = last.reshape(-1, last.shape[-1])
        flat_near = [n.reshape(-1, *n.shape[-2:]) for n in near]
        flat_counts = [c.reshape(-1, c.shape[-1]) for c in counts]
        for row in tied_rows:
            row_near = [n[row] for n in flat_near]
            if flat_total[row] < EXACT_FLOAT:
                # a state past the count is on no tied sequence, never read
                row_counts = [np.minimum(c[row], EXACT_FLOAT).astype(np.int64)
                              for c in flat_counts]
            else:
                row_counts = _exact_counts(row_near, flat_last.shape[-1])
            ties[row] = int(np.where(flat_last[row], row_counts[-1], 0).sum())
            number = _uniform_below(gens[row], ties[row])
            indices[:, row] = _unrank(number, flat_last[row], row_near, row_counts)
    kind = np.int64 if max(ties) < 2**63 else object
    return (indices.reshape((len(logs), *batch)), log_best,
            np.array(ties, dtype=kind).reshape(batch))


def _exact_counts(near: list[np.ndarray], states: int) -> list[np.ndarray]:
    """The counts of tied beginnings of one sequence as Python integers (past what a float
    holds exactly)."""
    counts = [np.array([1] * states, dtype=object)]
    for tied in near:
        counts.append(np.where(tied, counts[-1][:, None], 0).sum(axis=0))
    return counts


def _uniform_below(gen: np.random.Generator, n: int) -> int:
    """An integer drawn uniformly from ``0..n-1`` (``n`` may be past what numpy draws)."""
    if n < 2**63:
        return int(gen.integers(n))
    bits = n.bit_length()
    while True:  # rejection: fewer than two draws on average
        number = int.from_bytes(gen.bytes((bits + 7) // 8), "little") >> (-bits % 8)
        if number < n:
            return number


def _unrank(number: int, last: np.ndarray, near: list[np.ndarray],
            counts: list[np.ndarray]) -> np.ndarray:
    """The tied sequence of rank ``number`` of one row: its last state first, each block of
    sequences ending at a state as long as the tied beginnings that end there."""
    state, number = _pick(number, np.flatnonzero(last), counts[-1])
    path = [state]
    for t in range(len(near) - 1, -1, -1):
        state, number = _pick(number, np.flatnonzero(near[t][:, state]), counts[t])
        path.append(state)
    return np.array(path[::-1])


def _pick(number: int, candidates: np.ndarray, counts: np.ndarray) -> tuple[int, int]:
    for state in candidates:
        block = int(counts[state])
        if number < block:
            return int(state), number
        number -= block
    raise AssertionError("a rank past the count of tied sequences")
