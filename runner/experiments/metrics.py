"""Exploration metrics: Gamma (eq. 16), its area, visit counts, how the walker moved, and the
paired test of two configurations over the same runs."""

from __future__ import annotations

import warnings

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


def border_band(border: np.ndarray) -> np.ndarray:
    """The cells within one cell (8-neighbourhood) of a border cell, the border included."""
    from scipy import ndimage

    return ndimage.maximum_filter(border, size=3, mode="constant")


def visits(paths: np.ndarray, cells: int) -> np.ndarray:
    """Probes per cell over all runs ``paths`` [runs, K] (flat cells of a grid of ``cells``)."""
    return np.bincount(paths.ravel(), minlength=cells)


def moves(paths: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """The length (metres) of each move of runs ``paths`` [runs, K] (flat cells, ``centres``
    [cells, 2] in metres): [runs, K - 1]."""
    return np.linalg.norm(np.diff(centres[paths], axis=1), axis=-1)


def behaviour(paths: np.ndarray, border: np.ndarray,
              centres: np.ndarray | None = None) -> dict[str, float]:
    """How the walker moved, over runs ``paths`` [runs, K] (flat cells) for a task's ``border``
    (grid-shaped, bool); ``centres`` [cells, 2] (metres) for the path length.

    * ``enrichment``: share of visits within one cell of the border / that band's share of cells
      (1 for visits spread evenly, higher when they concentrate on the border);
    * ``reached``: share of runs that probe a border cell; ``reach_step``: median step of the
      first such probe among them;
    * ``border_probed``: mean share of the border's cells probed per run (border recall);
    * ``precision``: share of the probes that fall on a border cell;
    * ``path_length``: mean distance travelled per run, metres, from probe to probe (with
      ``centres``);
    * ``distinct``: mean number of distinct cells probed per run;
    * ``returns``: share of steps that go back to the cell of two steps before (oscillation).

    >>> border = np.zeros((3, 3), bool); border[1, 1] = True
    >>> b = behaviour(np.array([[0, 4, 0, 4]]), border)
    >>> b["reached"], b["reach_step"], b["distinct"], b["returns"], b["precision"]
    (1.0, 1.0, 2.0, 1.0, 0.5)
    """
    flat_border = border.ravel()
    band = border_band(border).ravel()
    on = flat_border[paths]
    reached = on.any(axis=1)
    first = np.argmax(on, axis=1)
    probed_share = [flat_border[np.unique(p)].sum() / max(flat_border.sum(), 1) for p in paths]
    length = {}
    if centres is not None:
        length["path_length"] = float(moves(paths, centres).sum(axis=1).mean())
    return {
        "precision": float(on.mean()),
        **length,
        "enrichment": float(band[paths].mean() / band.mean()),
        "reached": float(reached.mean()),
        "reach_step": float(np.median(first[reached])) if reached.any() else float("nan"),
        "border_probed": float(np.mean(probed_share)),
        "distinct": float(np.mean([len(np.unique(p)) for p in paths])),
        "returns": float(np.mean(paths[:, 2:] == paths[:, :-2])) if paths.shape[1] > 2 else 0.0,
    }


def phase_areas(gamma: np.ndarray, paths: np.ndarray, border: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """The area under Gamma(k) of each run [runs, K] split at the step it first probes a cell
    of the task's ``border`` (grid-shaped, bool): the search (k = 0 up to that step) and the
    following (from that step on), trapezoids as :func:`area_under`, so the two add up to it.
    A run that never reaches the border is all search.

    >>> border = np.array([False, True, False])
    >>> search, follow = phase_areas(np.array([[4.0, 2.0, 0.0, 0.0]]), np.array([[0, 1, 1, 2]]),
    ...                              border)
    >>> search.tolist(), follow.tolist(), area_under(np.array([[4.0, 2.0, 0.0, 0.0]])).tolist()
    ([3.0], [1.0], [4.0])
    """
    gamma = np.asarray(gamma, dtype=float)
    runs, steps = gamma.shape
    on = np.asarray(border).ravel()[paths]
    first = np.where(on.any(axis=1), on.argmax(axis=1), steps - 1)[:, None]
    k = np.arange(steps)[None, :]
    # trapezoid weights of [0, first] and of [first, K - 1]: half at each end of a part (a
    # part of one step has no area)
    search = np.where(k <= first, 1.0, 0.0) - 0.5 * (k == 0) - 0.5 * (k == first)
    follow = np.where(k >= first, 1.0, 0.0) - 0.5 * (k == first) - 0.5 * (k == steps - 1)
    if steps == 1:
        return np.zeros(runs), np.zeros(runs)
    return (gamma * search).sum(axis=1), (gamma * follow).sum(axis=1)


def area_under(gamma: np.ndarray) -> np.ndarray:
    """Area under Gamma(k) over k = 0..K-1 (trapezoids, unit steps), per run: metre-steps."""
    return np.trapezoid(gamma, axis=-1)


def paired_test(ablated: np.ndarray, full: np.ndarray) -> float:
    """Two-sided Wilcoxon signed-rank p-value of paired runs (1.0 when they never differ)."""
    if np.allclose(ablated, full):
        return 1.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        from scipy import stats  # (read by the report: a worker of the experiment needs none)

        return float(stats.wilcoxon(ablated, full).pvalue)
