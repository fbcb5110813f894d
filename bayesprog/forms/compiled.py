"""Compiled loops (numba) of the forms' arithmetic on large arrays, where numpy would make a
pass over memory per operation: each computes what the numpy expression it stands for
computes, operation by operation in the same order (no fused multiply-add, no reassociation),
so the same numbers to the bit. The transcendental functions stay numpy's, applied to their
results in place. Imported at the first use (numba takes a while to load)."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def gaussian_exponents(x: np.ndarray, means: np.ndarray, sigma: np.ndarray,
                       out: np.ndarray) -> None:
    """``out[b, k, i] = -0.5 * ((x[i] - means[b, k]) / sigma[b]) ** 2``: the exponents of
    isotropic Gaussians with means ``means`` [B, K] (one coordinate) and deviations ``sigma``
    [B] at the coordinates ``x`` [n], as ``-0.5 * ((x - m) / s) ** 2`` computes them."""
    for b in range(means.shape[0]):
        s = sigma[b]
        for k in range(means.shape[1]):
            m = means[b, k]
            for i in range(x.size):
                z = (x[i] - m) / s
                out[b, k, i] = -0.5 * (z * z)


@njit(cache=True)
def floored(mix: np.ndarray, divisor: np.ndarray, keep: np.ndarray, floor: np.ndarray,
            out: np.ndarray) -> None:
    """``out[b, c] = keep[b] * ((0.0 + mix[b, c]) / divisor[b]) + floor[b]``: a mixture
    ``mix`` [B, C] normalised by ``divisor`` and weighted by ``keep`` beside a uniform of
    weight ``floor``, as ``keep * ((0.0 + mix) / divisor) + floor`` computes it."""
    for b in range(mix.shape[0]):
        d, w, f = divisor[b], keep[b], floor[b]
        for c in range(mix.shape[1]):
            out[b, c] = w * ((0.0 + mix[b, c]) / d) + f
