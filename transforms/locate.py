"""From the 2D map back to the surface: which region triangle the ray from the centre in a
given direction hits, and where (the inverse of flattening, per point).

Seen from the centre, a triangle covers the spherical triangle of its corners' directions, and
a direction ``q`` lies in it when ``det[q, c_i, c_j]`` has the sign of ``det[c0, c1, c2]`` for
all three edges. Those three determinants, divided by their sum, are also the barycentric
coordinates of the ray's hit point. Candidates come from a k-d tree over the triangles'
direction caps (each triangle lies in the cap around its corners' mean direction reaching its
farthest corner), one tree per size class so that a few large triangles do not widen every
search.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from .arrays import as_faces, as_points, unit_rows
from .errors import TransformInputError, listed_rows

#: Neighbours asked of a tree per query at first; doubled where that many are within reach.
_FIRST_NEIGHBOURS = 8
#: Queries tested against candidates at a time.
_CHUNK = 65536
#: A direction counts as inside when each edge's determinant is above this (relative) amount.
_INSIDE = -1e-12


@dataclass(frozen=True)
class Hits:
    """Where rays from the centre meet a region.

    Attributes
    ----------
    faces : (k,) int, position of the triangle hit in the region's face list, -1 for a miss
    barycentric : (k, 3) float, weights of the triangle's corners (NaN for a miss)
    points : (k, 3) float, the hit points in the local frame (NaN for a miss)
    """

    faces: np.ndarray
    barycentric: np.ndarray
    points: np.ndarray


def locate(vertices_local, faces, directions) -> Hits:
    """The region triangle each ray from the centre (the local origin) meets first.

    Parameters
    ----------
    vertices_local : (n, 3) float, vertices in the local frame (none at the centre)
    faces : (m, 3) int, the region's triangles
    directions : (k, 3) float, the rays' directions (non-zero; need not be unit)

    Returns
    -------
    Hits

    Raises
    ------
    TransformInputError
        A vertex at the centre, or a zero direction.
    """
    points = as_points(vertices_local, "vertices")
    faces = as_faces(faces, len(points))
    rays, zero = unit_rows(as_points(directions, "directions"))
    if zero.any():
        raise TransformInputError("directions", "a direction is zero", np.flatnonzero(zero))
    corner_units, at_centre = unit_rows(points)
    if at_centre.any():
        used = np.bincount(faces.ravel(), minlength=len(points)) > 0
        if (at_centre & used).any():  # a vertex no triangle uses may be anywhere
            text, rows = listed_rows(at_centre & used, "vertex")
            raise TransformInputError("vertices", f"{text}: at the centre, no direction", rows)
    k = len(rays)
    hit_face = np.full(k, -1, dtype=np.int64)
    hit_depth = np.full(k, np.inf)
    weights = np.full((k, 3), np.nan)
    if len(faces) == 0 or k == 0:
        return Hits(hit_face, weights, np.full((k, 3), np.nan))

    corners = corner_units[faces]  # (m, 3, 3)
    middle, _ = unit_rows(corners.sum(axis=1))
    reach = np.sqrt(
        np.maximum(2.0 - 2.0 * np.einsum("mcj,mj->mc", corners, middle).min(axis=1), 0.0)
    )
    reach = reach * (1.0 + 1e-9) + 1e-12
    # A cap of 90 degrees or more may not hold its triangle (it is not convex): such huge
    # triangles (next to the centre) are tested against every query.
    huge = reach >= np.sqrt(2.0) * (1.0 - 1e-9)
    everyone = np.arange(k)
    for face in np.flatnonzero(huge):
        _test(points, faces, rays, everyone, np.full(k, face), hit_face, hit_depth, weights)
    for members in _size_classes(reach, np.flatnonzero(~huge)):
        tree = cKDTree(middle[members])
        limit = float(reach[members].max())
        pending = np.arange(k)
        wanted = _FIRST_NEIGHBOURS
        while pending.size:
            count = min(wanted, len(members))
            distance, found = tree.query(rays[pending], k=count, distance_upper_bound=limit)
            distance = distance.reshape(len(pending), count)
            found = found.reshape(len(pending), count)
            within = np.isfinite(distance)
            query_rows, slot = np.nonzero(within)
            candidates = members[found[query_rows, slot]]
            queries = pending[query_rows]
            close = distance[query_rows, slot] <= reach[candidates]
            _test(
                points, faces, rays, queries[close], candidates[close], hit_face, hit_depth, weights
            )
            # Where every neighbour asked for was within reach, more may be: ask again.
            full = within[:, -1] & (count < len(members))
            pending = pending[full]
            wanted *= 4
    hit = hit_face >= 0
    located = np.full((k, 3), np.nan)
    f = faces[hit_face[hit]]
    located[hit] = np.einsum("kc,kcj->kj", weights[hit], points[f])
    return Hits(hit_face, weights, located)


def _size_classes(reach: np.ndarray, faces: np.ndarray) -> list[np.ndarray]:
    """``faces`` grouped by their cap's reach, each class at most twice its smallest."""
    if faces.size == 0:
        return []
    order = faces[np.argsort(reach[faces], kind="stable")]
    sizes = reach[order]
    smallest = max(float(sizes[0]), 1e-12)
    classes = np.floor(np.log2(np.maximum(sizes, smallest) / smallest)).astype(np.int64)
    cuts = np.flatnonzero(np.diff(classes)) + 1
    return np.split(order, cuts)


def _test(points, faces, rays, queries, candidates, hit_face, hit_depth, weights) -> None:
    """Test (query, triangle) pairs; keep, per query, the nearest hit."""
    for start in range(0, len(queries), _CHUNK):
        q_ids = queries[start : start + _CHUNK]
        f_ids = candidates[start : start + _CHUNK]
        q = rays[q_ids]
        c0, c1, c2 = (points[faces[f_ids, i]] for i in range(3))
        e = np.stack(
            [
                np.einsum("kj,kj->k", q, np.cross(c1, c2)),
                np.einsum("kj,kj->k", q, np.cross(c2, c0)),
                np.einsum("kj,kj->k", q, np.cross(c0, c1)),
            ],
            axis=1,
        )
        total = e.sum(axis=1)  # q . n with n = (c1 - c0) x (c2 - c0)
        scale = np.abs(e).sum(axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            inside = (np.sign(total)[:, None] * e >= _INSIDE * scale[:, None]).all(axis=1)
            inside &= total != 0.0
            volume = np.einsum("kj,kj->k", c0, np.cross(c1, c2))  # det[c0, c1, c2]
            depth = volume / total  # the hit is at depth * q
            inside &= depth > 0.0
        rows = np.flatnonzero(inside)
        if rows.size == 0:
            continue
        # The nearest hit per query: order by depth, take each query's first.
        rows = rows[np.lexsort((depth[rows], q_ids[rows]))]
        first = np.ones(rows.size, dtype=bool)
        first[1:] = q_ids[rows][1:] != q_ids[rows][:-1]
        rows = rows[first]
        better = depth[rows] < hit_depth[q_ids[rows]]
        rows = rows[better]
        target = q_ids[rows]
        hit_face[target] = f_ids[rows]
        hit_depth[target] = depth[rows]
        weights[target] = e[rows] / total[rows, None]
