"""Compiled inner loops of the explorer (numba): the ICP of the shape cue and the saliency of the
perceived stimulus on 2-D grids, and the ICP of solids in a volume (the numpy versions spent
most of an experiment here).

ICP: for every (run, template, start) independently, transform the path into the template's
frame, pair each path point with its closest point on the template polygon, and solve the 2-D
Procrustes problem in closed form; repeat. Runs in parallel over (run, template, start).

3-D ICP (:func:`icp3d`): the same for every pose of a batch against a solid's surface sample,
each point paired with its nearest sample (exactly: the sample is looked for among the
candidates its cell of a grid keeps, see ``runner.shape.NearestGrid``, or among all samples
outside the grid's cells that keep candidates; or approximately, with the sample nearest to its
cell's centre), then the Kabsch rotation (an SVD of the 3 x 3 cross-covariance, a reflection
excluded); a pose stops where no pair changes.
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


@njit(cache=True, inline="always")
def _nearest3d(x, y, z, surface, low, cell, shape, starts, candidates, centre, approximate):
    """The index of the surface sample nearest to (x, y, z), and its squared distance; with
    ``approximate``, the sample nearest to the centre of the point's cell (of the nearest
    cell, outside the grid) and its squared distance to the point."""
    i = int(math.floor((x - low[0]) / cell))
    j = int(math.floor((y - low[1]) / cell))
    k = int(math.floor((z - low[2]) / cell))
    if approximate:
        i = min(max(i, 0), shape[0] - 1)
        j = min(max(j, 0), shape[1] - 1)
        k = min(max(k, 0), shape[2] - 1)
        s = centre[(i * shape[1] + j) * shape[2] + k]
        return s, (x - surface[s, 0]) ** 2 + (y - surface[s, 1]) ** 2 + (z - surface[s, 2]) ** 2
    first, last = 0, surface.shape[0]
    every = True
    if 0 <= i < shape[0] and 0 <= j < shape[1] and 0 <= k < shape[2]:
        c = (i * shape[1] + j) * shape[2] + k
        if starts[c, 0] >= 0:
            first, last, every = starts[c, 0], starts[c, 1], False
    best, arg = np.inf, -1
    for q in range(first, last):
        s = q if every else candidates[q]
        d = (x - surface[s, 0]) ** 2 + (y - surface[s, 1]) ** 2 + (z - surface[s, 2]) ** 2
        if d < best or (d == best and s < arg):
            best, arg = d, s
    return arg, best


@njit(cache=True)
def _local3d(path, r, j, rot, shift, p):
    """Path point j of run r in the frame of pose p: R^T (x - t)."""
    dx = path[r, j, 0] - shift[p, 0]
    dy = path[r, j, 1] - shift[p, 1]
    dz = path[r, j, 2] - shift[p, 2]
    return (rot[p, 0, 0] * dx + rot[p, 1, 0] * dy + rot[p, 2, 0] * dz,
            rot[p, 0, 1] * dx + rot[p, 1, 1] * dy + rot[p, 2, 1] * dz,
            rot[p, 0, 2] * dx + rot[p, 1, 2] * dy + rot[p, 2, 2] * dz)


@njit(cache=True, parallel=True)
def icp3d(path, counts, run_of, rot, shift, surface, low, cell, shape, starts, candidates,
          centre, iterations, approximate):
    """Refine every pose (``rot`` [P, 3, 3], ``shift`` [P, 3], in place) on the first
    ``counts[r]`` points of its run's path (``run_of`` [P]) by at most ``iterations`` ICP
    steps; a pose whose pairs did not change since its last step is at its fixed point.
    ``approximate``: pairs by the samples nearest to the cells' centres."""
    n_p, k = rot.shape[0], path.shape[1]
    for p in prange(n_p):
        r = run_of[p]
        n = counts[r]
        before = np.full(k, -1, np.int64)
        pairs = np.empty(k, np.int64)
        for _ in range(iterations):
            moved = False
            for j in range(n):
                x, y, z = _local3d(path, r, j, rot, shift, p)
                arg, _ = _nearest3d(x, y, z, surface, low, cell, shape, starts, candidates,
                                    centre, approximate)
                pairs[j] = arg
                moved = moved or arg != before[j]
            if not moved:
                break
            ms = np.zeros(3)
            mt = np.zeros(3)
            for j in range(n):
                for a in range(3):
                    ms[a] += surface[pairs[j], a]
                    mt[a] += path[r, j, a]
            ms /= n
            mt /= n
            h = np.zeros((3, 3))
            for j in range(n):
                for a in range(3):
                    sa = surface[pairs[j], a] - ms[a]
                    for b in range(3):
                        h[a, b] += sa * (path[r, j, b] - mt[b])
            u, _, vt = np.linalg.svd(h)
            d = 1.0 if np.linalg.det(u) * np.linalg.det(vt) >= 0 else -1.0
            for a in range(3):
                for b in range(3):
                    rot[p, a, b] = vt[0, a] * u[b, 0] + vt[1, a] * u[b, 1] \
                        + d * vt[2, a] * u[b, 2]
            for a in range(3):
                shift[p, a] = mt[a] - (rot[p, a, 0] * ms[0] + rot[p, a, 1] * ms[1]
                                       + rot[p, a, 2] * ms[2])
            for j in range(n):
                before[j] = pairs[j]


@njit(cache=True, parallel=True)
def distance3d(path, counts, run_of, rot, shift, surface, low, cell, shape, starts,
               candidates, centre, approximate):
    """Mean distance of each pose's used path points to their nearest surface samples, [P]
    (``approximate``: to the samples nearest to their cells' centres)."""
    n_p = rot.shape[0]
    out = np.empty(n_p)
    for p in prange(n_p):
        r = run_of[p]
        total = 0.0
        for j in range(counts[r]):
            x, y, z = _local3d(path, r, j, rot, shift, p)
            _, d = _nearest3d(x, y, z, surface, low, cell, shape, starts, candidates, centre,
                              approximate)
            total += math.sqrt(d)
        out[p] = total / counts[r]
    return out


@njit(cache=True, parallel=True)
def nearest3d(points, surface, low, cell, shape, starts, candidates, centre, approximate):
    """The nearest surface sample of each point [n, 3]: its index and squared distance
    (``approximate``: the sample nearest to its cell's centre)."""
    n = points.shape[0]
    index = np.empty(n, np.int64)
    squared = np.empty(n)
    for i in prange(n):
        index[i], squared[i] = _nearest3d(points[i, 0], points[i, 1], points[i, 2], surface,
                                          low, cell, shape, starts, candidates, centre,
                                          approximate)
    return index, squared
