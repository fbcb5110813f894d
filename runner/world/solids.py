"""The shapes of a workspace: polygons (outlines of a 2-D workspace) and the solids of a 3-D one,
boxes, ellipsoids, spheres and prisms (a polygon extruded along z).

A 3-D scenario places solids in a volume of cells, as a 2-D one places polygons on a surface.
A solid answers two questions: which points lie inside it (the material of a cell is that of the
last solid holding its centre), and where its surface is (points spread evenly over it, for the
shape cue's templates and their registration).

Even spreading: the surface is first sampled densely (a lattice on each face, rings on an
ellipsoid), then ``n`` points are kept by farthest-point sampling, each new point the sample
farthest from those already kept, so that any count is spread as evenly as the dense sample
allows, whatever the solid.

>>> box = SolidSpec(box=[0.1, 0.06, 0.04])
>>> box.inside(np.array([[0.0, 0.0, 0.0], [0.06, 0.0, 0.0]])).tolist()
[True, False]
>>> pts = box.surface(200)
>>> pts.shape, bool(np.allclose(np.abs(pts).max(axis=0), [0.05, 0.03, 0.02]))
((200, 3), True)
"""

from __future__ import annotations

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

#: dense surface samples per kept point before farthest-point sampling
_DENSITY = 12
#: the keys of a solid template, one of which it gives
SOLID_KEYS = ("box", "ellipsoid", "sphere", "prism")


def polygon_area(polygon: np.ndarray) -> float:
    """The area enclosed by a simple polygon [V, 2] (shoelace formula)."""
    x, y = polygon[:, 0], polygon[:, 1]
    return float(abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))) / 2)


def check_outline(points: list[list[float]], what: str) -> None:
    """A closed outline: at least three points of two finite coordinates, enclosing an area."""
    if len(points) < 3:
        raise ValueError(f"{what}: expected at least 3 points [x, y], found {len(points)}")
    for point in points:
        if len(point) != 2 or not all(np.isfinite(point)):
            raise ValueError(f"{what}: expected points [x, y] of two finite numbers, found "
                             f"{point}")
    if not polygon_area(np.asarray(points, float)) > 0:
        raise ValueError(f"{what}: expected a simple polygon enclosing an area (corners in "
                         "order, sides that do not cross), found an area of 0")


class PrismSpec(BaseModel):
    """A polygon [[x, y], ...] (metres, any simple polygon) extruded over ``height`` along z,
    from z = -height/2 to height/2."""

    model_config = ConfigDict(extra="forbid")
    polygon: list[list[float]]
    height: float = Field(gt=0, allow_inf_nan=False)

    @model_validator(mode="after")
    def _points(self) -> PrismSpec:
        check_outline(self.polygon, "prism polygon")
        return self


