"""The per-cell cue fields of pi_tar, batched over runs (leading axes).

* uncertainty U, eq. (11): entropy of the cell's material posterior / log(number of materials);
* saliency S, eq. (12): a 3x3 Sobel of the *perceived* stimulus d(v) = P(M_v = target material),
  taken over the cells that have been probed only (see :func:`saliency`);
  S = max(|s_x|, |s_y|, |s_z|) / s_norm, with s_norm = 4 (the largest response on a [0, 1] map);
* inhibition I, eq. (10): I(d) = 1 - f(d) / max f with the Beta kernel
  f(d) = d^(alpha-1) (1-d)^(beta-1), d = distance to the last probed cell / workspace diagonal.
  (The paper prints (1-d)^(1-beta), which diverges at d = 1; we read it as the Beta kernel.)
"""

from __future__ import annotations

from typing import cast

import numpy as np
from scipy.special import xlog1py, xlogy

from runner.attention._kernels import perceived_sobel_2d

INHIBITION_ALPHA = 1.01
INHIBITION_BETA = 9.0


def uncertainty(posterior: np.ndarray) -> np.ndarray:
    """Eq. (11): normalised entropy of ``posterior[..., materials]``, in [0, 1]."""
    k = posterior.shape[-1]
    h = -xlogy(posterior, posterior).sum(axis=-1)
    return np.clip(h / np.log(k), 0.0, 1.0)


def _slices(ndim: int, axis: int, part: slice) -> tuple[slice, ...]:
    index = [slice(None)] * ndim
    index[axis] = part
    return tuple(index)


def _box_sum(a: np.ndarray, axes: list[int], weights: tuple[float, float, float]) -> np.ndarray:
    """Along each of ``axes`` (padded by one on both sides), the weighted sum of each cell's
    three neighbours; those axes lose their padding."""
    for axis in axes:
        n = a.shape[axis] - 2
        a = cast(np.ndarray, sum(w * a[_slices(a.ndim, axis, slice(k, k + n))]
                                 for k, w in enumerate(weights) if w))
    return a


