"""From the 2D map back to the surface: which region triangle the ray from the centre in a
given direction hits first, and where (the inverse of flattening, per point; docs/math.md,
section 10).

Seen from the centre, a triangle covers the cone of its corners (their combinations with
non-negative weights), and a direction ``q`` lies in it when ``det[q, c_i, c_j]`` has the
sign of ``det[c0, c1, c2]`` for all three edges. Those three determinants, divided by their
sum, are also the barycentric coordinates of the ray's hit point, and ``det[c0, c1, c2]``
over their sum is its depth along ``q``: of the triangles a ray meets, the nearest is kept.

Candidates come from a cube map of directions (:class:`LocateIndex`), built in one
vectorised pass: on each face of the cube around the centre, the gnomonic projection
``(u, v) = (p_b, p_c) / |p_a|`` turns the cone of a triangle whose corners are all in front
of that face into the straight triangle of its projected corners, so the box of those
corners holds it exactly. Each box goes into the cells it overlaps of a grid over the face,
on the level whose cells are at least as wide as the box (so at most 2 x 2 of them), and a
query looks in its own cell on each level, then compares its ``(u, v)`` with the boxes
there before the exact test (:mod:`.cubemap` builds the map). Triangles that reach a face
without being in front of it (a few very large ones next to the centre) are tested against
every query.

Many queries walk the index in one compiled loop (:mod:`.locate_kernel`, numba), in cube-map
order; a click's few in plain floats (:meth:`LocateIndex._query_few`); both with the same
operations, so the same bits. For a handful of queries the index would cost more than it
saves: :func:`locate` then tests every triangle against the four planes through each ray (no
index; same exact test).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from .arrays import as_faces, as_points, blocks, cross_rows, unit_rows
from .cubemap import (
    SIDE,
    cube_coordinate,
    cube_coordinates,
    grid_of,
    sorted_by_cell,
    take_rows,
    triangle_boxes,
)
from .errors import TransformInputError, listed_rows
from .locate_kernel import INSIDE, put_rows, ray_hits, ray_order

#: Up to this many queries, testing every triangle costs no more than building the index: a
#: build costs about as much as 15 to 18 direct passes on 100k and on 1.6M faces
#: (docs/benchmarks.md, locate).
DIRECT_QUERIES = 16
#: Up to this many queries, :meth:`LocateIndex.query` looks each one up on its own in scalar
#: arithmetic (a click on the map): for so few, a pass of array operations per step costs
#: more than the step.
FEW_QUERIES = 4
#: From this many queries on, :meth:`LocateIndex.query` takes them in cube-map order: its
#: counting sort costs about as much as the cache misses it saves on this many.
SORTED_QUERIES = 4096
#: The cube-map order's squares per side of a cube face.
_SQUARES = 128
#: (query, triangle) pairs handled at a time.
_PAIRS = 1 << 18


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

    Builds a :class:`LocateIndex` unless there are at most ``DIRECT_QUERIES`` queries, which
    are tested against every triangle directly (a pass over the vertices and the faces per
    query; the build costs about as much as ``DIRECT_QUERIES`` of them). Same answers either
    way (docs/math.md, section 10).

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
    rays = _rays(directions)
    points, faces = _checked(vertices_local, faces)
    if len(rays) <= DIRECT_QUERIES:
        return _hits(rays, *_nearest(points, faces, rays, _direct_pairs(points, faces, rays)))
    return LocateIndex._of_checked(points, faces).query(rays)


@dataclass(frozen=True)
class LocateIndex:
    """A region's triangles sorted by the directions they cover (docs/math.md, section 10):
    build once, then ask :meth:`query` for many rays. Immutable (its arrays are read-only).

    Attributes
    ----------
    points : (n, 3) float, the vertices in the local frame
    faces : (m, 3) int, the region's triangles
    levels : (L, 7) float, per grid level: cube face, cell width, origin u and v, columns,
        rows, first cell id
    cell_start : (C + 1,) int, entries of cell ``c`` are ``cell_start[c]:cell_start[c + 1]``
    entry_face : (E,) int, the triangle of each entry, sorted by cell
    entry_box : (E, 4) float32, its box ``u0, v0, u1, v1`` on that cube face (padded)
    everyone : (g,) int, triangles tested against every query
    """

    points: np.ndarray
    faces: np.ndarray
    levels: np.ndarray
    cell_start: np.ndarray
    entry_face: np.ndarray
    entry_box: np.ndarray
    everyone: np.ndarray

    @classmethod
    def build(cls, vertices_local, faces) -> LocateIndex:
        """The index of ``faces`` (``(m, 3)`` int) over ``vertices_local`` (``(n, 3)``
        float, the centre at the origin).

        Raises
        ------
        TransformInputError
            A vertex of a triangle at the centre, a bad shape or index.
        """
        return cls._of_checked(*_checked(vertices_local, faces))

    @classmethod
    def _of_checked(cls, points: np.ndarray, faces: np.ndarray) -> LocateIndex:
        vertex_face, vertex_u, vertex_v = cube_coordinates(points)
        pair_face, pair_cube, pair_box, everyone = triangle_boxes(
            points, faces, vertex_face, vertex_u, vertex_v
        )
        cells = grid_of(pair_cube, pair_box)
        cell_start, entry_face, entry_box = sorted_by_cell(cells, pair_face, pair_box)
        index = cls(
            points=points,
            faces=faces,
            levels=cells.levels,
            cell_start=cell_start,
            entry_face=entry_face,
            entry_box=entry_box,
            everyone=everyone,
        )
        for array in (index.levels, index.cell_start, index.entry_face, index.entry_box):
            array.flags.writeable = False
        return index

    def query(self, directions) -> Hits:
        """The triangle each ray from the centre in ``directions`` (``(k, 3)``, non-zero)
        meets first; :class:`Hits`.

        Raises
        ------
        TransformInputError
            A zero direction.
        """
        directions = as_points(directions, "directions")
        if len(directions) <= FEW_QUERIES:
            return self._query_few(_few_rays(directions))
        k = len(directions)
        hits = Hits(np.empty(k, dtype=np.int64), np.empty((k, 3)), np.empty((k, 3)))
        if k < SORTED_QUERIES:
            self._ray_hits(directions, hits)
        else:  # in cube-map order, then back to the queries' rows
            order, ordered_directions = ray_order(directions, _SQUARES)
            ordered = Hits(np.empty(k, dtype=np.int64), np.empty((k, 3)), np.empty((k, 3)))
            self._ray_hits(ordered_directions, ordered)
            put_rows(order, *_arrays(ordered), *_arrays(hits))
        return hits

    def _ray_hits(self, directions: np.ndarray, hits: Hits) -> None:
        """:func:`.locate_kernel.ray_hits` of ``directions`` into ``hits``; a zero direction
        refused."""
        face_levels, level_counts = self._level_table
        zero = ray_hits(
            directions,
            self.points,
            self.faces,
            face_levels,
            level_counts,
            self.cell_start,
            self.entry_face,
            self.entry_box,
            self.everyone,
            np.empty(self._held_size, dtype=np.int64),
            hits.faces,
            hits.barycentric,
            hits.points,
        )
        if zero:
            rows = np.flatnonzero(~directions.any(axis=1))
            raise TransformInputError("directions", "a direction is zero", rows)

    def _query_few(self, rays: np.ndarray) -> Hits:
        """:meth:`query` for a few rays, each looked up alone: the same cells, the same
        float32 box test and the same exact test (:func:`_nearest_hit`, in plain floats,
        operation for operation as :func:`_pair_hits`), so the same answers."""
        count = len(rays)
        hit_face = np.full(count, -1, dtype=np.int64)
        weights = np.full((count, 3), np.nan)
        depth = np.full(count, np.nan)
        # The compiled function's own Python, on plain floats: no dispatch for a few rays.
        cube_of = cube_coordinate.py_func
        for k, ray in enumerate(rays.tolist()):
            found = self._candidates(*cube_of(*ray))
            if len(self.everyone):
                found = np.concatenate([found, self.everyone])
            corners = self.points[self.faces[found]].tolist()
            hit = _nearest_hit(ray, found.tolist(), corners)
            if hit is not None:
                hit_face[k], depth[k], weights[k] = hit
        return _hits(rays, hit_face, weights, depth)

    def _candidates(self, cube: int, u: float, v: float) -> np.ndarray:
        """The triangles whose boxes on cube face ``cube`` hold ``(u, v)`` (float32, as the
        boxes), from the query's cell on each level of that face."""
        ranges = []
        for width, u0, v0, columns, rows, offset in self._face_levels[cube]:
            column, row = math.floor((u - u0) / width), math.floor((v - v0) / width)
            if 0 <= column < columns and 0 <= row < rows:
                cell = offset + row * columns + column
                ranges.append(slice(self.cell_start.item(cell), self.cell_start.item(cell + 1)))
        if not ranges:
            return np.empty(0, dtype=np.int64)
        box = np.concatenate([self.entry_box[r] for r in ranges])
        face = np.concatenate([self.entry_face[r] for r in ranges])
        qu, qv = np.float32(u), np.float32(v)
        held = (box[:, 0] <= qu) & (qu <= box[:, 2]) & (box[:, 1] <= qv) & (qv <= box[:, 3])
        return face[held].astype(np.int64, copy=False)

    @cached_property
    def _face_levels(self) -> tuple[tuple[tuple[float, float, float, int, int, int], ...], ...]:
        """The grid levels of each cube face as plain numbers: width, origin u and v,
        columns, rows and first cell id."""
        by_face: list[list] = [[] for _ in range(6)]
        for face, width, u0, v0, columns, rows, offset in self.levels.tolist():
            by_face[int(face)].append((width, u0, v0, int(columns), int(rows), int(offset)))
        return tuple(tuple(levels) for levels in by_face)

    @cached_property
    def _held_size(self) -> int:
        """Room for the entries of the fullest cell on each level, and the everyone list."""
        most = int(np.diff(self.cell_start).max(initial=0))
        return len(self.levels) * most + len(self.everyone)

    @cached_property
    def _level_table(self) -> tuple[np.ndarray, np.ndarray]:
        """The grid levels by cube face for :func:`.locate_kernel.ray_hits`: (6, L, 6)
        float, per face its levels' width, origin u and v, columns, rows and first cell id
        (the first ``counts[face]`` rows), and (6,) int counts."""
        counts = np.zeros(6, dtype=np.int64)
        table = np.zeros((6, max(1, max(map(len, self._face_levels))), 6))
        for face, levels in enumerate(self._face_levels):
            counts[face] = len(levels)
            if levels:
                table[face, : len(levels)] = levels
        return table, counts


