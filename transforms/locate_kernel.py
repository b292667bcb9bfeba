"""The locate index's walk for many rays, compiled (docs/math.md, section 10): per ray, its
cube face and ``(u, v)``, the entries of its cell on each level of that face, the float32
box test, and the exact cone test of :func:`.locate._nearest_hit` on the triangles whose
boxes hold it, the nearest hit kept. The same operations in the same order as the scalar
path, so the same bits.

The box tests compact the held entries into a buffer without a branch (whether a box holds
a ray is a coin toss for the branch predictor), and only those are tested exactly. Many
rays are taken in cube-map order (:func:`ray_order`): neighbours read the same cells and
corners, which then stay in cache.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .cubemap import cube_coordinate

#: A direction counts as inside when each edge's determinant is above this (relative) amount.
INSIDE = -1e-12


@njit(cache=True, nogil=True)
def ray_hits(
    directions, points, faces, face_levels, level_counts, cell_start, entry_face, entry_box,
    everyone, held, hit_face, weights, hit_points,
):  # fmt: skip
    """The nearest triangle each direction's ray from the centre meets (the smaller position
    among equally near ones).

    One function with scalar helpers only: numba counts references on every array handed to
    a helper, each query.

    Parameters
    ----------
    directions : (k, 3) float, finite
    points, faces : the region's vertices (n, 3) and triangles (m, 3)
    face_levels : (6, L, 6) float, per cube face its grid levels' cell width, origin u and
        v, columns, rows and first cell id; ``level_counts`` (6,) int of them
    cell_start, entry_face, entry_box, everyone : the index's (:class:`.locate.LocateIndex`)
    held : (h,) int, room for the entries of a cell on each level and ``everyone``
    hit_face : (k,) int, out: the triangle, -1 for a miss or a zero direction
    weights, hit_points : (k, 3) float, out: barycentric weights and the hit, NaN for none

    Returns
    -------
    int, the number of zero directions
    """
    zero = 0
    for k in range(directions.shape[0]):
        x, y, z = _unit_ray(directions[k, 0], directions[k, 1], directions[k, 2])
        count = 0
        if np.isnan(x):
            zero += 1
        else:
            # The triangles whose float32 box holds the ray's (u, v), from its cell on each
            # level of its cube face, compacted without a branch; then everyone.
            cube, u, v = cube_coordinate(x, y, z)
            qu, qv = np.float32(u), np.float32(v)
            for level in range(level_counts[cube]):
                cell = _cell(u, v, face_levels[cube, level, 0], face_levels[cube, level, 1],
                             face_levels[cube, level, 2], face_levels[cube, level, 3],
                             face_levels[cube, level, 4], face_levels[cube, level, 5])  # fmt: skip
                first, stop = (cell_start[cell], cell_start[cell + 1]) if cell >= 0 else (0, 0)
                for entry in range(first, stop):
                    inside = (entry_box[entry, 0] <= qu) & (qu <= entry_box[entry, 2])
                    inside &= (entry_box[entry, 1] <= qv) & (qv <= entry_box[entry, 3])
                    held[count] = entry_face[entry]
                    count += inside
            for slot in range(len(everyone)):
                held[count] = everyone[slot]
                count += 1
        best, nearest, e0, e1, e2, total = -1, np.inf, np.nan, np.nan, np.nan, np.nan
        for slot in range(count):
            face = held[slot]
            a, b, c = faces[face, 0], faces[face, 1], faces[face, 2]
            hit, depth, f0, f1, f2, sum_ = triangle_hit(
                x, y, z, points[a, 0], points[a, 1], points[a, 2], points[b, 0], points[b, 1],
                points[b, 2], points[c, 0], points[c, 1], points[c, 2],
            )  # fmt: skip
            if hit and (depth < nearest or (depth == nearest and face < best)):
                best, nearest, e0, e1, e2, total = face, depth, f0, f1, f2, sum_
        depth = nearest if best >= 0 else np.nan
        hit_face[k] = best
        weights[k, 0], weights[k, 1], weights[k, 2] = e0 / total, e1 / total, e2 / total
        hit_points[k, 0], hit_points[k, 1], hit_points[k, 2] = depth * x, depth * y, depth * z
    return zero


@njit(cache=True, nogil=True, inline="always")
def _unit_ray(x, y, z):
    """:func:`.arrays.unit_rows` of one row: divided by its largest magnitude, then by its
    length (NaN for a zero row)."""
    largest = max(abs(x), abs(y), abs(z))
    if largest == 0.0:
        return np.nan, np.nan, np.nan
    x, y, z = x / largest, y / largest, z / largest
    length = math.sqrt(x * x + y * y + z * z)
    return x / length, y / length, z / length


@njit(cache=True, nogil=True, inline="always")
def _cell(u, v, width, u0, v0, columns, rows, offset):
    """The cell of a grid level (``width`` wide from ``(u0, v0)``, ``columns`` x ``rows``,
    the first numbered ``offset``) that holds ``(u, v)``; -1 outside."""
    column, row = math.floor((u - u0) / width), math.floor((v - v0) / width)
    if 0 <= column < columns and 0 <= row < rows:
        return int(offset + row * columns + column)
    return -1


@njit(cache=True, nogil=True, inline="always")
def triangle_hit(qx, qy, qz, x0, y0, z0, x1, y1, z1, x2, y2, z2):
    """Whether the ray ``(qx, qy, qz)`` meets the triangle of corners ``(x0, y0, z0)``,
    ...: ``(hit, depth, e0, e1, e2, total)``, the weights being ``e / total``. The test of
    :func:`.locate._nearest_hit`, operation for operation."""
    ax, ay, az = y1 * z2 - z1 * y2, z1 * x2 - x1 * z2, x1 * y2 - y1 * x2  # c1 x c2
    e0 = qx * ax + qy * ay + qz * az
    e1 = qx * (y2 * z0 - z2 * y0) + qy * (z2 * x0 - x2 * z0) + qz * (x2 * y0 - y2 * x0)
    e2 = qx * (y0 * z1 - z0 * y1) + qy * (z0 * x1 - x0 * z1) + qz * (x0 * y1 - y0 * x1)
    total = e0 + e1 + e2
    slack = INSIDE * (abs(e0) + abs(e1) + abs(e2))
    side = 1.0 if total > 0.0 else -1.0
    if total == 0.0 or side * e0 < slack or side * e1 < slack or side * e2 < slack:
        return False, 0.0, e0, e1, e2, total
    depth = (x0 * ax + y0 * ay + z0 * az) / total
    return depth > 0.0, depth, e0, e1, e2, total


@njit(cache=True, nogil=True)
def ray_order(directions, squares):
    """The directions ((k, 3) float) by cube face, then row and column of ``squares`` x
    ``squares`` squares of it (a counting sort; zero directions first): (k,) int, their
    rows in that order, and (k, 3) float, the directions in it."""
    k = directions.shape[0]
    key = np.zeros(k, dtype=np.int64)
    start = np.zeros(6 * squares * squares + 1, dtype=np.int64)
    half = squares / 2.0
    for i in range(k):
        x, y, z = directions[i, 0], directions[i, 1], directions[i, 2]
        if x != 0.0 or y != 0.0 or z != 0.0:
            cube, u, v = cube_coordinate(x, y, z)
            column = min(max(int((u + 1.0) * half), 0), squares - 1)
            row = min(max(int((v + 1.0) * half), 0), squares - 1)
            key[i] = (cube * squares + row) * squares + column
        start[key[i] + 1] += 1
    for j in range(1, len(start)):
        start[j] += start[j - 1]
    order = np.empty(k, dtype=np.int64)
    ordered = np.empty((k, 3))
    for i in range(k):
        place = start[key[i]]
        start[key[i]] += 1
        order[place] = i
        ordered[place, 0], ordered[place, 1] = directions[i, 0], directions[i, 1]
        ordered[place, 2] = directions[i, 2]
    return order, ordered


@njit(cache=True, nogil=True)
def put_rows(order, hit_face, weights, hit_points, out_face, out_weights, out_points):
    """Row ``i`` of the first three arrays to row ``order[i]`` of the last three."""
    for i in range(len(order)):
        k = order[i]
        out_face[k] = hit_face[i]
        for j in range(3):
            out_weights[k, j] = weights[i, j]
            out_points[k, j] = hit_points[i, j]
