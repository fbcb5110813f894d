"""The compiled loop (numba) of the physics presses' contact: where each press of a batch must
have its contact set again, and the contact there, as :meth:`runner.world.physics.Scene.contact`
computes it point by point (the same operations in the same order). Imported at the first
batch of presses (numba takes a while to load)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def contact_updates(x: np.ndarray, y: np.ndarray, depth: np.ndarray, at: np.ndarray,
                    half_sample: float, fingertip: float, cell: float, nx: int, ny: int,
                    disc: np.ndarray, cell_contact: np.ndarray, materials: np.ndarray,
                    variants: np.ndarray, slopes: np.ndarray, spacing: float, samples: int,
                    least_friction: float, out: np.ndarray) -> np.ndarray:
    """For each press i at (``x[i]``, ``y[i]``) pressed ``depth[i]`` in: whether its contact,
    last set at ``at[i]`` (x, y, depth), is to be set again (it moved half a relief sample
    along x, or its depth changed by a twentieth), and then its (stiffness, damping,
    friction) in ``out[i]`` and the new ``at[i]``: each cell's under the points ``disc`` of the
    contact disc (radius sqrt(R depth), at least a tenth of the fingertip's) averaged, the
    friction raised by the relief's slope under the centre."""
    moved = np.zeros(x.size, dtype=np.bool_)
    for i in range(x.size):
        if not (abs(x[i] - at[i, 0]) > half_sample
                or abs(depth[i] - at[i, 2]) > 0.05 * abs(at[i, 2]) + 1e-5):
            continue
        moved[i] = True
        radius = max(math.sqrt(fingertip * max(depth[i], 0.0)), fingertip / 10)
        k = b = mu = 0.0
        for p in range(disc.shape[0]):
            px = min(max((x[i] + radius * disc[p, 0]) // cell, 0.0), nx - 1.0)
            py = min(max((y[i] + radius * disc[p, 1]) // cell, 0.0), ny - 1.0)
            under = int(px) * ny + int(py)
            k += cell_contact[under, 0]
            b += cell_contact[under, 1]
            mu += cell_contact[under, 2]
        count = disc.shape[0]
        ix = min(max(int(x[i] // cell), 0), nx - 1)
        iy = min(max(int(y[i] // cell), 0), ny - 1)
        centre = ix * ny + iy
        u = int((x[i] - ix * cell) / spacing) % samples
        v = int((y[i] - iy * cell) / spacing) % samples
        slope = slopes[materials[centre], variants[centre], u, v]
        out[i, 0] = k / count
        out[i, 1] = b / count
        out[i, 2] = max(mu / count + slope, least_friction)
        at[i, 0], at[i, 1], at[i, 2] = x[i], y[i], depth[i]
    return moved
