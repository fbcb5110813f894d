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
        r = job // (n_t * n_s)
        t = (job // n_s) % n_t
        s = job % n_s
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
        c, sn = math.cos(a), math.sin(a)
        total = 0.0
        for i in range(k):
            px, py = path[r, i, 0], path[r, i, 1]
            qx = c * (px - tx) + sn * (py - ty)
            qy = -sn * (px - tx) + c * (py - ty)
            _, _, d2 = _closest(qx, qy, poly, nv)
            total += math.sqrt(d2)
        angle[r, t, s], shift[r, t, s, 0], shift[r, t, s, 1] = a, tx, ty
        dist[r, t, s] = total / k
    return dist


@njit(cache=True, parallel=True)
def perceived_sobel_2d(d, mask):
    """Saliency of the perceived stimulus on 2-D grids [R, nx, ny] (see runner.cues.saliency):
    per cell the largest difference of the (1, 2, 1)-weighted means of perceived cells between
    the lines either side, along x and y; NaN where nothing is compared but a cell is perceived
    nearby, 0 where nothing is perceived nearby."""
    runs, nx, ny = d.shape
    out = np.empty((runs, nx, ny))
    weights = (1.0, 2.0, 1.0)
    for job in prange(runs * nx):
        r = job // nx
        x = job % nx
        for y in range(ny):
            best = 0.0
            compared = False
            near = False
            for axis in range(2):
                means = np.zeros(3)
                has = np.zeros(3, np.bool_)
                for line in range(3):
                    num = 0.0
                    den = 0.0
                    for k in range(3):
                        if axis == 0:
                            cx, cy = x + line - 1, y + k - 1
                        else:
                            cx, cy = x + k - 1, y + line - 1
                        if 0 <= cx < nx and 0 <= cy < ny and mask[r, cx, cy]:
                            num += weights[k] * d[r, cx, cy]
                            den += weights[k]
                    if den > 0.0:
                        means[line] = num / den
                        has[line] = True
                        near = True
                if has[0] + has[1] + has[2] >= 2:
                    hi = means[2] if has[2] else means[1]
                    lo = means[0] if has[0] else means[1]
                    best = max(best, abs(hi - lo))
                    compared = True
            if compared:
                out[r, x, y] = min(best, 1.0)
            elif near:
                out[r, x, y] = np.nan
            else:
                out[r, x, y] = 0.0
    return out
