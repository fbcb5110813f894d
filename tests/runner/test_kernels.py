"""The explorer's compiled loops against plain references: ICP with its starts side by side
and one by one, and against the per-point loop of Python; the followed part of the perceived
border against scipy's labelling of it; the marked cells first against numpy's stable sort."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import ndimage

from runner.attention._kernels import (
    followed_border_2d,
    icp,
    icp_one_by_one,
    icp_side_by_side,
    marked_first,
)
from runner.attention.cues import perceived_border
from runner.attention.shape import pad_outlines


def _closest(qx, qy, poly, nv):
    """The closest point of the polygon ``poly[:nv]`` to (qx, qy) and its squared distance,
    edge by edge (the first of equal distances), in Python."""
    best, bx, by = math.inf, 0.0, 0.0
    for v in range(nv):
        ax, ay = poly[v, 0], poly[v, 1]
        w = v + 1 if v + 1 < nv else 0
        ex, ey = poly[w, 0] - ax, poly[w, 1] - ay
        length2 = ex * ex + ey * ey
        t = 0.0
        if length2 > 0.0:
            t = ((qx - ax) * ex + (qy - ay) * ey) / length2
            t = min(max(t, 0.0), 1.0)
        cx, cy = ax + t * ex, ay + t * ey
        d2 = (qx - cx) ** 2 + (qy - cy) ** 2
        if d2 < best:
            best, bx, by = d2, cx, cy
    return bx, by, best


def _icp_python(path, k, poly, nv, a, tx, ty, iterations):
    """One start refined by ICP in Python: the pose and the mean distance."""
    for _ in range(iterations):
        c, sn = math.cos(a), math.sin(a)
        ssx = ssy = sdx = sdy = cross = dot = 0.0
        for i in range(k):
            px, py = path[i, 0], path[i, 1]
            qx = c * (px - tx) + sn * (py - ty)
            qy = -sn * (px - tx) + c * (py - ty)
            cx, cy, _ = _closest(qx, qy, poly, nv)
            ssx += cx
            ssy += cy
            sdx += px
            sdy += py
            cross += cx * py - cy * px
            dot += cx * px + cy * py
        msx, msy, mdx, mdy = ssx / k, ssy / k, sdx / k, sdy / k
        cross -= k * (msx * mdy - msy * mdx)
        dot -= k * (msx * mdx + msy * mdy)
        a = math.atan2(cross, dot)
        c, sn = math.cos(a), math.sin(a)
        tx = mdx - (c * msx - sn * msy)
        ty = mdy - (sn * msx + c * msy)
    c, sn = math.cos(a), math.sin(a)
    total = 0.0
    for i in range(k):
        px, py = path[i, 0] - tx, path[i, 1] - ty
        total += math.sqrt(_closest(c * px + sn * py, -sn * px + c * py, poly, nv)[2])
    return a, tx, ty, total / k


def _problem(seed: int, starts: int):
    rng = np.random.default_rng(seed)
    square = np.array([[-0.05, -0.05], [0.05, -0.05], [0.05, 0.05], [-0.05, 0.05]])
    triangle = np.array([[-0.06, -0.04], [0.06, -0.04], [0.0, 0.07]])
    outlines = pad_outlines([square, triangle])  # the triangle padded: an empty edge
    nverts = np.array([4, 3], np.int64)
    runs = 3
    path = rng.uniform(-0.08, 0.08, (runs, 12, 2))
    counts = np.array([12, 5, 1], np.int64)
    angle = rng.uniform(-np.pi, np.pi, (runs, 2, starts))
    shift = rng.uniform(-0.02, 0.02, (runs, 2, starts, 2))
    return path, counts, outlines, nverts, angle, shift


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("starts", [1, 3, 41])
def test_icp_side_by_side_one_by_one_and_python_agree_to_the_bit(seed, starts):
    path, counts, outlines, nverts, angle, shift = _problem(seed, starts)
    results = []
    for refine in (icp, icp_one_by_one, icp_side_by_side):
        a, s = angle.copy(), shift.copy()
        results.append((refine(path, counts, outlines, nverts, a, s, 6), a, s))
    for other in results[1:]:
        for x, y in zip(results[0], other, strict=True):
            assert np.array_equal(x, y)
    dist, a, s = results[0]
    for r, t, j in np.ndindex(angle.shape):
        expected = _icp_python(path[r], counts[r], outlines[t], nverts[t], angle[r, t, j],
                               shift[r, t, j, 0], shift[r, t, j, 1], 6)
        assert (a[r, t, j], s[r, t, j, 0], s[r, t, j, 1], dist[r, t, j]) == expected


def _followed_by_labels(target, perceived, path):
    """The part of the perceived border the runs follow, as scipy labels it."""
    border = perceived_border(target, perceived, dims=2)
    structure = np.zeros((3, 3, 3), bool)
    structure[1] = True
    labels, _ = ndimage.label(border, structure=structure)
    labels = labels.reshape(len(target), -1)
    rows = np.arange(len(target))
    followed = np.full(len(target), -1)
    todo = labels.max(axis=1) > 0
    for cells in reversed(list(path)):
        label = labels[rows, cells]
        hit = todo & (label > 0)
        followed[hit] = label[hit]
        todo &= ~hit
    return labels == followed[:, None]


@pytest.mark.parametrize("seed", range(6))
def test_the_followed_border_is_the_labelled_component_of_the_last_border_probe(seed):
    rng = np.random.default_rng(seed)
    runs, nx, ny, steps = 5, 9, 13, 30
    path = rng.integers(0, nx * ny, (steps, runs))
    perceived = np.zeros((runs, nx * ny), bool)
    np.put_along_axis(perceived, path.T, True, axis=1)
    # the task's material on one side of a line, and a few misperceptions
    x, y = np.divmod(np.arange(nx * ny), ny)
    side = (x + 0.7 * y + rng.uniform(-3, 3, (runs, 1)) > 8) ^ (rng.random((runs, nx * ny))
                                                                  < 0.1)
    target = (side & perceived).reshape(runs, nx, ny)
    perceived = perceived.reshape(runs, nx, ny)
    out = np.empty((runs, nx * ny), bool)
    followed_border_2d(target, perceived, path, out)
    assert np.array_equal(out, _followed_by_labels(target, perceived, path))
    assert out.any()


@pytest.mark.parametrize("seed", range(4))
def test_the_marked_cells_first_are_numpy_s_stable_sort(seed):
    rng = np.random.default_rng(seed)
    marked = rng.random((6, 40)) < rng.uniform(0, 0.6, (6, 1))
    marked[0] = False
    width = max(int(marked.sum(axis=1).max()), 1)
    for w in (width, width + 3):
        assert np.array_equal(marked_first(marked, w),
                              np.argsort(~marked, axis=1, kind="stable")[:, :w])
