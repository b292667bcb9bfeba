"""The cube map of directions the locate index is built on (docs/math.md, section 10): each
direction's cube face and gnomonic coordinates ``(u, v)`` there, each triangle's padded boxes
on the faces its cone reaches, and the grid levels those boxes are filed in.

On a cube face, the gnomonic projection ``(u, v) = (p_b, p_c) / |p_a|`` turns the cone of a
triangle whose corners are all in front of that face into the straight triangle of its
projected corners, so the box of those corners holds it exactly. A box goes on the level
whose cells are at least as wide as it, so it meets at most 2 x 2 of them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

#: Slack of the plane tests (a corner counts as on a plane's side within this part of its
#: coordinates' sum).
SIDE = 1e-9
#: Slack around every box, in gnomonic units (about radians near a face's middle): more than
#: the exact test's tolerance and float32's rounding of the stored boxes.
_PAD = 1e-6
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


def take_rows(array: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """``array[rows]``: np.take, several times faster than indexing for rows of a 2-D
    array."""
    return np.take(array, rows, axis=0)


def cube_coordinates(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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


@njit(cache=True, nogil=True, inline="always")
def cube_coordinate(x: float, y: float, z: float) -> tuple[int, float, float]:
    """:func:`cube_coordinates` of one point, in plain numbers (compiled: the locate walk's
    kernels inline it, and Python calls it too)."""
    ax, ay, az = abs(x), abs(y), abs(z)
    if ax >= ay and ax >= az:
        major, b, c, axis = x, y, z, 0
    elif ay >= az:
        major, b, c, axis = y, z, x, 1
    else:
        major, b, c, axis = z, x, y, 2
    scale = abs(major)
    if scale == 0.0:
        scale = 1.0
    return 2 * axis + (major < 0), b / scale, c / scale


def triangle_boxes(points, faces, vertex_face, vertex_u, vertex_v):
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
    corners = take_rows(points, take_rows(faces, general).ravel()).reshape(-1, 3, 3)
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
    slack = SIDE * np.abs(corners).sum(axis=2)
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
class Cells:
    """Where each box lies in the grid: the row of ``levels`` and the id of its lowest cell,
    how many more columns and rows it reaches (each below ``_SPAN``), and its level's number
    of columns."""

    levels: np.ndarray
    first: np.ndarray
    more_columns: np.ndarray
    more_rows: np.ndarray
    columns: np.ndarray
    n_cells: int


def grid_of(pair_cube: np.ndarray, pair_box: np.ndarray) -> Cells:
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
    return Cells(levels, first, more_columns, more_rows, columns_of, n_cells)


def _cell(coordinate: np.ndarray, origin: float, width: float, count: int) -> np.ndarray:
    """The column (or row) of cells ``width`` wide from ``origin`` holding ``coordinate``."""
    return np.floor((coordinate - origin) / width).clip(0, count - 1).astype(np.int64)


def sorted_by_cell(cells: Cells, pair_face: np.ndarray, pair_box: np.ndarray):
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
