"""Strands: guide hairs grown from sites along the growth field, kept out of the head
(docs/math.md, section 20).

A strand of length ``L`` is a polyline of ``m`` points, each segment ``L / (m - 1)`` long (the
first no longer than ``free``, the others sharing the rest).
It leaves its root along the site's direction (the exit angle), bends over towards the
field's tangent, and runs on at a clearance ``c`` above the scalp, following the field:

* ``P_0`` is the root, ``P_1 = P_0 + delta d`` (``d`` the site's direction);
* its height above the scalp then goes from ``h_1 = delta sin(a)`` towards ``c``,
  ``h_k = c + (h_1 - c) exp(-(k - 1) delta / bend)``;
* its foot on the scalp is marched on the map along the field (the map is seam-free: one
  plane, no chart to change), by the surface length the segment leaves for it, and lifted
  (the map is linear in each triangle), with the vertex normals interpolated there;
* ``P_k`` is the point ``delta`` from ``P_{k-1}`` towards ``foot + h_k n``: every segment
  keeps its length, so the arc length is ``L`` to rounding;
* a point nearer the surface than its floor (``c / 2`` past an arc length ``free`` from the
  root, ``0`` before), or behind it, is put back on the floor along the nearest surface
  point's normal (:class:`SurfaceGuard`), before the next segment starts from it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from .arrays import combine, face_cross, solve_2x2, unit_rows
from .checkpoints import checkpoint
from .growth import GrowthField, triangle_edges
from .mapping import MapTriangles

#: Candidate triangles for a point's nearest: those of the nearest centroids.
NEAREST_CANDIDATES = 8


@dataclass(frozen=True)
class Roots:
    """Where strands start: ``points`` (n, 3) on the surface, ``directions`` (n, 3) unit,
    ``normals`` (n, 3) unit, ``triangles`` (n,) int (positions in the region's faces) and
    ``map_points`` (n, 2)."""

    points: np.ndarray
    directions: np.ndarray
    normals: np.ndarray
    triangles: np.ndarray
    map_points: np.ndarray


@dataclass(frozen=True)
class StrandShape:
    """How strands lie: ``points`` a strand (2 or more), the ``clearance`` above the scalp
    once bent over, the ``bend``, the arc length over which the height settles, and
    ``free``, the arc length from the root within which a strand may lie nearer the scalp
    than half the clearance (it leaves the skin there); mesh units all."""

    points: int
    clearance: float
    bend: float
    free: float


class SurfaceGuard:
    """The nearest points of a triangle mesh and its outward normals there, for keeping
    points out of it.

    Parameters
    ----------
    vertices : (k, 3) float
    faces : (m, 3) int
    outward : +1 or -1, the sign that turns the faces' winding normals outwards
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, outward: int) -> None:
        self._corners = np.asarray(vertices, dtype=np.float64)[faces]  # (m, 3, 3)
        normals, _ = unit_rows(face_cross(vertices, faces))
        self._normals = outward * normals
        self._tree = cKDTree(self._corners.mean(axis=1))

    def nearest(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """For (p, 3) ``points``: the nearest surface points (p, 3) among the triangles of
        the ``NEAREST_CANDIDATES`` nearest centroids, the outward unit normals of their
        triangles (p, 3) and the signed heights of the points above them (p,)."""
        count = min(NEAREST_CANDIDATES, len(self._corners))
        _, candidates = self._tree.query(points, k=count)
        candidates = candidates.reshape(len(points), count)
        corners = self._corners[candidates]  # (p, c, 3, 3)
        closest = _closest_on_triangles(np.repeat(points, count, axis=0), corners.reshape(-1, 3, 3))
        closest = closest.reshape(len(points), count, 3)
        gap = np.linalg.norm(closest - points[:, None, :], axis=2)
        best = np.argmin(gap, axis=1)
        rows = np.arange(len(points))
        foot = closest[rows, best]
        normal = self._normals[candidates[rows, best]]
        return foot, normal, np.einsum("pd,pd->p", points - foot, normal)


def grow_strands(
    triangles: MapTriangles,
    field: GrowthField,
    normals: np.ndarray,
    roots: Roots,
    lengths: np.ndarray,
    shape: StrandShape,
    guard: SurfaceGuard,
) -> np.ndarray:
    """(n, m, 3) float: the strands of ``roots`` (docs/math.md, section 20).

    Parameters
    ----------
    triangles : MapTriangles, the region's map and surface
    field : GrowthField, the growth field on that map
    normals : (k, 3) float, unit, the region's vertex normals, outwards
    roots : Roots
    lengths : (n,) float > 0, each strand's arc length
    shape : StrandShape
    guard : SurfaceGuard, of the whole mesh
    """
    n, m = len(roots.points), shape.points
    lengths = np.asarray(lengths, dtype=np.float64)
    first, step = _steps(lengths, m, shape.free)
    strands = np.empty((n, m, 3))
    strands[:, 0] = roots.points
    if n == 0:
        return strands
    strands[:, 1] = roots.points + first[:, None] * roots.directions
    rise = np.einsum("pd,pd->p", roots.directions, roots.normals)
    height = first * rise
    foot, triangle = _marched(triangles, field, roots.map_points, roots.triangles,
                              first * np.sqrt(np.clip(1.0 - rise**2, 0.0, 1.0)))  # fmt: skip
    for k in range(2, m):
        checkpoint()
        arc = first + (k - 1) * step
        settled = np.exp(-(arc - first) / shape.bend)
        target = shape.clearance + (first * rise - shape.clearance) * settled
        along = step * np.sqrt(np.clip(1.0 - ((target - height) / step) ** 2, 0.0, 1.0))
        foot, triangle = _marched(triangles, field, foot, triangle, along)
        ground, up = _lifted(triangles, normals, foot, triangle)
        floor = np.where(arc > shape.free, 0.5 * shape.clearance, 0.0)
        strands[:, k] = _next_point(guard, strands[:, k - 1], ground + target[:, None] * up,
                                    step, floor)  # fmt: skip
        height = target
    return strands


def _steps(lengths: np.ndarray, points: int, free: float) -> tuple[np.ndarray, np.ndarray]:
    """(n,) each: the first segment's length and the others': even, but the first no longer
    than ``free`` (so that it ends where a strand may still lie low), the others sharing the
    rest. A strand of two points is one segment."""
    if points == 2:
        return lengths, lengths
    even = lengths / (points - 1)
    first = np.minimum(even, free) if free > 0 else even
    return first, (lengths - first) / (points - 2)


#: Times a point put back on its floor is brought back to its segment's length, and put back
#: again if that took it below.
KEEP_OUT_ROUNDS = 4


def _next_point(guard: SurfaceGuard, last: np.ndarray, aim: np.ndarray, step, floor):
    """(p, 3): the point ``step`` from ``last`` towards ``aim``, kept at its ``floor`` or above
    the surface: put back on it, and again ``step`` from ``last`` towards that, a few
    rounds; the last put back wins (the segment then a little off its length)."""
    point = last + step[:, None] * unit_rows(aim - last)[0]
    for _ in range(KEEP_OUT_ROUNDS):
        kept = _kept_out(guard, point, floor)
        moved = np.any(kept != point, axis=1)
        if not moved.any():
            return point
        point[moved] = last[moved] + step[moved, None] * unit_rows(kept[moved] - last[moved])[0]
    return _kept_out(guard, point, floor)


def _kept_out(guard: SurfaceGuard, points: np.ndarray, floor: np.ndarray) -> np.ndarray:
    """``points`` with those nearer the surface than ``floor`` ((p,)), or behind it, put at
    ``floor`` from their nearest surface point."""
    foot, normal, above = guard.nearest(points)
    low = above < floor
    out = points.copy()
    if not low.any():
        return out
    # Out along the way from the nearest point when outside (the nearest point stays the
    # nearest along it, so the distance is the floor), along its triangle's normal inside.
    away, at_foot = unit_rows(points[low] - foot[low])
    outside = (above[low] > 0) & ~at_foot
    way = np.where(outside[:, None], away, normal[low])
    out[low] = foot[low] + floor[low, None] * way
    return out


def _marched(triangles: MapTriangles, field: GrowthField, points, faces, distances):
    """The map points ``distances`` ((p,) surface length) on from ``points`` ((p, 2), in
    ``faces``) along the field, and their triangles (a point off the region keeps its last
    triangle: the map's linear piece there is carried on)."""
    directions = field.map_directions(points, faces)
    # The surface length of a unit map step along d: |J d|, J = E3 E2^-1 the triangle's.
    e2, e3 = triangle_edges(triangles, faces)
    stretch = np.linalg.norm(np.einsum("pij,pj->pi", e3, solve_2x2(e2, directions)), axis=1)
    stretch = np.where(np.isfinite(stretch) & (stretch > 0), stretch, 1.0)
    moved = points + (distances / stretch)[:, None] * directions
    found, _ = triangles.locate(moved)
    return moved, np.where(found >= 0, found, faces)


def _lifted(triangles: MapTriangles, normals: np.ndarray, points, faces):
    """The surface points of map ``points`` by their triangles' linear maps (carried on
    beyond a triangle for a point off the region) and the unit normals there."""
    weights = triangles.barycentric(faces, points)
    weights = np.where(np.isfinite(weights), weights, 1.0 / 3.0)
    ground = combine(triangles.surface_points, triangles.faces, faces, weights)
    return ground, _surface_normals(triangles, normals, points, faces, weights)


def _surface_normals(triangles, normals, points, faces, weights=None) -> np.ndarray:
    """(p, 3) unit: the vertex ``normals`` interpolated at map ``points`` in ``faces``
    (weights clipped to the triangle)."""
    if weights is None:
        weights = triangles.barycentric(faces, points)
        weights = np.where(np.isfinite(weights), weights, 1.0 / 3.0)
    inside = np.clip(weights, 0.0, None)
    inside /= np.maximum(inside.sum(axis=1, keepdims=True), 1e-300)
    return unit_rows(combine(normals, triangles.faces, faces, inside))[0]


def _closest_on_triangles(points: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """(p, 3): the closest point of each triangle (p, 3, 3) to each point (p, 3), by its
    barycentric region (Ericson, Real-Time Collision Detection, 5.1.5), vectorised."""
    a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
    ab, ac, ap = b - a, c - a, points - a
    d1, d2 = _dot(ab, ap), _dot(ac, ap)
    bp = points - b
    d3, d4 = _dot(ab, bp), _dot(ac, bp)
    cp = points - c
    d5, d6 = _dot(ab, cp), _dot(ac, cp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        total = va + vb + vc
        v, w = vb / total, vc / total
        inside = a + v[:, None] * ab + w[:, None] * ac
        t_ab = d1 / (d1 - d3)
        t_ac = d2 / (d2 - d6)
        t_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
    # Ericson's tests in reverse, so that the first of his that holds is the one kept.
    out = inside
    out = _where(out, (va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0), b + t_bc[:, None] * (c - b))
    out = _where(out, (vb <= 0) & (d2 >= 0) & (d6 <= 0), a + t_ac[:, None] * ac)
    out = _where(out, (d6 >= 0) & (d5 <= d6), c)
    out = _where(out, (vc <= 0) & (d1 >= 0) & (d3 <= 0), a + t_ab[:, None] * ab)
    out = _where(out, (d3 >= 0) & (d4 <= d3), b)
    out = _where(out, (d1 <= 0) & (d2 <= 0), a)
    bad = ~np.isfinite(out).all(axis=1)  # a triangle of no area: its nearest corner
    if bad.any():
        gaps = np.linalg.norm(corners[bad] - points[bad, None, :], axis=2)
        out[bad] = corners[bad][np.arange(bad.sum()), np.argmin(gaps, axis=1)]
    return out


def _dot(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return np.einsum("pd,pd->p", u, v)


def _where(current: np.ndarray, chosen: np.ndarray, value: np.ndarray) -> np.ndarray:
    return np.where(chosen[:, None], value, current)
