"""Shape matching of the exploration path: rigid registration against each template, batched,
by ICP (the paper's) or by a chamfer search on a 2-D grid, by ICP on a 3-D one (``match3d``).

``match(path, outlines, points)`` registers every template onto every run's path (eq. 6-7):
rigid ICP in which each path point is paired with its closest point on the template's outline
(a closed polygon, so points slide along edges instead of sticking to sampled vertices), then
the closed-form 2-D Procrustes step; several starts (rotations x offsets), the best one wins,
and a warm start (the previous step's transform) can be added. The normalised error
``L = d / (d + error_scale)`` in [0, 1), where ``d`` is the mean distance (metres) of the path
points to the registered outline: 0 for a perfect match, 1/2 at ``d = error_scale``, and never 1
(Beta(1, 4.5) is 0 at 1, so a mismatch of both templates would otherwise be impossible).

``method="chamfer"`` registers without pairing points: the mean distance of the path points to
the outline (the chamfer distance, computed exactly against the polygon) is scored at every pose
of a grid (24 rotations x 7 x 7 offsets around the path's centroid, spanning the template's
radius), and its best eight poses each refined by a pattern search (27 neighbouring poses per
round, the steps halved every other round), the best refined pose kept. ICP descends from each
of its starts to the nearest minimum of the same distance; the chamfer search looks at every
pose of its grid, so it cannot be trapped by a start, but it is only as fine as its refinement.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from runner.attention._kernels import chamfer, distance3d, icp, icp3d, nearest3d

ERROR_SCALE = 0.02  # metres: the mean distance at which L = 1/2
MIN_POINTS = 10  # fewer probed cells than this on the perceived border: no shape evidence (R uniform)
_OFFSETS = np.array([[0.0, 0.0], [0.5, 0.0], [-0.5, 0.0], [0.0, 0.5], [0.0, -0.5]])
METHODS = ("icp", "chamfer")
#: In a volume, a run's full search of starts is made again once its set of points has grown
#: by this factor since the last (a 3-D search costs some forty warm steps: every multiple of
#: ``restart_every`` points, as on a surface, made them two thirds of the experiment's time)
SEARCH_GROWTH_3D = 1.5
#: the chamfer search's grid: rotations, and offsets per axis across [-radius, radius]
CHAMFER_ROTATIONS, CHAMFER_OFFSETS = 24, 7
#: its refinement: the best poses of the grid, each by rounds of 27 neighbouring poses (angle
#: and both offsets -1, 0, +1 step); a few, since the grid's best can lie in another basin than
#: the true pose's, a grid step away and a fraction of a millimetre worse
CHAMFER_REFINED, CHAMFER_ROUNDS = 8, 8
#: the first rounds refine all of them, the others the best one
CHAMFER_WIDE_ROUNDS = 2
_NEIGHBOURS = np.array([(i, j, k) for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1)],
                       float)


@dataclass
class Registration:
    """ICP results per run and template: ``error`` L in [0, 1), ``distance`` in metres,
    ``points`` [runs, T, K, D] the registered template points, and the rigid transform
    (``angle``, ``shift``) taking template coordinates onto the path: in 2-D ``angle`` [runs, T]
    is the angle of the rotation, in 3-D [runs, T, 3, 3] its matrix."""

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
    counts: np.ndarray | None = None,
    rotations: int = 8,
    iterations: int = 25,
    error_scale: float = ERROR_SCALE,
    warm: tuple[np.ndarray, np.ndarray] | None = None,
    method: str = "icp",
) -> Registration:
    """Register templates onto ``path`` [runs, k, 2] by ``method`` (``icp`` or ``chamfer``).

    ``counts`` [runs] (each in 1..k) says how many of its first points each run uses (all k
    when None): runs with point sets of different sizes are registered in one batch.
    ``outlines`` [T, V, 2] are the template polygons and ``points`` [T, K, 2] the template points
    returned registered (both in the template frame, centred). ``warm`` = (angle, shift) of
    shape [runs, T] and [runs, T, 2] adds the previous step's transform as one more start.
    With ``chamfer``, ``rotations`` > 0 asks for the grid search (``rotations`` and
    ``iterations`` are ICP's otherwise), and a warm start alone is refined as it is.
    """
    if method not in METHODS:
        raise ValueError(f"unknown shape matcher {method!r}: expected one of {METHODS}")
    counts, _, centroid = _path_set_up(path, counts, rotations, warm)
    radius = np.linalg.norm(outlines, axis=-1).max(axis=-1)  # [T]
    path = np.ascontiguousarray(path, dtype=float)
    outlines = np.ascontiguousarray(outlines, float)
    nverts = np.array([_vertex_count(o) for o in outlines], dtype=np.int64)
    if method == "icp":
        angle, shift = _poses(rotations, _OFFSETS, radius, centroid, warm)
        dist = icp(path, counts, outlines, nverts, angle, shift, iterations)
        angle, shift, distance = _best(dist, angle, shift)
    else:
        angle, shift, distance = _chamfer_search(path, counts, outlines, nverts, radius,
                                                 centroid, rotations > 0, warm)
    registered = _transform(angle[..., None], shift[:, :, None], points[None, :, None])[:, :, 0]
    return Registration(
        error=distance / (distance + error_scale),
        distance=distance,
        points=registered,
        angle=angle,
        shift=shift,
    )


def _path_set_up(path: np.ndarray, counts: np.ndarray | None, rotations: int,
                 warm: tuple | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The checks and set-up shared by the matchers: each run's count of points [runs], the
    points it uses as weights [runs, k] (1 or 0) and their centroid [runs, D]."""
    runs, k = path.shape[:2]
    counts = np.full(runs, k, np.int64) if counts is None else np.asarray(counts, np.int64)
    if counts.shape != (runs,) or np.any(counts < 1) or np.any(counts > k):
        raise ValueError(f"counts must be {runs} integers in 1..{k}, got {counts.tolist()}")
    if rotations == 0 and warm is None:
        raise ValueError("a match needs rotations > 0 or a warm start")
    weight = (np.arange(k)[None, :] < counts[:, None]).astype(float)
    centroid = (weight[..., None] * path).sum(axis=1) / counts[:, None]
    return counts, weight, centroid


def _poses(turns: int, offsets: np.ndarray, radius: np.ndarray, centroid: np.ndarray,
           warm: tuple[np.ndarray, np.ndarray] | None) -> tuple[np.ndarray, np.ndarray]:
    """Starting poses (angle [runs, T, S], shift [runs, T, S, 2]): ``turns`` rotations evenly
    spread, each at every one of ``offsets`` (in template radii) around the path's centroid,
    then the ``warm`` pose when given."""
    runs, n_t = len(centroid), len(radius)
    angles = np.repeat(np.arange(turns) * (2 * np.pi / max(turns, 1)), len(offsets))
    moves = np.tile(offsets, (turns, 1))[None] * radius[:, None, None]  # [T, S, 2]
    angle = np.broadcast_to(angles, (runs, n_t, angles.size)).copy()
    shift = centroid[:, None, None, :] + moves[None]
    if warm is not None:
        angle = np.concatenate([angle, warm[0][..., None]], axis=2)
        shift = np.concatenate([shift, warm[1][:, :, None, :]], axis=2)
    return np.ascontiguousarray(angle, dtype=float), np.ascontiguousarray(shift, dtype=float)


def _best(dist: np.ndarray, angle: np.ndarray, shift: np.ndarray
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The pose of smallest distance of each run and template, and that distance."""
    best = dist.argmin(-1)[..., None]
    return (np.take_along_axis(angle, best, -1)[..., 0],
            np.take_along_axis(shift, best[..., None], 2)[:, :, 0],
            np.take_along_axis(dist, best, -1)[..., 0])


def _chamfer_search(path: np.ndarray, counts: np.ndarray, outlines: np.ndarray,
                    nverts: np.ndarray, radius: np.ndarray, centroid: np.ndarray, search: bool,
                    warm: tuple[np.ndarray, np.ndarray] | None
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The chamfer search (see the module): the best poses of a grid (with ``search``; the warm
    pose otherwise), each refined by rounds of neighbouring poses, the best refined pose
    kept."""
    if search:
        grid = np.linspace(-1.0, 1.0, CHAMFER_OFFSETS)
        offsets = np.stack(np.meshgrid(grid, grid, indexing="ij"), -1).reshape(-1, 2)
        angle, shift = _poses(CHAMFER_ROTATIONS, offsets, radius, centroid, warm)
        dist = chamfer(path, counts, outlines, nverts, angle, shift)
        keep = np.argsort(dist, axis=-1, kind="stable")[..., :CHAMFER_REFINED]
        angle = np.take_along_axis(angle, keep, -1)  # [runs, T, N]
        shift = np.take_along_axis(shift, keep[..., None], 2)  # [runs, T, N, 2]
        turn, step = np.pi / CHAMFER_ROTATIONS, radius / (CHAMFER_OFFSETS - 1)
    else:
        assert warm is not None
        angle, shift = warm[0].astype(float)[..., None], warm[1].astype(float)[:, :, None]
        turn, step = np.pi / (4 * CHAMFER_ROTATIONS), radius / (4 * (CHAMFER_OFFSETS - 1))
    for round_ in range(CHAMFER_ROUNDS):  # the centre is among the neighbours: never worse
        runs, n_t, n = angle.shape
        scale = 0.5 ** (round_ // 2)
        candidates_angle = angle[..., None] + _NEIGHBOURS[:, 0] * turn * scale  # [r, T, N, 27]
        candidates_shift = (shift[:, :, :, None, :] + _NEIGHBOURS[:, 1:]
                            * (step * scale)[None, :, None, None, None])
        dist = chamfer(path, counts, outlines, nverts,
                       np.ascontiguousarray(candidates_angle.reshape(runs, n_t, -1)),
                       np.ascontiguousarray(candidates_shift.reshape(runs, n_t, -1, 2)))
        dist = dist.reshape(runs, n_t, n, len(_NEIGHBOURS))
        best = dist.argmin(-1)[..., None]  # each pose's best neighbour
        angle = np.take_along_axis(candidates_angle, best, -1)[..., 0]
        shift = np.take_along_axis(candidates_shift, best[..., None], 3)[:, :, :, 0]
        distance = np.take_along_axis(dist, best, -1)[..., 0]
        if round_ + 1 == CHAMFER_WIDE_ROUNDS:  # the basins told apart: the best one goes on
            angle, shift, distance = (a[:, :, None] for a in _best(distance, angle, shift))
    return _best(distance, angle, shift)


def match3d(
    path: np.ndarray,
    surfaces: list[np.ndarray],
    points: np.ndarray,
    *,
    counts: np.ndarray | None = None,
    rotations: int = 8,
    iterations: int = 25,
    error_scale: float = ERROR_SCALE,
    warm: tuple[np.ndarray, np.ndarray] | None = None,
    trees: list | None = None,
    offsets: np.ndarray = _OFFSETS,
    screen: int = 5,
    keep: int = 3,
    grids: list[NearestGrid] | None = None,
) -> Registration:
    """Register 3-D templates onto ``path`` [runs, k, 3] by ICP: each path point is paired with
    its nearest point of the template's surface sample (``surfaces``, one [M, 3] per template, in
    the template frame; a k-d tree finds it), then the rigid transform that brings the pairs
    closest is solved in closed form (Kabsch: an SVD, a reflection excluded); several starts,
    the best one wins. The starts turn the template about z (``rotations`` turns, as objects
    rest on their base) at each of ``offsets`` (in template radii, in x and y) around the path's
    centroid (by default the five of :func:`match`); ``warm`` = (rotation
    [runs, T, 3, 3], shift [runs, T, 3]) adds one more. The registration itself is not limited
    to turns about z. Every start takes ``screen`` steps; the ``keep`` nearest of each run go on
    for the rest of the ``iterations``. Pairing with samples, a fit stops where no pair changes:
    within about half
    the samples' spacing of the exact pose (about 3 mm for 1,500 samples of a 10 cm solid,
    a third of a cell). ``counts``, ``points`` and the error are as in :func:`match`; ``trees``
    are the surfaces' ``scipy.spatial.cKDTree`` when already built. With ``grids``
    (:class:`NearestGrid`, one per surface) the steps run compiled
    (:func:`runner.attention._kernels.icp3d`), the same pairs found through the grid, but for the
    screening of the starts, which pairs each point with the sample nearest to its grid
    cell's centre (within half a cell's diagonal of its own nearest)."""
    from scipy.spatial import cKDTree

    runs = path.shape[0]
    counts, weight, centroid = _path_set_up(path, counts, rotations, warm)
    path = np.ascontiguousarray(path, dtype=float)
    trees = trees if trees is not None else [cKDTree(s) for s in surfaces]
    n_t = len(surfaces)
    radius = np.array([np.linalg.norm(s, axis=1).max() for s in surfaces])
    offsets = np.column_stack([offsets, np.zeros(len(offsets))])
    turns = np.repeat(np.arange(rotations) * (2 * np.pi / max(rotations, 1)), len(offsets))
    start_rot = np.zeros((turns.size, 3, 3))  # turns about z
    start_rot[:, :2, :2], start_rot[:, 2, 2] = rotation(turns), 1.0
    moves = np.tile(offsets, (rotations, 1))
    def steps(t: int, rot: np.ndarray, shift: np.ndarray, run_of: np.ndarray, n: int,
              rough: bool = False) -> None:
        """ICP steps of the poses in place (``rough``: paired approximately, with grids)."""
        if grids is not None:
            icp3d(path, counts, run_of, rot, shift, *grids[t].arrays, n, rough)
        else:
            _icp_poses(trees[t], surfaces[t], path, weight, run_of, rot, shift, n)

    def distances(t: int, rot: np.ndarray, shift: np.ndarray, run_of: np.ndarray,
                  rough: bool = False) -> np.ndarray:
        """The poses' mean distances to template ``t``'s surface sample, [P]."""
        if grids is not None:
            return distance3d(path, counts, run_of, rot, shift, *grids[t].arrays, rough)
        return _mean_distance(trees[t], path, weight, counts, run_of, rot, shift)

    out_rot = np.empty((runs, n_t, 3, 3))
    out_shift = np.empty((runs, n_t, 3))
    out_dist = np.empty((runs, n_t))
    for t in range(n_t):
        # every (run, start) pose in one flat batch: rot [P, 3, 3], shift [P, 3]
        rot = np.broadcast_to(start_rot, (runs, *start_rot.shape))
        shift = centroid[:, None, :] + moves[None] * radius[t]  # [runs, S, 3]
        if warm is not None:
            rot = np.concatenate([rot, warm[0][:, t, None]], axis=1)
            shift = np.concatenate([shift, warm[1][:, t, None]], axis=1)
        n_s = rot.shape[1]
        rot, shift = rot.reshape(-1, 3, 3).copy(), shift.reshape(-1, 3).copy()
        run_of = np.repeat(np.arange(runs), n_s)
        # the screening of many starts, some far from the surface: with grids, paired
        # approximately (each point with its cell centre's nearest sample)
        screened = n_s > keep and iterations > screen
        steps(t, rot, shift, run_of, min(screen, iterations), screened)
        if screened:  # the most promising starts go on
            dist = distances(t, rot, shift, run_of, True)
            order = np.argsort(dist.reshape(runs, n_s), axis=1, kind="stable")[:, :keep]
            chosen = (np.arange(runs)[:, None] * n_s + order).ravel()
            rot, shift, run_of, n_s = rot[chosen], shift[chosen], run_of[chosen], keep
        if iterations > screen:
            steps(t, rot, shift, run_of, iterations - screen)
        dist = distances(t, rot, shift, run_of).reshape(runs, n_s)
        best = np.arange(runs) * n_s + dist.argmin(axis=1)
        out_rot[:, t], out_shift[:, t] = rot[best], shift[best]
        out_dist[:, t] = dist.min(axis=1)
    registered = np.einsum("rtij,tkj->rtki", out_rot, points) + out_shift[:, :, None, :]
    return Registration(error=out_dist / (out_dist + error_scale), distance=out_dist,
                        points=registered, angle=out_rot, shift=out_shift)


def _icp_poses(tree: Any, surface: np.ndarray, path: np.ndarray, weight: np.ndarray,
               run_of: np.ndarray, rot: np.ndarray, shift: np.ndarray, iterations: int) -> None:
    """ICP from every pose (``rot`` [P, 3, 3], ``shift`` [P, 3], refined in place) on its run's
    path (``run_of`` [P]). A pose whose pairs did not change since its last step is at its fixed
    point (the same pairs give the same pose): it leaves the batch."""
    active = np.arange(len(run_of))
    before = np.full((len(run_of), path.shape[1]), -1)
    for _ in range(iterations):
        runs = run_of[active]
        local = _local(path[runs], rot[active], shift[active])
        _, index = tree.query(local.reshape(-1, 3))
        index = np.where(weight[runs] > 0, index.reshape(local.shape[:2]), -1)
        moved = ~(index == before[active]).all(axis=1)
        active, index, runs = active[moved], index[moved], runs[moved]
        if not active.size:
            return
        rot[active], shift[active] = _kabsch(surface[index], path[runs], weight[runs, :, None])
        before[active] = index


def _mean_distance(tree: Any, path: np.ndarray, weight: np.ndarray, counts: np.ndarray,
                   run_of: np.ndarray, rot: np.ndarray, shift: np.ndarray) -> np.ndarray:
    """Mean distance of each pose's used path points to the surface sample, [P]."""
    local = _local(path[run_of], rot, shift)
    distance, _ = tree.query(local.reshape(-1, 3))
    return (distance.reshape(local.shape[:2]) * weight[run_of]).sum(axis=1) / counts[run_of]


class NearestGrid:
    """Where to look for the sample of a surface nearest to a point: a grid of cubic cells
    (the samples' mean spacing) over the surface's bounding box widened by half its radius,
    each cell within ``BAND`` cells of the surface keeping the samples within ``d + 2h`` of its
    centre (``d``: the centre's distance to its nearest sample, ``h``: half the cell's
    diagonal), which hold the nearest sample of every point of the cell. A cell farther, or
    with more than ``MAX_CANDIDATES`` of them, and a point outside the grid, are looked up
    among all the samples (a registered path lies within a few cells of the surface: the band
    spares the lists of the cells it never reaches, most of the grid's making). The compiled 3-D ICP (:func:`runner.attention._kernels.icp3d`) reads it: ``starts[c]`` is the slice of
    ``candidates`` of cell ``c`` (-1: all the samples)."""

    MAX_CANDIDATES = 64
    BAND = 4.0

    def __init__(self, tree: Any, surface: np.ndarray) -> None:
        spacing = float(np.mean(tree.query(surface, 2)[0][:, 1]))
        margin = 0.5 * float(np.linalg.norm(surface, axis=1).max())
        self.surface = np.ascontiguousarray(surface, dtype=float)
        self.cell = spacing
        self.low = surface.min(axis=0) - margin
        self.shape = np.ceil((surface.max(axis=0) + margin - self.low) / self.cell).astype(
            np.int64)
        axes = [self.low[a] + self.cell * (np.arange(self.shape[a]) + 0.5) for a in range(3)]
        centres = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
        nearest, self.centre = tree.query(centres)
        # (a small relative slack: a sample at exactly the bound stays in)
        reach = (nearest + np.sqrt(3.0) * self.cell) * (1 + 1e-9)
        sizes = tree.query_ball_point(centres, reach, return_length=True)
        kept = np.flatnonzero((sizes <= self.MAX_CANDIDATES) & (nearest <= self.BAND * self.cell))
        lists = tree.query_ball_point(centres[kept], reach[kept])
        lengths = np.array([len(found) for found in lists], dtype=np.int64)
        self.starts = np.full((len(centres), 2), -1, dtype=np.int64)
        ends = np.cumsum(lengths)
        self.starts[kept, 0], self.starts[kept, 1] = ends - lengths, ends
        self.candidates = np.fromiter((i for found in lists for i in sorted(found)),
                                      dtype=np.int64, count=int(lengths.sum()))

    @property
    def arrays(self) -> tuple[np.ndarray, np.ndarray, float, np.ndarray, np.ndarray, np.ndarray,
                              np.ndarray]:
        """What the compiled kernels take: surface, low corner, cell, shape, starts,
        candidates, and each cell centre's nearest sample."""
        return (self.surface, self.low, self.cell, self.shape, self.starts, self.candidates,
                self.centre)

    def query(self, points: np.ndarray, approximate: bool = False
              ) -> tuple[np.ndarray, np.ndarray]:
        """The distance to the nearest sample and its index, for points [n, 3] (as the k-d
        tree's ``query`` gives them); ``approximate``: the sample nearest to each point's
        cell's centre (of the nearest cell, outside the grid)."""
        index, squared = nearest3d(np.ascontiguousarray(points, dtype=float), *self.arrays,
                                   approximate)
        return np.sqrt(squared), index


#: The grids of the surfaces a process has registered, by their bytes (made once per process,
#: as they take a tree search per cell).
_GRIDS: dict[bytes, NearestGrid] = {}


#: Grids a process keeps (a few megabytes each): the templates of a few scenarios.
GRIDS_KEPT = 16


def nearest_grid(tree: Any, surface: np.ndarray) -> NearestGrid:
    """The :class:`NearestGrid` of ``surface`` (whose k-d tree is ``tree``), made once (the
    ``GRIDS_KEPT`` last used are kept)."""
    key = np.ascontiguousarray(surface).tobytes()
    found = _GRIDS.pop(key, None)
    if found is None:
        found = NearestGrid(tree, surface)
        while len(_GRIDS) >= GRIDS_KEPT:
            del _GRIDS[next(iter(_GRIDS))]  # the least recently used
    _GRIDS[key] = found
    return found


def _local(path: np.ndarray, rot: np.ndarray, shift: np.ndarray) -> np.ndarray:
    """Paths [P, k, 3] in the template frame of their poses (rotation [P, 3, 3], shift
    [P, 3]): R^T (p - t), [P, k, 3]."""
    return np.einsum("pki,pij->pkj", path - shift[:, None], rot)


def _kabsch(source: np.ndarray, target: np.ndarray, w: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray]:
    """The proper rotation R [P, 3, 3] and shift t [P, 3] minimising
    sum_k w |R source + t - target|^2 per pose: ``source``, ``target`` [P, k, 3], ``w``
    [P, k, 1]."""
    total = w.sum(axis=1)
    mean_s = (w * source).sum(axis=1) / total
    mean_t = (w * target).sum(axis=1) / total
    h = np.einsum("pki,pkj->pij", w * (source - mean_s[:, None]), target - mean_t[:, None])
    u, _, vt = np.linalg.svd(h)
    d = np.where(np.linalg.det(u) * np.linalg.det(vt) < 0, -1.0, 1.0)  # det(V U^T)
    fix = np.ones(u.shape[:-1])
    fix[..., 2] = d
    rot = np.einsum("pji,pj,pkj->pik", vt, fix, u)
    return rot, mean_t - np.einsum("pij,pj->pi", rot, mean_s)


_FIELDS = ("error", "distance", "points", "angle", "shift")


class ShapeTracker:
    """ICP over point sets that change a little from one step to the next, batched over runs;
    2-D outlines [T, V, 2] by :func:`match`, 3-D surface samples [T, M, 3] by :func:`match3d`.

    Each run keeps its last registration. ``update`` recomputes only the runs it is given
    (those whose point set changed), starting from their previous transform (a few
    iterations). The full multi-start search runs again while a run's set is short, each time
    its size passes a multiple of ``restart_every`` (with ``growth``: each time it has grown by
    that factor since the run's last search), and at once for the runs whose warm fit got
    clearly worse than their previous one (it is sliding into a wrong basin). In 3-D the steps
    run compiled, pairs found through each surface's :class:`NearestGrid`.
    """

    def __init__(self, outlines: np.ndarray, points: np.ndarray, restart_every: int = 10,
                 short: int = 12, warm_iterations: int = 8, worse: float = 1.25,
                 slack: float = 0.0005, method: str = "icp", growth: float | None = None):
        if method not in METHODS:
            raise ValueError(f"unknown shape matcher {method!r}: expected one of {METHODS}")
        self.outlines, self.points, self.method = outlines, points, method
        self.dims = points.shape[-1]
        if self.dims == 3 and method != "icp":
            raise ValueError(f"shape matcher {method!r} registers 2-D outlines; a 3-D grid "
                             "takes 'icp'")
        if self.dims == 3:
            from scipy.spatial import cKDTree

            self._trees = [cKDTree(surface) for surface in outlines]
            self._grids = [nearest_grid(tree, surface)
                           for tree, surface in zip(self._trees, outlines, strict=True)]
        self.restart_every, self.short, self.growth = restart_every, short, growth
        self.warm_iterations, self.worse, self.slack = warm_iterations, worse, slack
        self.reset()

    def reset(self) -> None:
        self.state: Registration | None = None
        self.fitted: np.ndarray | None = None  # runs registered at least once
        self.searched: np.ndarray | None = None  # point count at each run's last full search

    def _allocate(self, runs: int) -> Registration:
        n_t, n_k, dims = self.points.shape
        nan = np.full((runs, n_t), np.nan)
        self.fitted = np.zeros(runs, bool)
        self.searched = np.zeros(runs, np.int64)
        angle = nan.copy() if dims == 2 else np.full((runs, n_t, 3, 3), np.nan)
        return Registration(error=nan.copy(), distance=nan.copy(),
                            points=np.full((runs, n_t, n_k, dims), np.nan), angle=angle,
                            shift=np.full((runs, n_t, dims), np.nan))

    def update(self, path: np.ndarray, counts: np.ndarray | None = None,
               runs: np.ndarray | None = None) -> Registration:
        """Register the templates onto ``path`` [runs, k, 2] (the first ``counts[r]`` points of
        run r) for the ``runs`` given (all when None); the other runs keep their registration
        (NaN until they have one). Returns every run's registration."""
        n, k = path.shape[:2]
        counts = np.full(n, k, np.int64) if counts is None else np.asarray(counts, np.int64)
        todo = np.arange(n) if runs is None else np.asarray(runs, np.int64)
        if self.state is None:
            self.state = self._allocate(n)
        state, fitted, searched = self.state, self.fitted, self.searched
        assert fitted is not None and searched is not None
        every = self.restart_every
        if self.growth is None:  # at each multiple of restart_every
            grown = counts[todo] // every > searched[todo] // every
        else:  # once the set has grown by the factor growth since the last search
            grown = counts[todo] >= searched[todo] * self.growth
        full = ~fitted[todo] | (counts[todo] <= self.short) | grown
        warm_runs = todo[~full]
        if warm_runs.size:
            reg = self._match(path, counts, warm_runs, rotations=0,
                              iterations=self.warm_iterations)
            # a fit clearly worse than the run's last one (x `worse`, + `slack` metres): search
            limit = state.distance[warm_runs] * self.worse + self.slack
            worse = (reg.distance > limit).any(axis=1)
            self._store(warm_runs[~worse], reg, np.asarray(~worse))
            todo_full = np.concatenate([todo[full], warm_runs[worse]])
            if worse.any():
                # start the search from the warm result too
                state.angle[warm_runs[worse]] = reg.angle[worse]
                state.shift[warm_runs[worse]] = reg.shift[worse]
        else:
            todo_full = todo[full]
        for group in (todo_full[fitted[todo_full]], todo_full[~fitted[todo_full]]):
            if group.size:
                reg = self._match(path, counts, group, rotations=8, iterations=25,
                                  warm=bool(fitted[group[0]]))
                self._store(group, reg, np.ones(group.size, bool))
                searched[group] = counts[group]
        fitted[todo] = True
        return Registration(**{name: getattr(state, name).copy() for name in _FIELDS})

    def _match(self, path: np.ndarray, counts: np.ndarray, runs: np.ndarray, *, rotations: int,
               iterations: int, warm: bool = True) -> Registration:
        top = int(counts[runs].max())
        assert self.state is not None
        start = (self.state.angle[runs], self.state.shift[runs]) if warm else None
        if self.dims == 3:
            return match3d(path[runs, :top], list(self.outlines), self.points,
                           counts=counts[runs], rotations=rotations, iterations=iterations,
                           warm=start, trees=self._trees, grids=self._grids)
        return match(path[runs, :top], self.outlines, self.points, counts=counts[runs],
                     rotations=rotations, iterations=iterations, warm=start,
                     method=self.method)

    def _store(self, runs: np.ndarray, reg: Registration, keep: np.ndarray) -> None:
        assert self.state is not None
        for name in _FIELDS:
            getattr(self.state, name)[runs] = getattr(reg, name)[keep]
