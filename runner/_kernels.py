"""Compiled inner loops of the explorer (numba): the ICP of the shape cue and the saliency of the
perceived stimulus on 2-D grids (the numpy versions spent most of an experiment here).

ICP: for every (run, template, start) independently, transform the path into the template's
frame, pair each path point with its closest point on the template polygon, and solve the 2-D
Procrustes problem in closed form; repeat. Runs in parallel over (run, template, start).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange


@njit(cache=True, inline="always")
def _closest(qx, qy, poly, nv):
    """Closest point on the closed polygon ``poly[:nv]`` to (qx, qy), and its squared distance."""
    best = np.inf
    bx = by = 0.0
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


@njit(cache=True, inline="always")
def _mean_distance(points, k, poly, nv, a, tx, ty):
    """Mean distance of the first ``k`` points to the polygon moved by rotation ``a`` then shift
    (tx, ty)."""
    c, sn = math.cos(a), math.sin(a)
    total = 0.0
    for i in range(k):
        px, py = points[i, 0] - tx, points[i, 1] - ty
        _, _, d2 = _closest(c * px + sn * py, -sn * px + c * py, poly, nv)
        total += math.sqrt(d2)
    return total / k


@njit(cache=True, inline="always")
def _job(job, n_t, n_s):
    """The (run, template, start) of a flat job index over runs x templates x starts."""
    return job // (n_t * n_s), (job // n_s) % n_t, job % n_s


@njit(cache=True, parallel=True)
def icp(path, counts, outlines, nverts, angle, shift, iterations):
    """Refine every start in place; returns the mean distance per start.

    path [R, k, 2], of which run r uses its first ``counts[r]`` (>= 1) points; outlines
    [T, V, 2] with ``nverts[t]`` vertices used; angle [R, T, S] and
    shift [R, T, S, 2] are the starts (overwritten with the results).
    """
    runs, n_t, n_s = angle.shape
    dist = np.empty((runs, n_t, n_s))
    for job in prange(runs * n_t * n_s):
        r, t, s = _job(job, n_t, n_s)
        poly = outlines[t]
        nv = nverts[t]
        k = counts[r]
        a, tx, ty = angle[r, t, s], shift[r, t, s, 0], shift[r, t, s, 1]
        for _ in range(iterations):
            c, sn = math.cos(a), math.sin(a)
            ssx = ssy = sdx = sdy = cross = dot = 0.0
            for i in range(k):
                px, py = path[r, i, 0], path[r, i, 1]
                # the path point in the template frame: R^T (p - shift)
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
        angle[r, t, s], shift[r, t, s, 0], shift[r, t, s, 1] = a, tx, ty
        dist[r, t, s] = _mean_distance(path[r], k, poly, nv, a, tx, ty)
    return dist


@njit(cache=True, inline="always")
def _sobel_cell(d, mask, r, x, y):
    """The saliency of cell (x, y) of run r (see perceived_sobel_2d)."""
    nx, ny = d.shape[1], d.shape[2]
    best = 0.0
    compared = False
    near = False
    for axis in range(2):
        m0 = m1 = m2 = 0.0
        h0 = h1 = h2 = False
        for line in range(3):
            num = 0.0
            den = 0.0
            for k in range(3):
                if axis == 0:
                    cx, cy = x + line - 1, y + k - 1
                else:
                    cx, cy = x + k - 1, y + line - 1
                if 0 <= cx < nx and 0 <= cy < ny and mask[r, cx, cy]:
                    w = 2.0 if k == 1 else 1.0
                    num += w * d[r, cx, cy]
                    den += w
            if den > 0.0:
                near = True
                if line == 0:
                    m0, h0 = num / den, True
                elif line == 1:
                    m1, h1 = num / den, True
                else:
                    m2, h2 = num / den, True
        if h0 + h1 + h2 >= 2:
            hi = m2 if h2 else m1
            lo = m0 if h0 else m1
            best = max(best, abs(hi - lo))
            compared = True
    if compared:
        return min(best, 1.0)
    if near:
        return np.nan
    return 0.0


@njit(cache=True, parallel=True)
def perceived_sobel_2d(d, mask):
    """Saliency of the perceived stimulus on 2-D grids [R, nx, ny] (see runner.cues.saliency):
    per cell the largest difference of the (1, 2, 1)-weighted means of perceived cells between
    the lines either side, along x and y; NaN where nothing is compared but a cell is perceived
    nearby, 0 where nothing is perceived nearby."""
    runs, nx, ny = d.shape
    out = np.empty((runs, nx, ny))
    for job in prange(runs * nx):
        r = job // nx
        x = job % nx
        for y in range(ny):
            out[r, x, y] = _sobel_cell(d, mask, r, x, y)
    return out


@njit(cache=True)
def perceived_sobel_2d_around(d, mask, out, cells):
    """``out`` (a saliency map from perceived_sobel_2d) brought up to date after the stimulus
    ``d`` (numbers, or booleans read as 0 and 1) or the mask changed at one cell per run (flat index ``cells[r]``, -1 for none): a cell's
    saliency reads its 3 x 3 neighbourhood, so only the 3 x 3 cells around it change."""
    runs, nx, ny = d.shape
    for r in range(runs):
        if cells[r] < 0:
            continue
        x0, y0 = cells[r] // ny, cells[r] % ny
        for x in range(max(x0 - 1, 0), min(x0 + 2, nx)):
            for y in range(max(y0 - 1, 0), min(y0 + 2, ny)):
                out[r, x, y] = _sobel_cell(d, mask, r, x, y)


@njit(cache=True, parallel=True)
def chamfer(path, counts, outlines, nverts, angle, shift):
    """The mean distance of the path points to the template outline at every given pose (the
    chamfer distance), without moving it: path [R, k, 2] (run r uses its first ``counts[r]``
    points), outlines [T, V, 2] with ``nverts[t]`` vertices used, poses angle [R, T, S] and
    shift [R, T, S, 2]; returns [R, T, S]."""
    runs, n_t, n_s = angle.shape
    dist = np.empty((runs, n_t, n_s))
    for job in prange(runs * n_t * n_s):
        r, t, s = _job(job, n_t, n_s)
        dist[r, t, s] = _mean_distance(path[r], counts[r], outlines[t], nverts[t],
                                       angle[r, t, s], shift[r, t, s, 0], shift[r, t, s, 1])
    return dist