def _rays(directions) -> np.ndarray:
    """(k, 3) unit rows of ``directions``; a zero one refused."""
    rays, zero = unit_rows(as_points(directions, "directions"))
    if zero.any():
        raise TransformInputError("directions", "a direction is zero", np.flatnonzero(zero))
    return rays


def _few_rays(directions: np.ndarray) -> np.ndarray:
    """:func:`_rays` of a few checked directions ((k, 3) float), row by row in plain floats
    as :func:`.arrays.unit_rows` computes them (the same bits)."""
    rays = []
    for row, (x, y, z) in enumerate(directions.tolist()):
        largest = max(abs(x), abs(y), abs(z))
        if largest == 0.0:
            raise TransformInputError("directions", "a direction is zero", [row])
        x, y, z = x / largest, y / largest, z / largest
        length = math.sqrt(x * x + y * y + z * z)
        rays.append((x / length, y / length, z / length))
    return np.array(rays, dtype=np.float64).reshape(-1, 3)


def _checked(vertices_local, faces) -> tuple[np.ndarray, np.ndarray]:
    """The points and faces as arrays; a vertex of a triangle at the centre refused (a
    vertex no triangle uses may be anywhere)."""
    points = as_points(vertices_local, "vertices")
    faces = as_faces(faces, len(points))
    at_centre = (points[:, 0] == 0.0) & (points[:, 1] == 0.0) & (points[:, 2] == 0.0)
    if at_centre.any():
        used = np.bincount(faces.ravel(), minlength=len(points)) > 0
        if (at_centre & used).any():
            text, rows = listed_rows(at_centre & used, "vertex")
            raise TransformInputError("vertices", f"{text}: at the centre, no direction", rows)
    return points, faces


