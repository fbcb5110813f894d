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


def closest_on_outline(points: np.ndarray, vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closest points on closed polygons: ``points`` [..., k, 2], ``vertices`` [..., V, 2].

    Returns the closest points [..., k, 2] and their squared distances [..., k].
    """
    a = vertices
    b = np.roll(vertices, -1, axis=-2)
    ab = b - a  # [..., V, 2]
    ap = points[..., :, None, :] - a[..., None, :, :]  # [..., k, V, 2]
    length2 = (ab * ab).sum(-1)[..., None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(length2 > 0, (ap * ab[..., None, :, :]).sum(-1) / length2, 0.0)
    t = np.clip(t, 0.0, 1.0)
    proj = a[..., None, :, :] + t[..., None] * ab[..., None, :, :]
    d2 = ((points[..., :, None, :] - proj) ** 2).sum(-1)  # [..., k, V]
    best = d2.argmin(-1)
    closest = np.take_along_axis(proj, best[..., None, None], axis=-2)[..., 0, :]
    return closest, np.take_along_axis(d2, best[..., None], axis=-1)[..., 0]


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
    pts = path[:, None, None]  # [runs, 1, 1, k, 2]
    verts = outlines[None, :, None]  # [1, T, 1, V, 2]
    for _ in range(iterations):
        moved = _transform(angle, shift, verts)
        dst_free, _ = closest_on_outline(pts, moved)  # closest outline points, path frame
        # Pair path point p with its closest outline point q; express q in the template frame.
        c, s = np.cos(angle)[..., None], np.sin(angle)[..., None]
        q = dst_free - shift[..., None, :]
        src = np.stack([c * q[..., 0] + s * q[..., 1], -s * q[..., 0] + c * q[..., 1]], -1)
        dst = np.broadcast_to(pts, src.shape)
        ms, md = src.mean(-2), dst.mean(-2)
        a, b = src - ms[..., None, :], dst - md[..., None, :]
        cross = (a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]).sum(-1)
        dot = (a * b).sum(-1).sum(-1)
        angle = np.arctan2(cross, dot)
        c, s = np.cos(angle), np.sin(angle)
        shift = md - np.stack([c * ms[..., 0] - s * ms[..., 1], s * ms[..., 0] + c * ms[..., 1]], -1)
    _, d2 = closest_on_outline(pts, _transform(angle, shift, verts))
    dist = np.sqrt(d2).mean(-1)  # [runs, T, S]
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

    The path grows by one point per step, so each step starts from the previous step's transform
    (a few iterations); every ``restart_every`` steps (and while the path is short) the full
    multi-start search runs as well, to leave a wrong basin.
    """

    def __init__(self, outlines: np.ndarray, points: np.ndarray, restart_every: int = 10,
                 short: int = 12, warm_iterations: int = 8):
        self.outlines, self.points = outlines, points
        self.restart_every, self.short, self.warm_iterations = restart_every, short, warm_iterations
        self.warm: tuple[np.ndarray, np.ndarray] | None = None

    def reset(self) -> None:
        self.warm = None

    def update(self, path: np.ndarray) -> Registration:
        k = path.shape[1]
        full = self.warm is None or k <= self.short or k % self.restart_every == 0
        reg = match(path, self.outlines, self.points, rotations=8 if full else 0,
                    iterations=25 if full else self.warm_iterations, warm=self.warm)
        self.warm = (reg.angle, reg.shift)
        return reg