class SolidSpec(BaseModel):
    """A 3-D template: exactly one of ``box: [lx, ly, lz]`` (edge lengths), ``ellipsoid:
    [a, b, c]`` (semi-axes), ``sphere: r`` or ``prism: {polygon: [...], height: h}``, all in
    metres, in the solid's own frame (a box, an ellipsoid and a sphere centred on its origin, a
    prism's polygon where it is written, from z = -h/2 to h/2)."""

    model_config = ConfigDict(extra="forbid")
    box: list[float] | None = None
    ellipsoid: list[float] | None = None
    sphere: float | None = None
    prism: PrismSpec | None = None

    @model_validator(mode="after")
    def _one_solid(self) -> SolidSpec:
        given = [k for k in SOLID_KEYS if getattr(self, k) is not None]
        if len(given) != 1:
            raise ValueError("expected exactly one of 'box: [lx, ly, lz]', 'ellipsoid: [a, b, c]', "
                             "'sphere: r' or 'prism: {polygon: [[x, y], ...], height: h}', found "
                             f"{', '.join(given) or 'none'}")
        for key in ("box", "ellipsoid"):
            value = getattr(self, key)
            if value is not None and not (len(value) == 3
                                          and all(np.isfinite(v) and v > 0 for v in value)):
                raise ValueError(f"{key}: expected three positive lengths (metres), found {value}")
        if self.sphere is not None and not (np.isfinite(self.sphere) and self.sphere > 0):
            raise ValueError(f"sphere: expected a positive radius (metres), found {self.sphere}")
        return self

    @property
    def _semi_axes(self) -> np.ndarray:
        r = self.sphere
        return np.asarray(self.ellipsoid if self.ellipsoid is not None else (r, r, r), float)

    def inside(self, points: np.ndarray) -> np.ndarray:
        """Which of ``points`` [N, 3] (in the solid's frame) lie inside it."""
        p = np.asarray(points, float)
        if self.box is not None:
            return np.all(np.abs(p) <= np.asarray(self.box) / 2, axis=1)
        if self.prism is not None:
            return (np.abs(p[:, 2]) <= self.prism.height / 2) \
                & inside(p[:, :2], np.asarray(self.prism.polygon, float))
        return ((p / self._semi_axes) ** 2).sum(axis=1) <= 1.0

    def surface(self, n: int) -> np.ndarray:
        """``n`` points [n, 3] spread evenly over the surface (see the module)."""
        m = _DENSITY * n
        for _ in range(4):  # a sliver's caps hold few of their lattice's points: finer
            dense = self._dense(m)
            if len(dense) >= n:
                return farthest_points(dense, n)
            m *= 4
        raise ValueError(f"the solid is too thin to spread {n:,} points over its surface "
                         f"({len(dense):,} found)")

    def _dense(self, m: int) -> np.ndarray:
        """About ``m`` points on the surface, roughly evenly spaced."""
        if self.box is not None:
            size = np.asarray(self.box, float)
            area = 2 * (size[0] * size[1] + size[1] * size[2] + size[0] * size[2])
            # no coarser than the area asks, and no finer than the edges allow (a thin box would
            # otherwise take a lattice as long as its edges over a tiny spacing): about 7 m points
            h = max(np.sqrt(area / m), 4 * size.sum() / m)
            out = []
            for axis in range(3):
                u, v = [a for a in range(3) if a != axis]
                gu = _lattice(size[u], h)
                gv = _lattice(size[v], h)
                uu, vv = np.meshgrid(gu, gv, indexing="ij")
                for side in (-0.5, 0.5):
                    face = np.zeros((uu.size, 3))
                    face[:, u], face[:, v], face[:, axis] = uu.ravel(), vv.ravel(), side * size[axis]
                    out.append(face)
            return np.unique(np.concatenate(out).round(12), axis=0)
        if self.prism is not None:
            poly = np.asarray(self.prism.polygon, float)
            height = self.prism.height
            closed = np.vstack([poly, poly[:1]])
            perimeter = np.hypot(*np.diff(closed, axis=0).T).sum()
            extent = poly.max(axis=0) - poly.min(axis=0)
            # the caps are sampled over the polygon's bounding box: its area bounds their count;
            # the lengths bound the lattices' edges (as for a box)
            h = max(np.sqrt((perimeter * height + 2 * extent[0] * extent[1]) / m),
                    (2 * perimeter + height + 2 * extent.sum()) / m)
            ring = outline_points(poly, max(int(np.ceil(perimeter / h)), 3))
            zs = _lattice(height, h)
            walls = np.concatenate([np.column_stack([ring, np.full(len(ring), z)]) for z in zs])
            gx = poly.min(axis=0)[0] + _lattice(extent[0], h) + extent[0] / 2
            gy = poly.min(axis=0)[1] + _lattice(extent[1], h) + extent[1] / 2
            xx, yy = np.meshgrid(gx, gy, indexing="ij")
            flat = np.column_stack([xx.ravel(), yy.ravel()])
            cap = flat[inside(flat, poly)]
            caps = [np.column_stack([cap, np.full(len(cap), z)]) for z in (-height / 2, height / 2)]
            return np.concatenate([walls, *caps])
        # ellipsoid: a Fibonacci lattice on the unit sphere, stretched (denser where the surface
        # is stretched least; the farthest-point sampling evens it out)
        i = np.arange(m) + 0.5
        z = 1 - 2 * i / m
        phi = np.pi * (3 - np.sqrt(5)) * i
        r = np.sqrt(1 - z ** 2)
        return np.column_stack([r * np.cos(phi), r * np.sin(phi), z]) * self._semi_axes

def outline_points(polygon: np.ndarray, n: int) -> np.ndarray:
    """``n`` points evenly spaced along the closed outline of ``polygon`` (arc length)."""
    closed = np.vstack([polygon, polygon[:1]])
    seg = np.diff(closed, axis=0)
    length = np.hypot(seg[:, 0], seg[:, 1])
    cum = np.concatenate([[0.0], np.cumsum(length)])
    s = np.arange(n) * cum[-1] / n
    i = np.searchsorted(cum, s, side="right") - 1
    frac = (s - cum[i]) / length[i]
    return closed[i] + frac[:, None] * seg[i]


def inside(points: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """Even-odd rule: which of ``points`` [N, 2] lie inside ``polygon`` [V, 2]."""
    x, y = points[:, 0:1], points[:, 1:2]
    x1, y1 = polygon[:, 0], polygon[:, 1]
    x2, y2 = np.roll(x1, -1), np.roll(y1, -1)
    crosses = (y1 > y) != (y2 > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        xint = x1 + (y - y1) * (x2 - x1) / (y2 - y1)
    return np.logical_xor.reduce(crosses & (x < xint), axis=1)


def _lattice(length: float, step: float) -> np.ndarray:
    """Points across [-length/2, length/2], both ends included, at most ``step`` apart."""
    count = max(int(np.ceil(length / step)), 1) + 1
    return np.linspace(-length / 2, length / 2, count)


def farthest_points(points: np.ndarray, n: int) -> np.ndarray:
    """``n`` of ``points`` [m, d] chosen greedily, each the farthest from those already chosen,
    starting from the point farthest from their centroid (deterministic)."""
    points = np.asarray(points, float)
    if n > len(points):
        raise ValueError(f"asked for {n} points of a sample of {len(points)}")
    first = int(np.argmax(((points - points.mean(axis=0)) ** 2).sum(axis=1)))
    chosen = [first]
    nearest = ((points - points[first]) ** 2).sum(axis=1)
    for _ in range(n - 1):
        nxt = int(np.argmax(nearest))
        chosen.append(nxt)
        np.minimum(nearest, ((points - points[nxt]) ** 2).sum(axis=1), out=nearest)
    return points[chosen]


def yaw(degrees: float) -> np.ndarray:
    """The rotation [3, 3] by ``degrees`` about z (counter-clockwise seen from above)."""
    t = np.deg2rad(degrees)
    c, s = np.cos(t), np.sin(t)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
