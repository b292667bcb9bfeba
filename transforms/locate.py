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
there before the exact test. Triangles that reach a face without being in front of it (a few very
large ones next to the centre) are tested against every query.

For a handful of queries the index would cost more than it saves: :func:`locate` then tests
every triangle against the four planes through each ray (no index; same exact test).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from .arrays import as_faces, as_points, blocks, cross_rows, unit_rows
from .errors import TransformInputError, listed_rows

#: A direction counts as inside when each edge's determinant is above this (relative) amount.
_INSIDE = -1e-12
#: Slack around every box, in gnomonic units (about radians near a face's middle): more than
#: the exact test's tolerance and float32's rounding of the stored boxes.
_PAD = 1e-6
#: Slack of the plane tests (a corner counts as on a plane's side within this part of its
#: coordinates' sum).
_SIDE = 1e-9
#: A vertex this far inside its cube face (``max(|u|, |v|)`` below it) keeps its triangle on
#: that face alone when all three corners are.
_INNER = 1.0 - 1e-4
#: Percentile of the boxes' sizes that fit level 0's cells.
_LEVEL0_PERCENTILE = 90.0
#: A box spans at most this many cells each way on its level.
_SPAN = 2
#: Level-0 cells per triangle of a cube face at most (bounds the index's size).
_CELLS_PER_TRIANGLE = 2.0
#: A box is stored on the first level whose cells exceed it by this part.
_FIT = 1.0 - 1e-6
#: Up to this many queries, testing every triangle costs no more than building the index: a
#: build costs about as much as 15 to 18 direct passes on 100k and on 1.6M faces
#: (docs/benchmarks.md, locate).
DIRECT_QUERIES = 16
#: Up to this many queries, :meth:`LocateIndex.query` looks each one up on its own in scalar
#: arithmetic (a click on the map): for so few, a pass of array operations per step costs
#: more than the step.
FEW_QUERIES = 4
#: (query, triangle) pairs handled at a time.
_PAIRS = 1 << 18
#: Queries looked up at a time (their candidates' arrays stay in cache).
_QUERIES = 8192


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
        vertex_face, vertex_u, vertex_v = _cube_coordinates(points)
        pair_face, pair_cube, pair_box, everyone = _boxes(
            points, faces, vertex_face, vertex_u, vertex_v
        )
        cells = _grid(pair_cube, pair_box)
        cell_start, entry_face, entry_box = _sorted_by_cell(cells, pair_face, pair_box)
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
        rays = _rays(directions)
        k = len(rays)
        if k <= FEW_QUERIES:
            return self._query_few(rays)
        cube, u, v = _cube_coordinates(rays)
        # Neighbouring queries one after another: they read the same cells and vertices. A
        # 16-bit key (the cube face, then 64 x 64 squares of it) sorts in one radix pass.
        key = (cube.astype(np.uint16) << 12) | (_square(v) << 6) | _square(u)
        order = np.argsort(key, kind="stable")
        ordered, cube, u, v = _rows(rays, order), cube[order], u[order], v[order]
        # Chunks of queries such that their pairs with the everyone list stay bounded.
        per_chunk = max(1, _QUERIES // (1 + len(self.everyone) // 16))
        hits = Hits(np.empty(k, dtype=np.int64), np.empty((k, 3)), np.empty((k, 3)))
        for part in blocks(k, per_chunk):
            found = self._query_chunk(ordered[part], cube[part], u[part], v[part])
            # Each chunk's answers straight to their queries' rows (np.put: fast for rows).
            mine = order[part]
            hits.faces[mine] = found[0]
            row_items = (3 * mine[:, None] + np.arange(3)).ravel()
            np.put(hits.barycentric, row_items, found[1])
            np.put(hits.points, row_items, found[2][:, None] * ordered[part])
        return hits

    def _query_few(self, rays: np.ndarray) -> Hits:
        """:meth:`query` for a few rays, each looked up alone: the same cells, the same
        float32 box test and the same exact test, so the same answers."""
        queries, faces = [np.empty(0, dtype=np.int64)], [np.empty(0, dtype=np.int64)]
        for k, (x, y, z) in enumerate(rays.tolist()):
            cube, u, v = _cube_coordinate(x, y, z)
            found = self._candidates(cube, u, v)
            queries.append(np.full(len(found), k, dtype=np.int64))
            faces.append(found)
        if len(self.everyone):
            count = len(rays)
            queries.append(np.repeat(np.arange(count), len(self.everyone)))
            faces.append(np.tile(self.everyone, count))
        query, face = np.concatenate(queries), np.concatenate(faces)
        return _hits(rays, *_nearest_few(self.points, self.faces, rays, query, face))

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

    def _query_chunk(self, rays, cube, u, v) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        k = len(rays)
        query, cell = self._lookups(cube, u, v)
        start = self.cell_start[cell]
        counts = self.cell_start[cell + 1] - start
        first = np.cumsum(counts) - counts
        entry = np.arange(counts.sum()) + np.repeat(start - first, counts)
        box = _rows(self.entry_box, entry)
        # float32 like the boxes, which are padded by more than its rounding; u first, then v
        # on what is left.
        pair_query = np.repeat(query, counts)
        qu = np.repeat(u.astype(np.float32)[query], counts)
        rows = np.flatnonzero((box[:, 0] <= qu) & (qu <= box[:, 2]))
        pair_query = pair_query[rows]
        qv = v.astype(np.float32)[pair_query]
        near = (box[:, 1][rows] <= qv) & (qv <= box[:, 3][rows])
        pairs = [(pair_query[near], self.entry_face[entry[rows[near]]])]
        if len(self.everyone):
            pairs.append((np.repeat(np.arange(k), len(self.everyone)), np.tile(self.everyone, k)))
        return _nearest(self.points, self.faces, rays, pairs)

    def _lookups(self, cube, u, v) -> tuple[np.ndarray, np.ndarray]:
        """(query, cell): the cell each query is in on each level of its cube face (none on
        a level whose boxes it is outside); ``cube`` sorted."""
        queries, cells = [], []
        bounds = np.searchsorted(cube, np.arange(7))
        for face, width, u0, v0, columns, rows, offset in self.levels:
            mine = slice(bounds[int(face)], bounds[int(face) + 1])
            column = np.floor((u[mine] - u0) / width)
            row = np.floor((v[mine] - v0) / width)
            inside = np.flatnonzero((column >= 0) & (column < columns) & (row >= 0) & (row < rows))
            queries.append(inside + mine.start)
            cells.append((offset + row[inside] * columns + column[inside]).astype(np.int64))
        if not queries:
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        return np.concatenate(queries), np.concatenate(cells)


def _rows(array: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """``array[rows]``: np.take, several times faster than indexing for rows of a 2-D
    array."""
    return np.take(array, rows, axis=0)


def _square(coordinate: np.ndarray) -> np.ndarray:
    """A gnomonic coordinate in [-1, 1] as one of 64 steps (6 bits)."""
    return np.clip((coordinate + 1.0) * 32.0, 0, 63).astype(np.uint16)


def _rays(directions) -> np.ndarray:
    """(k, 3) unit rows of ``directions``; a zero one refused."""
    rays, zero = unit_rows(as_points(directions, "directions"))
    if zero.any():
        raise TransformInputError("directions", "a direction is zero", np.flatnonzero(zero))
    return rays


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


def _cube_coordinates(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each point's cube face and gnomonic coordinates there.

    Parameters
    ----------
    points : (n, 3) float

    Returns
    -------
    face : (n,) int8, ``2 * a + (p_a < 0)`` for the axis ``a`` of the largest ``|p_a|`` (the
        first of equals)
    u, v : (n,) float, ``p_b / |p_a|`` and ``p_c / |p_a|`` with ``b, c = a + 1, a + 2`` (mod
        3); 0 for a point at the origin
    """
    x, y, z = points[:, 0], points[:, 1], points[:, 2]
    ax, ay, az = np.abs(x), np.abs(y), np.abs(z)
    on_x = (ax >= ay) & (ax >= az)
    on_y = ~on_x & (ay >= az)
    on_z = ~on_x & ~on_y
    major = np.where(on_x, x, np.where(on_y, y, z))
    b = np.where(on_x, y, np.where(on_y, z, x))
    c = np.where(on_x, z, np.where(on_y, x, y))
    scale = np.abs(major)
    scale[scale == 0.0] = 1.0
    face = (on_y * 2 + on_z * 4 + (major < 0)).astype(np.int8)
    return face, b / scale, c / scale


def _cube_coordinate(x: float, y: float, z: float) -> tuple[int, float, float]:
    """:func:`_cube_coordinates` of one point, in plain numbers."""
    ax, ay, az = abs(x), abs(y), abs(z)
    if ax >= ay and ax >= az:
        major, b, c, axis = x, y, z, 0
    elif ay >= az:
        major, b, c, axis = y, z, x, 1
    else:
        major, b, c, axis = z, x, y, 2
    scale = abs(major) or 1.0
    return 2 * axis + (major < 0), b / scale, c / scale


def _boxes(points, faces, vertex_face, vertex_u, vertex_v):
    """Each triangle's padded boxes on the cube faces its cone reaches.

    Returns
    -------
    pair_face : (E,) int, the triangle of each box
    pair_cube : (E,) int8, the cube face of each box
    pair_box : (E, 4) float, ``u0, v0, u1, v1``
    everyone : (g,) int, triangles that reach a face without being in front of it
    """
    # A vertex well inside its cube face, by its face's number; 6: near an edge of the cube.
    inner = np.maximum(np.abs(vertex_u), np.abs(vertex_v)) <= _INNER
    home = np.where(inner, vertex_face, np.int8(6))
    a, b, c = faces[:, 0], faces[:, 1], faces[:, 2]
    # All three corners well inside one cube face: the cone is inside it (both are convex).
    simple = home[a] == home[b]
    simple &= home[b] == home[c]
    simple &= home[a] < 6
    ids = np.flatnonzero(simple)
    corners = [np.take(faces[:, i], ids) for i in range(3)]
    boxes = [_corner_box(*(vertex_u[c] for c in corners), *(vertex_v[c] for c in corners))]
    pair_faces, cubes = [ids], [home[a[ids]]]
    general = np.flatnonzero(~simple)
    corners = _rows(points, _rows(faces, general).ravel()).reshape(-1, 3, 3)
    reached = []
    for cube in range(6):
        ids, box, not_in_front = _general_boxes(corners, general, cube)
        pair_faces.append(ids)
        cubes.append(np.full(len(ids), cube, dtype=np.int8))
        boxes.append(box)
        reached.append(not_in_front)
    box = np.concatenate(boxes)
    box[:, :2] -= _PAD
    box[:, 2:] += _PAD
    everyone = np.unique(np.concatenate(reached))
    return np.concatenate(pair_faces), np.concatenate(cubes), box, everyone


def _corner_box(u0, u1, u2, v0, v1, v2) -> np.ndarray:
    """(g, 4) ``u_min, v_min, u_max, v_max`` of three corners' coordinates."""
    box = np.empty((len(u0), 4))
    np.minimum(np.minimum(u0, u1, out=box[:, 0]), u2, out=box[:, 0])
    np.minimum(np.minimum(v0, v1, out=box[:, 1]), v2, out=box[:, 1])
    np.maximum(np.maximum(u0, u1, out=box[:, 2]), u2, out=box[:, 2])
    np.maximum(np.maximum(v0, v1, out=box[:, 3]), v2, out=box[:, 3])
    return box


def _general_boxes(corners, general, cube):
    """For the triangles ``general`` (ids; ``corners`` (g, 3, 3) their corners): those
    whose cone reaches cube face ``cube`` (ids, (g, 4) boxes clipped to the face), and those
    reaching it with a corner not in front of it."""
    axis, sign = divmod(cube, 2)
    sign = -1.0 if sign else 1.0
    major = sign * corners[:, :, axis]
    b, c = corners[:, :, (axis + 1) % 3], corners[:, :, (axis + 2) % 3]
    slack = _SIDE * np.abs(corners).sum(axis=2)
    # The face's cone is major >= |b| and major >= |c|: reached unless all corners are out
    # of one of its four half-spaces (the triangle's cone is made of their combinations).
    reaches = np.ones(len(general), dtype=bool)
    for side in (major - b, major + b, major - c, major + c):
        reaches &= (side >= -slack).any(axis=1)
    in_front = (major > 0).all(axis=1)
    keep = reaches & in_front
    u, v = b[keep] / major[keep], c[keep] / major[keep]
    box = _corner_box(u[:, 0], u[:, 1], u[:, 2], v[:, 0], v[:, 1], v[:, 2])
    np.clip(box, -1.0, 1.0, out=box)
    return general[keep], box, general[reaches & ~in_front]


@dataclass(frozen=True)
class _Cells:
    """Where each box lies in the grid: the row of ``levels`` and the id of its lowest cell,
    how many more columns and rows it reaches (each below ``_SPAN``), and its level's number
    of columns."""

    levels: np.ndarray
    first: np.ndarray
    more_columns: np.ndarray
    more_rows: np.ndarray
    columns: np.ndarray
    n_cells: int


def _grid(pair_cube: np.ndarray, pair_box: np.ndarray) -> _Cells:
    """The grid's levels and the cells of each box.

    On a cube face, level ``L`` has square cells of width ``h0 * 2**L`` from the lower
    corner of the face's boxes; a box goes to the first level where it overlaps at most
    ``_SPAN`` x ``_SPAN`` cells. ``h0`` is such that most boxes (``_LEVEL0_PERCENTILE``) are
    on level 0, but no smaller than leaves ``_CELLS_PER_TRIANGLE`` level-0 cells per box.
    """
    first = np.zeros(len(pair_cube), dtype=np.int64)
    more_columns = np.zeros(len(pair_cube), dtype=np.int8)
    more_rows = np.zeros(len(pair_cube), dtype=np.int8)
    columns_of = np.zeros(len(pair_cube), dtype=np.int64)
    levels, n_cells = [], 0
    for cube in range(6):
        mine = np.flatnonzero(pair_cube == cube)
        if mine.size == 0:
            continue
        u0, v0, u1, v1 = (np.take(pair_box[:, i], mine) for i in range(4))
        low, high = (float(u0.min()), float(v0.min())), (float(u1.max()), float(v1.max()))
        width, height = high[0] - low[0], high[1] - low[1]
        size = np.maximum(u1 - u0, v1 - v0) / ((_SPAN - 1) * _FIT)  # the cell width it needs
        budget = _CELLS_PER_TRIANGLE * len(mine)
        h0 = max(
            float(np.percentile(size, _LEVEL0_PERCENTILE)),
            math.sqrt(width * height / budget),
            max(width, height) / budget,
            1e-12,
        )
        level = np.maximum(np.ceil(np.log2(np.maximum(size, 1e-300) / h0)), 0)
        level += size > h0 * np.exp2(level)  # where log2 rounded down
        for step in np.flatnonzero(np.bincount(level.astype(np.int64))):
            cell_width = h0 * 2.0**step
            columns = math.floor(width / cell_width) + 1
            rows = math.floor(height / cell_width) + 1
            on = np.flatnonzero(level == step)
            column = [_cell(c[on], low[0], cell_width, columns) for c in (u0, u1)]
            row = [_cell(c[on], low[1], cell_width, rows) for c in (v0, v1)]
            ids = mine[on]
            first[ids] = n_cells + row[0] * columns + column[0]
            more_columns[ids] = column[1] - column[0]
            more_rows[ids] = row[1] - row[0]
            columns_of[ids] = columns
            levels.append((cube, cell_width, low[0], low[1], columns, rows, n_cells))
            n_cells += columns * rows
    levels = np.array(levels, dtype=np.float64).reshape(-1, 7)
    return _Cells(levels, first, more_columns, more_rows, columns_of, n_cells)


def _cell(coordinate: np.ndarray, origin: float, width: float, count: int) -> np.ndarray:
    """The column (or row) of cells ``width`` wide from ``origin`` holding ``coordinate``."""
    return np.floor((coordinate - origin) / width).clip(0, count - 1).astype(np.int64)


def _sorted_by_cell(cells: _Cells, pair_face: np.ndarray, pair_box: np.ndarray):
    """The boxes' entries (one per cell a box overlaps) sorted by cell, by counting: one
    sort of the boxes by their lowest cell orders each shifted copy (the entries one column
    right, one row up, ...) too.

    Returns
    -------
    cell_start : (C + 1,) int
    entry_face : (E,) int
    entry_box : (E, 4) float32
    """
    order = np.argsort(cells.first)
    reach_columns, reach_rows = cells.more_columns[order], cells.more_rows[order]
    shifted = []
    for right in range(_SPAN):
        for up in range(_SPAN):
            members = order[(reach_columns >= right) & (reach_rows >= up)]
            keys = cells.first[members] + right + up * cells.columns[members]
            shifted.append((members, keys))
    n_entries = sum(len(members) for members, _ in shifted)  # at most _SPAN**2 per box
    counts = np.zeros(cells.n_cells, dtype=np.int64)
    placed = []
    for _, keys in shifted:
        # Entries of one copy go after those of the copies before, in the order sorted.
        run_start = np.flatnonzero(np.diff(keys, prepend=-1))
        rank = np.arange(len(keys)) - np.repeat(run_start, np.diff(run_start, append=len(keys)))
        placed.append(counts[keys] + rank)
        counts += np.bincount(keys, minlength=cells.n_cells)
    cell_start = np.zeros(cells.n_cells + 1, dtype=np.int64)
    np.cumsum(counts, out=cell_start[1:])
    entry_face = np.empty(n_entries, dtype=pair_face.dtype)
    entry_box = np.empty((n_entries, 4), dtype=np.float32)
    boxes = pair_box.astype(np.float32).view(np.complex128)[:, 0]  # a row as one item
    for (members, keys), within in zip(shifted, placed, strict=True):
        where = cell_start[keys] + within
        np.put(entry_face, where, np.take(pair_face, members))
        np.put(entry_box.view(np.complex128)[:, 0], where, np.take(boxes, members))
    return cell_start, entry_face, entry_box


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
        slack = _SIDE * (np.abs(x) + np.abs(y) + np.abs(w))
        code = codes[part]
        for bit, side in enumerate((x >= -slack, x <= slack, y >= -slack, y <= slack)):
            code |= side.view(np.uint8) << bit
        code |= (w >= -slack).view(np.uint8) << 4
    for part in blocks(len(faces)):
        corner = _rows(codes, faces[part].ravel()).reshape(-1, 3, k)
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


def _nearest_few(points, faces, rays, query, face):
    """:func:`_nearest` for a few queries and their candidate pairs at once: of each query's
    hits the nearest, the smaller position among equally near ones."""
    k = len(rays)
    hit_face = np.full(k, -1, dtype=np.int64)
    weights = np.full((k, 3), np.nan)
    depth = np.full(k, np.nan)
    query, face, found, weight = _pair_hits(points, faces, rays, query, face)
    if len(query):
        order = np.lexsort((face, found, query))  # by query, then depth, then position
        ordered = query[order]
        first = order[np.flatnonzero(np.r_[True, ordered[1:] != ordered[:-1]])]
        hit_face[query[first]] = face[first]
        weights[query[first]] = weight[first]
        depth[query[first]] = found[first]
    return hit_face, weights, depth


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
    weights[query[rows]] = _rows(weight, rows)
    nearest_depth[query[rows]] = depth[rows]


def _pair_hits(points, faces, rays, query, face):
    """The (query, triangle) pairs whose triangle holds the query's ray: their query,
    triangle, depth along the ray, and barycentric weights (p, 3)."""
    q = _rows(rays, query)
    corners = _rows(faces, face)
    c0, c1, c2 = (_rows(points, corners[:, i]) for i in range(3))
    across = cross_rows(c1, c2)
    e0, e1, e2 = _dot(q, across), _dot(q, cross_rows(c2, c0)), _dot(q, cross_rows(c0, c1))
    total = e0 + e1 + e2  # q . n with n = (c1 - c0) x (c2 - c0)
    slack = _INSIDE * (np.abs(e0) + np.abs(e1) + np.abs(e2))
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


def _hits(rays, hit_face, weights, depth) -> Hits:
    """:class:`Hits` of the rays' nearest hits; the points on the rays themselves."""
    return Hits(hit_face, weights, depth[:, None] * rays)