def _direct_pairs(points, faces, rays) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """(query, triangle) pairs that may hit, without an index, a block of triangles at a
    time: a triangle's cone can hold a ray only if, for each of two planes through the ray
    (across each other) and the plane across it, some corner is on the ray's side or on the
    plane and, for the first two, some corner is on the other side or on the plane.

    Yields
    ------
    query, face : (p,) int each
    """
    k = len(rays)
    if k == 0:
        return
    across = np.eye(3)[np.abs(rays).argmin(axis=1)]
    side_a, _ = unit_rows(np.cross(rays, across))
    side_b = np.cross(rays, side_a)
    basis = np.concatenate([side_a.T, side_b.T, rays.T], axis=1)  # (3, 3k): x, y, then w
    codes = np.zeros((len(points), k), dtype=np.uint8)
    for part in blocks(len(points)):
        projected = points[part] @ basis  # (B, 3k)
        x, y, w = projected[:, :k], projected[:, k : 2 * k], projected[:, 2 * k :]
        slack = SIDE * (np.abs(x) + np.abs(y) + np.abs(w))
        code = codes[part]
        for bit, side in enumerate((x >= -slack, x <= slack, y >= -slack, y <= slack)):
            code |= side.view(np.uint8) << bit
        code |= (w >= -slack).view(np.uint8) << 4
    for part in blocks(len(faces)):
        corner = take_rows(codes, faces[part].ravel()).reshape(-1, 3, k)
        face, query = np.nonzero((corner[:, 0] | corner[:, 1] | corner[:, 2]) == 31)
        yield query, face + part.start


