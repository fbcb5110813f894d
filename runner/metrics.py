"""Exploration metrics: Gamma (eq. 16) and visit counts."""

from __future__ import annotations

import numpy as np


class BorderDistance:
    """Gamma, eq. (16): sum over ground-truth border cells of the distance (metres) to the
    nearest probed cell, kept incrementally as cells are probed (one update per step).

    >>> centres = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]])
    >>> g = BorderDistance(centres, border=np.array([True, False, True]), runs=1)
    >>> g.probe(np.array([1])).tolist()
    [2.0]
    >>> g.probe(np.array([0])).tolist()
    [1.0]
    """

    def __init__(self, centres: np.ndarray, border: np.ndarray, runs: int):
        self.points = centres[border.ravel()]
        self.centres = centres
        self.nearest = np.full((runs, len(self.points)), np.inf)

    def probe(self, cells: np.ndarray) -> np.ndarray:
        """Record one probed cell per run (flat indices); returns Gamma per run."""
        d = np.linalg.norm(self.points[None, :, :] - self.centres[cells][:, None, :], axis=-1)
        np.minimum(self.nearest, d, out=self.nearest)
        return self.gamma()

    def gamma(self) -> np.ndarray:
        return self.nearest.sum(axis=1)


def gamma_brute_force(centres: np.ndarray, border: np.ndarray, probed: list[int]) -> float:
    """Eq. (16) from scratch, for checking."""
    total = 0.0
    for b in np.flatnonzero(border.ravel()):
        total += min(float(np.linalg.norm(centres[b] - centres[p])) for p in probed)
    return total
