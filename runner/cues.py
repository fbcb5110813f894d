"""The per-cell cue fields of pi_tar, batched over runs (leading axis).

* uncertainty U, eq. (11): entropy of the cell's material posterior / log(number of materials);
* saliency S, eq. (12): 3x3 Sobel of the map d(v) = P(M_v = target material);
  S = max(|s_x|, |s_y|) / 4 (4 is the largest Sobel response on a [0, 1] map); s_z exists in 3D only;
* inhibition I, eq. (10): I(d) = 1 - f(d) / max f with the Beta kernel
  f(d) = d^(alpha-1) (1-d)^(beta-1), d = distance to the last probed cell / workspace diagonal.
  (The paper prints (1-d)^(1-beta), which diverges at d = 1; we read it as the Beta kernel.)
"""

from __future__ import annotations

import numpy as np
from scipy.special import xlog1py, xlogy

SOBEL_NORM = 4.0
INHIBITION_ALPHA = 1.01
INHIBITION_BETA = 9.0


def uncertainty(posterior: np.ndarray) -> np.ndarray:
    """Eq. (11): normalised entropy of ``posterior[..., materials]``, in [0, 1]."""
    k = posterior.shape[-1]
    h = -xlogy(posterior, posterior).sum(axis=-1)
    return np.clip(h / np.log(k), 0.0, 1.0)


def sobel(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """3x3 Sobel responses (s_x along axis -2, s_y along axis -1), edges replicated."""
    p = np.pad(d, [(0, 0)] * (d.ndim - 2) + [(1, 1), (1, 1)], mode="edge")
    nx, ny = d.shape[-2:]

    def at(dx: int, dy: int) -> np.ndarray:
        return p[..., 1 + dx : 1 + dx + nx, 1 + dy : 1 + dy + ny]

    sx = (at(1, -1) + 2 * at(1, 0) + at(1, 1)) - (at(-1, -1) + 2 * at(-1, 0) + at(-1, 1))
    sy = (at(-1, 1) + 2 * at(0, 1) + at(1, 1)) - (at(-1, -1) + 2 * at(0, -1) + at(1, -1))
    return sx, sy


def saliency(target_probability: np.ndarray) -> np.ndarray:
    """Eq. (12) on a map ``[..., nx, ny]`` of P(M = target material), in [0, 1]."""
    sx, sy = sobel(target_probability)
    return np.clip(np.maximum(np.abs(sx), np.abs(sy)) / SOBEL_NORM, 0.0, 1.0)


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
    """Eq. (10) for every cell: ``centres`` [cells, 2], ``last`` [runs, 2] -> [runs, cells].

    1 at the last probed cell, falling to 0 at distance ``(alpha-1)/(alpha+beta-2)`` of the
    diagonal, then rising back towards 1 far away (a locality prior that also inhibits return).
    """
    d = np.linalg.norm(centres[None, :, :] - last[:, None, :], axis=-1) / diagonal
    d = np.clip(d, 0.0, 1.0)
    mode = (alpha - 1) / (alpha + beta - 2)
    log_max = _log_kernel(np.asarray(mode), alpha, beta)
    return np.clip(1.0 - np.exp(_log_kernel(d, alpha, beta) - log_max), 0.0, 1.0)
