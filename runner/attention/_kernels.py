"""Compiled inner loops of the explorer (numba): the ICP of the shape cue, the saliency of the
perceived stimulus and the part of the perceived border a run follows on 2-D grids, and the ICP
of solids in a volume (the numpy versions spent most of an experiment here).

ICP: for every (run, template, start) independently, transform the path into the template's
frame, pair each path point with its closest point on the template polygon, and solve the 2-D
Procrustes problem in closed form; repeat. Runs in parallel over (run, template), the starts of
a search side by side (the loops the compiler vectorises run over them), or over (run,
template, start) for a few starts.

3-D ICP (:func:`icp3d`): the same for every pose of a batch against a solid's surface sample,
each point paired with its nearest sample (exactly: the sample is looked for among the
candidates its cell of a grid keeps, see ``runner.attention.shape.NearestGrid``, or among all
samples outside the grid's cells that keep candidates; or approximately, with the sample nearest to its
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


@njit(cache=True, inline="always")
def _closest_each(qx, qy, k, poly, nv, cx, cy, best):
    """:func:`_closest` for the first ``k`` points (``qx``, ``qy``) at once, into ``cx``,
    ``cy`` and ``best`` (their squared distances): the same arithmetic and the same
    comparisons, edge by edge, so the same closest points to the bit; the loop over the points
    is the inner one, branch-free, which the compiler vectorises (point after point, the
    polygon's few edges ran as a short inner loop and the choice of the closest as
    unpredictable branches: half of the experiment's ICP time)."""
    for i in range(k):
        best[i] = np.inf
        cx[i] = 0.0
        cy[i] = 0.0
    for v in range(nv):
        ax, ay = poly[v, 0], poly[v, 1]
        w = v + 1 if v + 1 < nv else 0
        ex, ey = poly[w, 0] - ax, poly[w, 1] - ay
        length2 = ex * ex + ey * ey
        if length2 > 0.0:
            for i in range(k):
                t = ((qx[i] - ax) * ex + (qy[i] - ay) * ey) / length2
                t = min(max(t, 0.0), 1.0)
                px, py = ax + t * ex, ay + t * ey
                d2 = (qx[i] - px) ** 2 + (qy[i] - py) ** 2
                closer = d2 < best[i]
                best[i] = d2 if closer else best[i]
                cx[i] = px if closer else cx[i]
                cy[i] = py if closer else cy[i]
        else:  # an empty edge (a padded outline's): its vertex, as _closest computes it
            px, py = ax + 0.0 * ex, ay + 0.0 * ey
            for i in range(k):
                d2 = (qx[i] - px) ** 2 + (qy[i] - py) ** 2
                closer = d2 < best[i]
                best[i] = d2 if closer else best[i]
                cx[i] = px if closer else cx[i]
                cy[i] = py if closer else cy[i]


#: From this many starts per run and template, ICP runs them side by side (the search of every
#: start, 41 of them): a loop over the starts is longer than one over a path's points.
SIDE_BY_SIDE = 8


def icp(path, counts, outlines, nverts, angle, shift, iterations):
    """Refine every start in place; returns the mean distance per start.

    path [R, k, 2], of which run r uses its first ``counts[r]`` (>= 1) points; outlines
    [T, V, 2] with ``nverts[t]`` vertices used; angle [R, T, S] and
    shift [R, T, S, 2] are the starts (overwritten with the results).

    Each step of a start: the points in the template frame, their closest points on the
    outline, then the sums of the Procrustes step in the points' order (a sum in another order
    would differ in its last bits). Many starts (a search) are refined side by side
    (:func:`icp_side_by_side`), a few one by one (:func:`icp_one_by_one`): the same arithmetic,
    the same numbers.
    """
    refine = icp_side_by_side if angle.shape[2] >= SIDE_BY_SIDE else icp_one_by_one
    return refine(path, counts, outlines, nverts, angle, shift, iterations)


@njit(cache=True, parallel=True)
def icp_one_by_one(path, counts, outlines, nverts, angle, shift, iterations):
    """:func:`icp`, each (run, template, start) on its own: a step finds the closest points of
    all the path's points at once (:func:`_closest_each`)."""
    runs, n_t, n_s = angle.shape
    dist = np.empty((runs, n_t, n_s))
    width = path.shape[1]
    for job in prange(runs * n_t * n_s):
        r, t, s = _job(job, n_t, n_s)
        poly = outlines[t]
        nv = nverts[t]
        k = counts[r]
        qx, qy = np.empty(width), np.empty(width)
        cx, cy, best = np.empty(width), np.empty(width), np.empty(width)
        a, tx, ty = angle[r, t, s], shift[r, t, s, 0], shift[r, t, s, 1]
        for _ in range(iterations):
            c, sn = math.cos(a), math.sin(a)
            for i in range(k):
                px, py = path[r, i, 0], path[r, i, 1]
                # the path point in the template frame: R^T (p - shift)
                qx[i] = c * (px - tx) + sn * (py - ty)
                qy[i] = -sn * (px - tx) + c * (py - ty)
            _closest_each(qx, qy, k, poly, nv, cx, cy, best)
            ssx = ssy = sdx = sdy = cross = dot = 0.0
            for i in range(k):
                px, py = path[r, i, 0], path[r, i, 1]
                ssx += cx[i]
                ssy += cy[i]
                sdx += px
                sdy += py
                cross += cx[i] * py - cy[i] * px
                dot += cx[i] * px + cy[i] * py
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


@njit(cache=True, parallel=True)
def icp_side_by_side(path, counts, outlines, nverts, angle, shift, iterations):
    """:func:`icp`, the starts of each (run, template) side by side: a step takes the path's
    points one after the other, and each point's closest points and its terms of the sums for
    every start at once (the loops over the starts are the inner ones, which the compiler
    vectorises; each start's sums still add the points in their order)."""
    runs, n_t, n_s = angle.shape
    dist = np.empty((runs, n_t, n_s))
    for job in prange(runs * n_t):
        r, t = job // n_t, job % n_t
        poly = outlines[t]
        nv = nverts[t]
        k = counts[r]
        a, tx, ty = angle[r, t].copy(), shift[r, t, :, 0].copy(), shift[r, t, :, 1].copy()
        c, sn = np.empty(n_s), np.empty(n_s)
        ssx, ssy, sdx, sdy = np.empty(n_s), np.empty(n_s), np.empty(n_s), np.empty(n_s)
        cross, dot = np.empty(n_s), np.empty(n_s)
        qx, qy = np.empty(n_s), np.empty(n_s)
        cx, cy, best = np.empty(n_s), np.empty(n_s), np.empty(n_s)
        for _ in range(iterations):
            for s in range(n_s):
                c[s], sn[s] = math.cos(a[s]), math.sin(a[s])
                ssx[s] = ssy[s] = sdx[s] = sdy[s] = cross[s] = dot[s] = 0.0
            for i in range(k):
                px, py = path[r, i, 0], path[r, i, 1]
                for s in range(n_s):
                    # the path point in each start's template frame: R^T (p - shift)
                    qx[s] = c[s] * (px - tx[s]) + sn[s] * (py - ty[s])
                    qy[s] = -sn[s] * (px - tx[s]) + c[s] * (py - ty[s])
                _closest_each(qx, qy, n_s, poly, nv, cx, cy, best)
                for s in range(n_s):
                    ssx[s] += cx[s]
                    ssy[s] += cy[s]
                    sdx[s] += px
                    sdy[s] += py
                    cross[s] += cx[s] * py - cy[s] * px
                    dot[s] += cx[s] * px + cy[s] * py
            for s in range(n_s):
                msx, msy, mdx, mdy = ssx[s] / k, ssy[s] / k, sdx[s] / k, sdy[s] / k
                turn = cross[s] - k * (msx * mdy - msy * mdx)
                along = dot[s] - k * (msx * mdx + msy * mdy)
                a[s] = math.atan2(turn, along)
                cs, ss = math.cos(a[s]), math.sin(a[s])
                tx[s] = mdx - (cs * msx - ss * msy)
                ty[s] = mdy - (ss * msx + cs * msy)
        for s in range(n_s):
            angle[r, t, s], shift[r, t, s, 0], shift[r, t, s, 1] = a[s], tx[s], ty[s]
            dist[r, t, s] = _mean_distance(path[r], k, poly, nv, a[s], tx[s], ty[s])
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
    """Saliency of the perceived stimulus on 2-D grids [R, nx, ny] (see
    runner.attention.cues.saliency):
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


@njit(cache=True, inline="always")
def _on_border_2d(target, perceived, r, x, y):
    """Whether cell (x, y) of run r is a probed cell on the perceived border (see
    runner.attention.cues.perceived_border): perceived, with a perceived neighbour (3 x 3) of the
    other side (the task's material or not)."""
    if not perceived[r, x, y]:
        return False
    nx, ny = perceived.shape[1], perceived.shape[2]
    inside = target[r, x, y]
    for cx in range(max(x - 1, 0), min(x + 2, nx)):
        for cy in range(max(y - 1, 0), min(y + 2, ny)):
            if perceived[r, cx, cy] and target[r, cx, cy] != inside:
                return True
    return False


@njit(cache=True)
def followed_border_2d(target, perceived, path, out):
    """The part of the perceived border that each run follows, into ``out`` [R, nx * ny]
    (booleans): of the probed cells on the perceived border (``target`` [R, nx, ny] the cells
    perceived as the task's material, ``perceived`` [R, nx, ny] those perceived as either side),
    the ones connected (8 neighbours) to the last cell of the run's ``path`` [steps, R] (flat
    cells) that lies on the border; none when no cell of the path does. A flood fill from that
    cell: the cells it reaches are those of its connected component, the border's other cells
    are never looked at."""
    runs, nx, ny = perceived.shape
    stack = np.empty(nx * ny, np.int64)
    for r in range(runs):
        out[r, :] = False
        seed = -1
        for k in range(path.shape[0] - 1, -1, -1):
            cell = path[k, r]
            if _on_border_2d(target, perceived, r, cell // ny, cell % ny):
                seed = cell
                break
        if seed < 0:
            continue
        out[r, seed] = True
        stack[0] = seed
        top = 1
        while top:
            top -= 1
            cell = stack[top]
            x, y = cell // ny, cell % ny
            for cx in range(max(x - 1, 0), min(x + 2, nx)):
                for cy in range(max(y - 1, 0), min(y + 2, ny)):
                    near = cx * ny + cy
                    if not out[r, near] and _on_border_2d(target, perceived, r, cx, cy):
                        out[r, near] = True
                        stack[top] = near
                        top += 1


@njit(cache=True)
def marked_first(marked, width):
    """The first ``width`` cells of each run ``marked`` [R, cells] (booleans) in the order of
    a stable sort that puts the marked ones first: the marked cells in order, then the others
    in order (``np.argsort(~marked, axis=1, kind="stable")[:, :width]``), [R, width]."""
    runs, cells = marked.shape
    out = np.empty((runs, width), np.int64)
    for r in range(runs):
        n = 0
        for c in range(cells):
            if n < width and marked[r, c]:
                out[r, n] = c
                n += 1
        for c in range(cells):
            if n >= width:
                break
            if not marked[r, c]:
                out[r, n] = c
                n += 1
    return out


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