def _line_means(values: np.ndarray, weights: np.ndarray, axis: int, dims: int
                ) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per cell, the (1, 2, 1)-weighted mean of ``values`` over the weighted cells of each of
    the three lines (offsets -1, 0, +1 along ``axis``) of its 3^dims neighbourhood, and whether
    that line has any weight. Cells outside the grid have no weight."""
    pad = [(0, 0)] * (values.ndim - dims) + [(1, 1)] * dims
    w = np.pad(weights.astype(float), pad)
    num = np.pad(np.where(weights, values, 0.0), pad)
    others = [values.ndim + a for a in range(-dims, 0) if a != axis]
    num, den = _box_sum(num, others, (1.0, 2.0, 1.0)), _box_sum(w, others, (1.0, 2.0, 1.0))
    axis = values.ndim + axis
    n = values.shape[axis]
    out = []
    for k in range(3):
        part = _slices(values.ndim, axis, slice(k, k + n))
        line_num, line_den = num[part], den[part]
        has = line_den > 0.5  # weights are whole numbers: a line has weight >= 1 or none
        out.append((np.divide(line_num, line_den, out=np.zeros_like(line_num), where=has), has))
    return out


def _near(mask: np.ndarray, dims: int) -> np.ndarray:
    """Cells with a marked cell in their 3^dims neighbourhood."""
    pad = [(0, 0)] * (mask.ndim - dims) + [(1, 1)] * dims
    near = np.pad(mask, pad)
    for axis in range(mask.ndim - dims, mask.ndim):
        n = near.shape[axis] - 2
        near = (near[_slices(near.ndim, axis, slice(0, n))]
                | near[_slices(near.ndim, axis, slice(1, n + 1))]
                | near[_slices(near.ndim, axis, slice(2, n + 2))])
    return near


def saliency(target_map: np.ndarray, perceived: np.ndarray | None = None,
             dims: int = 2, kernel: bool = True) -> np.ndarray:
    """Eq. (12): saliency of the perceived stimulus, ``[..., nx, ny(, nz)]`` -> same, in [0, 1].

    ``target_map`` is the perceived stimulus for the task's material (d(v) in [0, 1]) and
    ``perceived`` marks the cells that have been probed (every cell when None). Along each grid
    axis the Sobel kernel compares the two lines of the cell's 3x3 neighbourhood on either side
    of it, each a (1, 2, 1)-weighted sum; divided by s_norm = 4 this is the difference of the two
    lines' weighted means. Here each line's mean runs over its *perceived* cells only, and a line
    with none is replaced by the centre line, as the standard Sobel replicates the centre line at
    the edge of an image (cells outside the grid are not perceived); along an axis with fewer
    than two perceived lines there is nothing to compare. So the frontier between probed and
    unprobed cells is not salient, a perceived change of material is, and so are the unprobed
    cells that continue a perceived border: they lie between perceived cells of the target
    material and perceived cells of another. Inside the grid, with every cell perceived, this
    is the standard Sobel.

    Where the neighbourhood holds perceived cells but nothing to compare, the saliency is not
    observed (NaN: the term is marginalised); where it holds no perceived cell, the map there is
    the uniform prior, whose Sobel response is 0. ``dims`` = 3 adds s_z for a 3-D grid. On 2-D
    grids a compiled kernel computes the same numbers (``kernel=False``: the array version).

    >>> d = np.array([[1.0, 1.0, 0.0, 0.0],
    ...               [1.0, 1.0, 0.0, 0.0],
    ...               [0.0, 0.0, 0.0, 0.0]])
    >>> probed = np.array([[True, True, True, False],
    ...                    [True, False, False, False],
    ...                    [False, False, False, False]])
    >>> saliency(d, probed).round(2)
    array([[ 0.,  1.,  1., nan],
           [ 0.,  1.,  1., nan],
           [nan, nan,  0.,  0.]])
    """
    d = np.asarray(target_map, dtype=float)
    mask = np.ones(d.shape, bool) if perceived is None else \
        np.broadcast_to(np.asarray(perceived, bool), d.shape)
    if np.isnan(d[mask]).any():
        raise ValueError("saliency: the map is NaN at a perceived cell")
    if dims == 2 and kernel and d.size:
        flat = (-1, *d.shape[-2:])
        return perceived_sobel_2d(np.ascontiguousarray(d.reshape(flat)),
                                  np.ascontiguousarray(mask.reshape(flat))).reshape(d.shape)
    best = np.zeros(d.shape)
    compared_any = np.zeros(d.shape, bool)
    for axis in range(-dims, 0):
        (lo, has_lo), (mid, has_mid), (hi, has_hi) = _line_means(d, mask, axis, dims)
        upper = np.where(has_hi, hi, mid)
        lower = np.where(has_lo, lo, mid)
        compared = (has_lo.astype(int) + has_mid + has_hi) >= 2
        np.maximum(best, np.where(compared, np.abs(upper - lower), 0.0), out=best)
        compared_any |= compared
    near = _near(mask, dims)
    return np.where(compared_any, np.clip(best, 0.0, 1.0), np.where(near, np.nan, 0.0))


def perceived_border(target_probability: np.ndarray, perceived: np.ndarray,
                     dims: int = 2) -> np.ndarray:
    """The probed cells on a perceived border: perceived as the target material (d >= 1/2) with
    a probed neighbour (3^dims neighbourhood) perceived as another, or the reverse."""
    mask = np.asarray(perceived, bool)
    target = (np.asarray(target_probability) >= 0.5) & mask
    return mask & np.where(target, _near(mask & ~target, dims), _near(target, dims))


def _log_kernel(d: np.ndarray, alpha: float, beta: float) -> np.ndarray:
    with np.errstate(divide="ignore"):
        return xlogy(alpha - 1, d) + xlog1py(beta - 1, -d)


def inhibition(
    centres: np.ndarray,
    last: np.ndarray,
    diagonal: float,
    alpha: float = INHIBITION_ALPHA,
    beta: float = INHIBITION_BETA,
) -> np.ndarray:
    """Eq. (10) for every cell: ``centres`` [cells, dims], ``last`` [runs, dims] -> [runs, cells].

    1 at the last probed cell, falling to 0 at distance ``(alpha-1)/(alpha+beta-2)`` of the
    diagonal, then rising back towards 1 far away (a locality prior that also inhibits return).
    """
    d = np.linalg.norm(centres[None, :, :] - last[:, None, :], axis=-1) / diagonal
    return inhibition_at_distance(d, alpha, beta)


def inhibition_at_distance(d: np.ndarray, alpha: float = INHIBITION_ALPHA,
                           beta: float = INHIBITION_BETA) -> np.ndarray:
    """Eq. (10) at distances ``d`` already divided by the workspace's diagonal."""
    d = np.clip(d, 0.0, 1.0)
    mode = (alpha - 1) / (alpha + beta - 2)
    log_max = _log_kernel(np.asarray(mode), alpha, beta)
    return np.clip(1.0 - np.exp(_log_kernel(d, alpha, beta) - log_max), 0.0, 1.0)
