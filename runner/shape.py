"""Shape matching of the exploration path: rigid 2-D ICP against each template, batched.

``match(path, outlines, points)`` registers every template onto every run's path (eq. 6-7):
rigid ICP in which each path point is paired with its closest point on the template's outline
(a closed polygon, so points slide along edges instead of sticking to sampled vertices), then
the closed-form 2-D Procrustes step; several starts (rotations x offsets), the best one wins,
and a warm start (the previous step's transform) can be added. The normalised error
``L = d / (d + error_scale)`` in [0, 1), where ``d`` is the mean distance (metres) of the path
points to the registered outline: 0 for a perfect match, 1/2 at ``d = error_scale``, and never 1
(Beta(1, 4.5) is 0 at 1, so a mismatch of both templates would otherwise be impossible).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from runner._icp import icp

ERROR_SCALE = 0.02  # metres: the mean distance at which L = 1/2
MIN_POINTS = 3  # fewer probed cells than this: no shape evidence (R uniform)
_OFFSETS = np.array([[0.0, 0.0], [0.5, 0.0], [-0.5, 0.0], [0.0, 0.5], [0.0, -0.5]])


@dataclass
class Registration:
    """ICP results per run and template: ``error`` L in [0, 1), ``distance`` in metres,
    ``points`` [runs, T, K, 2] the registered template points, and the rigid transform
    (``angle``, ``shift``) taking template coordinates onto the path."""

    error: np.ndarray
    distance: np.ndarray
    points: np.ndarray
    angle: np.ndarray
    shift: np.ndarray


def rotation(angle: np.ndarray) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


def _transform(angle: np.ndarray, shift: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Rotate then shift ``pts`` [..., T, 1, P, 2] for transforms [runs, T, S]."""
    c, s = np.cos(angle)[..., None], np.sin(angle)[..., None]
    x, y = pts[..., 0], pts[..., 1]
    return np.stack([c * x - s * y, s * x + c * y], -1) + shift[..., None, :]


def _vertex_count(padded: np.ndarray) -> int:
    """Vertices of a padded outline (the padding repeats the last vertex)."""
    n = len(padded)
    while n > 1 and np.array_equal(padded[n - 1], padded[n - 2]):
        n -= 1
    return n


def pad_outlines(outlines: list[np.ndarray]) -> np.ndarray:
    """Stack polygons with different vertex counts (repeating the last vertex: empty edges)."""
    v = max(len(o) for o in outlines)
    return np.stack([np.vstack([o] + [o[-1:]] * (v - len(o))) for o in outlines])


def match(
    path: np.ndarray,
    outlines: np.ndarray,
    points: np.ndarray,
    *,
    rotations: int = 8,
    iterations: int = 25,
    error_scale: float = ERROR_SCALE,
    warm: tuple[np.ndarray, np.ndarray] | None = None,
) -> Registration:
    """Register templates onto ``path`` [runs, k, 2].

    ``outlines`` [T, V, 2] are the template polygons and ``points`` [T, K, 2] the template points
    returned registered (both in the template frame, centred). ``warm`` = (angle, shift) of
    shape [runs, T] and [runs, T, 2] adds the previous step's transform as one more start.
    """
    runs = path.shape[0]
    n_t = outlines.shape[0]
    radius = np.linalg.norm(outlines, axis=-1).max(axis=-1)  # [T]
    angles = np.repeat(np.arange(rotations) * (2 * np.pi / max(rotations, 1)), len(_OFFSETS))
    moves = np.tile(_OFFSETS, (rotations, 1))[None] * radius[:, None, None]  # [T, S, 2]
    angle = np.broadcast_to(angles, (runs, n_t, angles.size)).copy()
    shift = path.mean(axis=1)[:, None, None, :] + moves[None]
    if rotations == 0 and warm is None:
        raise ValueError("match needs rotations > 0 or a warm start")
    if warm is not None:
        angle = np.concatenate([angle, warm[0][..., None]], axis=2)
        shift = np.concatenate([shift, warm[1][:, :, None, :]], axis=2)
    angle = np.ascontiguousarray(angle, dtype=float)
    shift = np.ascontiguousarray(shift, dtype=float)
    nverts = np.array([_vertex_count(o) for o in outlines], dtype=np.int64)
    dist = icp(np.ascontiguousarray(path, dtype=float), np.ascontiguousarray(outlines, float),
               nverts, angle, shift, iterations)
    best = dist.argmin(-1)[..., None]
    angle = np.take_along_axis(angle, best, -1)[..., 0]
    shift = np.take_along_axis(shift, best[..., None], 2)[:, :, 0]
    distance = np.take_along_axis(dist, best, -1)[..., 0]
    registered = _transform(angle[..., None], shift[:, :, None], points[None, :, None])[:, :, 0]
    return Registration(
        error=distance / (distance + error_scale),
        distance=distance,
        points=registered,
        angle=angle,
        shift=shift,
    )


class ShapeTracker:
    """ICP over a growing path, one update per step, batched over runs.

    The path grows by one point per step, so each step starts from the previous step's
    transform (a few iterations). The full multi-start search runs again while the path is
    short, every ``restart_every`` steps, and at once for the runs whose warm fit got clearly
    worse than at the previous step (it is sliding into a wrong basin).
    """

    def __init__(self, outlines: np.ndarray, points: np.ndarray, restart_every: int = 10,
                 short: int = 12, warm_iterations: int = 8, worse: float = 1.25,
                 slack: float = 0.0005):
        self.outlines, self.points = outlines, points
        self.restart_every, self.short = restart_every, short
        self.warm_iterations, self.worse, self.slack = warm_iterations, worse, slack
        self.reset()

    def reset(self) -> None:
        self.warm: tuple[np.ndarray, np.ndarray] | None = None
        self.distance: np.ndarray | None = None

    def update(self, path: np.ndarray) -> Registration:
        k = path.shape[1]
        if self.warm is None or k <= self.short or k % self.restart_every == 0:
            reg = match(path, self.outlines, self.points, warm=self.warm)
        else:
            reg = match(path, self.outlines, self.points, rotations=0,
                        iterations=self.warm_iterations, warm=self.warm)
            assert self.distance is not None
            # a fit clearly worse than last step's (x `worse`, + `slack` metres): search again
            limit = self.distance * self.worse + self.slack
            redo = np.flatnonzero((reg.distance > limit).any(axis=1))
            if redo.size:
                again = match(path[redo], self.outlines, self.points,
                              warm=(reg.angle[redo], reg.shift[redo]))
                for name in ("error", "distance", "points", "angle", "shift"):
                    getattr(reg, name)[redo] = getattr(again, name)
        self.warm = (reg.angle, reg.shift)
        self.distance = reg.distance
        return reg