def _nearest(points, faces, rays, pairs):
    """Per query, the nearest triangle among its pairs that holds its ray (the smaller
    position among equally near ones), the hit's barycentric weights and depth.

    Parameters
    ----------
    pairs : iterable of (query, face) int arrays

    Returns
    -------
    hit_face : (k,) int, -1 for none
    weights : (k, 3) float, NaN for none
    depth : (k,) float, the hit is at ``depth * ray``; NaN for none
    """
    k = len(rays)
    hit_face = np.full(k, -1, dtype=np.int64)
    weights = np.full((k, 3), np.nan)
    depth = np.full(k, np.inf)
    for pair_query, pair_face in pairs:
        for part in blocks(len(pair_query), _PAIRS):
            hits = _pair_hits(points, faces, rays, pair_query[part], pair_face[part])
            _keep_nearest(*hits, hit_face, weights, depth)
    depth[hit_face < 0] = np.nan
    return hit_face, weights, depth


def _nearest_hit(ray, faces: list[int], corners: list):
    """The nearest of the triangles ``faces`` (their ``corners``, three points each) that
    holds ``ray`` (three floats), the smaller position among equally near ones: ``(face,
    depth, weights)``, or None. The test of :func:`_pair_hits`, in plain floats in the same
    order of operations (IEEE arithmetic, so the same bits), for a ray with few candidates."""
    qx, qy, qz = ray
    best = None
    for face, ((x0, y0, z0), (x1, y1, z1), (x2, y2, z2)) in zip(faces, corners, strict=True):
        ax, ay, az = y1 * z2 - z1 * y2, z1 * x2 - x1 * z2, x1 * y2 - y1 * x2  # c1 x c2
        e0 = qx * ax + qy * ay + qz * az
        e1 = qx * (y2 * z0 - z2 * y0) + qy * (z2 * x0 - x2 * z0) + qz * (x2 * y0 - y2 * x0)
        e2 = qx * (y0 * z1 - z0 * y1) + qy * (z0 * x1 - x0 * z1) + qz * (x0 * y1 - y0 * x1)
        total = e0 + e1 + e2
        if total == 0.0:
            continue
        slack = INSIDE * (abs(e0) + abs(e1) + abs(e2))
        side = 1.0 if total > 0.0 else -1.0
        if side * e0 < slack or side * e1 < slack or side * e2 < slack:
            continue
        depth = (x0 * ax + y0 * ay + z0 * az) / total
        if depth > 0.0 and (best is None or (depth, face) < (best[1], best[0])):
            best = (face, depth, (e0 / total, e1 / total, e2 / total))
    return best


def _keep_nearest(query, face, depth, weight, hit_face, weights, nearest_depth) -> None:
    """Merge hits into each query's nearest so far (in place; the smaller position among
    equally near ones)."""
    nearest = nearest_depth.copy()
    np.minimum.at(nearest, query, depth)
    best = depth == nearest[query]
    kept = (nearest_depth == nearest) & (hit_face >= 0)
    lowest = np.where(kept, hit_face, np.iinfo(np.int64).max)
    np.minimum.at(lowest, query[best], face[best])
    best &= face == lowest[query]
    rows = np.flatnonzero(best)
    hit_face[query[rows]] = face[rows]
    weights[query[rows]] = take_rows(weight, rows)
    nearest_depth[query[rows]] = depth[rows]


def _pair_hits(points, faces, rays, query, face):
    """The (query, triangle) pairs whose triangle holds the query's ray: their query,
    triangle, depth along the ray, and barycentric weights (p, 3)."""
    q = take_rows(rays, query)
    corners = take_rows(faces, face)
    c0, c1, c2 = (take_rows(points, corners[:, i]) for i in range(3))
    across = cross_rows(c1, c2)
    e0, e1, e2 = _dot(q, across), _dot(q, cross_rows(c2, c0)), _dot(q, cross_rows(c0, c1))
    total = e0 + e1 + e2  # q . n with n = (c1 - c0) x (c2 - c0)
    slack = INSIDE * (np.abs(e0) + np.abs(e1) + np.abs(e2))
    side = np.sign(total)
    inside = (side * e0 >= slack) & (side * e1 >= slack) & (side * e2 >= slack)
    with np.errstate(divide="ignore", invalid="ignore"):
        depth = _dot(c0, across) / total  # det[c0, c1, c2] / (q . n): the hit is depth * q
    inside &= (total != 0.0) & (depth > 0.0)
    rows = np.flatnonzero(inside)
    weights = np.stack([e0[rows], e1[rows], e2[rows]], axis=1) / total[rows, None]
    return query[rows], face[rows], depth[rows], weights


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise ``a . b`` of (p, 3) arrays."""
    return a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1] + a[:, 2] * b[:, 2]


def _arrays(hits: Hits) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The faces, barycentric weights and points of ``hits`` (the arrays themselves)."""
    return hits.faces, hits.barycentric, hits.points


def _hits(rays, hit_face, weights, depth) -> Hits:
    """:class:`Hits` of the rays' nearest hits; the points on the rays themselves."""
    return Hits(hit_face, weights, depth[:, None] * rays)
