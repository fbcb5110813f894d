"""The compiled loop of Gibbs sampling (numba): the sweeps of every row's chain over a block of
uniform draws, each variable drawn from the product of its factors at the others' states.

The factors are held flat (:func:`flatten`): their logs one after another, and for each the
offset of its first entry, the stride of its rows (0 when it has no rows' axis) and, per axis,
the variable and the stride; each variable lists the factors it is in with its own stride
there. A row's chain reads only its own state and draws, so the rows are swept one after
another, each through the whole block: the same draws give the same states as sweeping the
variables of every row at once.

Imported at the first use (numba takes a while to load).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numba import njit

#: a question's factors as :func:`sweep` reads them: the logs, each factor's offset, row stride
#: and first axis, each axis's variable and stride, each variable's first factor, and its
#: factors with its stride in each
Flat = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
             np.ndarray, np.ndarray]


def flatten(factors: Sequence, position: dict[str, int], unknown: int) -> Flat:
    """``factors`` (each with ``axes``, ``log`` and ``batched``) in the flat form of the
    module, their axes numbered by ``position`` among ``unknown`` variables."""
    logs, base, row_stride, axes_start, axis_var, axis_stride = [], [], [], [0], [], []
    homes: list[list[tuple[int, int]]] = [[] for _ in range(unknown)]
    at = 0
    for f_index, f in enumerate(factors):
        log = np.ascontiguousarray(f.log, dtype=np.float64)
        strides = [s // log.itemsize for s in log.strides]
        lead = 1 if f.batched else 0
        base.append(at)
        row_stride.append(strides[0] if f.batched and log.shape[0] > 1 else 0)
        for k, name in enumerate(f.axes):
            axis_var.append(position[name])
            axis_stride.append(strides[lead + k])
            homes[position[name]].append((f_index, strides[lead + k]))
        axes_start.append(len(axis_var))
        logs.append(log.ravel())
        at += log.size
    home_start = np.cumsum([0] + [len(h) for h in homes])
    home = [pair for h in homes for pair in h]
    return (np.concatenate(logs) if logs else np.zeros(0),
            np.asarray(base, np.int64), np.asarray(row_stride, np.int64),
            np.asarray(axes_start, np.int64), np.asarray(axis_var, np.int64),
            np.asarray(axis_stride, np.int64), home_start.astype(np.int64),
            np.asarray([f for f, _ in home], np.int64).reshape(-1),
            np.asarray([s for _, s in home], np.int64).reshape(-1))


@njit(cache=True)
def sweep(state: np.ndarray, cards: np.ndarray, uniforms: np.ndarray, logs: np.ndarray,
          base: np.ndarray, row_stride: np.ndarray, axes_start: np.ndarray,
          axis_var: np.ndarray, axis_stride: np.ndarray, home_start: np.ndarray,
          home_factor: np.ndarray, home_stride: np.ndarray, first_step: int, burn_in: int,
          thin: int, kept: int, keep: np.ndarray, searched: np.ndarray,
          searched_size: np.ndarray) -> int:
    """Run ``uniforms.shape[0]`` sweeps (steps ``first_step`` on) of each row's chain over
    ``state`` [rows, variables]; the sweeps past ``burn_in``, one in ``thin``, write the cell of
    the ``searched`` variables (numbered with ``searched_size``, as ``ravel_multi_index``) into
    ``keep`` from row ``kept`` on, while it has room. Returns the rows of ``keep`` written."""
    rows, variables = state.shape
    block = uniforms.shape[0]
    samples = keep.shape[0]
    log = np.empty(max(cards.max(), 1) if cards.size else 1)
    written = kept
    for r in range(rows):
        written = kept
        for b in range(block):
            for j in range(variables):
                card = cards[j]
                for s in range(card):
                    log[s] = 0.0
                for h in range(home_start[j], home_start[j + 1]):
                    f = home_factor[h]
                    offset = base[f] + r * row_stride[f]
                    for a in range(axes_start[f], axes_start[f + 1]):
                        if axis_var[a] != j:
                            offset += state[r, axis_var[a]] * axis_stride[a]
                    stride = home_stride[h]
                    for s in range(card):
                        log[s] += logs[offset + s * stride]
                top = log[0]
                for s in range(1, card):
                    if log[s] > top:
                        top = log[s]
                if not np.isfinite(top):
                    continue
                norm = 0.0
                for s in range(card):
                    norm += np.exp(log[s] - top)
                    log[s] = norm  # the cumulative sum
                if not norm > 0:
                    continue
                bound = uniforms[b, r, j] * norm
                choice = 0
                for s in range(card):
                    if log[s] < bound:
                        choice += 1
                state[r, j] = min(choice, card - 1)
            step = first_step + b
            if step >= burn_in and (step - burn_in) % thin == 0 and written < samples:
                cell = 0
                for i in range(searched.size):
                    cell = cell * searched_size[i] + state[r, searched[i]]
                keep[written, r] = cell
                written += 1
    return written
