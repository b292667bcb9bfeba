"""A mesh's half-edges grouped by their edge in linear time, and what is read from the groups:
the pieces faces sharing an edge make, and the edges' classes (docs/math.md, sections 6 and 8).

A half-edge of face ``f`` runs from corner ``c`` to corner ``c + 1`` (mod 3); its edge is
the pair ``(low, high)`` of its ends' vertex ids. Sorting ``3 m`` edge keys with numpy is the
slow part of both the pieces and the edge classes on a large scan, so here the half-edges are
put in order by a counting sort on ``low`` (vertex ids are small integers) and then, within
each vertex's few half-edges, by ``high``: one stable pass, linear in the half-edges, in
compiled loops (numba; ``docs/architecture.md`` says why numba). The order is the one
``np.argsort(low * n + high, kind="stable")`` gives.
"""

from __future__ import annotations

import numpy as np
from numba import njit

#: A vertex's half-edges are put in order by insertion below this many, by a merge sort above
#: (a fan of thousands of faces round one vertex stays ``k log k``).
_INSERTION_BELOW = 33


@njit(cache=True, nogil=True)
def _ends(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(3 m,) int32 each: the lower and the higher end of each half-edge, ``3 f + c``."""
    m = faces.shape[0]
    low = np.empty(3 * m, dtype=np.int32)
    high = np.empty(3 * m, dtype=np.int32)
    for f in range(m):
        for c in range(3):
            a = faces[f, c]
            b = faces[f, (c + 1) % 3]
            low[3 * f + c] = min(a, b)
            high[3 * f + c] = max(a, b)
    return low, high


@njit(cache=True, nogil=True)
def _edge_order(
    low: np.ndarray, high: np.ndarray, sides: np.ndarray, n: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The half-edges (their rows in ``low`` and ``high``, values below ``n``) in the order
    of their edge ``(low, high)``, ties in row order: ``(k,)`` int64 rows, and their ``low``,
    ``high`` and ``sides`` (when it has rows) in that order, moved with them so that what is
    read from them after is read in sequence. 32-bit throughout: the scatter is bound by
    memory traffic, and half the bytes take about half the time."""
    k = low.shape[0]
    start = np.zeros(n + 1, dtype=np.int32)
    for i in range(k):
        start[low[i] + 1] += 1
    for v in range(n):
        start[v + 1] += start[v]
    fill = start[:-1].copy()
    order = np.empty(k, dtype=np.int32)
    lows = np.empty(k, dtype=np.int32)
    keys = np.empty(k, dtype=np.int32)
    moved = np.empty(sides.shape[0], dtype=sides.dtype)
    carry = sides.shape[0] > 0
    for i in range(k):
        at = fill[low[i]]
        order[at] = i
        keys[at] = high[i]
        if carry:
            moved[at] = sides[i]
        fill[low[i]] = at + 1
    for v in range(n):
        lows[start[v] : start[v + 1]] = v
        _sort_bucket(start[v], start[v + 1], order, keys, moved, carry)
    return order, lows, keys, moved


@njit(cache=True, nogil=True)
def _sort_bucket(
    first: int, last: int, order: np.ndarray, keys: np.ndarray, moved: np.ndarray, carry: bool
) -> None:
    """Put rows ``first:last`` of ``order`` (and ``moved`` with them when ``carry``) in the
    order of ``keys``, stably: one vertex's half-edges by their higher end."""
    if last - first >= _INSERTION_BELOW:
        by = np.argsort(keys[first:last], kind="mergesort") + first
        order[first:last] = order[by]
        keys[first:last] = keys[by]
        if carry:
            moved[first:last] = moved[by]
        return
    for j in range(first + 1, last):
        row, key = order[j], keys[j]
        side = moved[j] if carry else 0
        t = j
        while t > first and keys[t - 1] > key:
            order[t], keys[t] = order[t - 1], keys[t - 1]
            if carry:
                moved[t] = moved[t - 1]
            t -= 1
        order[t], keys[t] = row, key
        if carry:
            moved[t] = side


@njit(cache=True, nogil=True)
def _root(parent: np.ndarray, f: int) -> int:
    while parent[f] != f:
        parent[f] = parent[parent[f]]  # path halving
        f = parent[f]
    return f


@njit(cache=True, nogil=True)
def _components(faces: np.ndarray, n: int) -> np.ndarray:
    """(m,) int64: each face's piece, numbered in the order of their first faces."""
    m = faces.shape[0]
    low, high = _ends(faces)
    order, lows, keys, _ = _edge_order(low, high, np.empty(0, dtype=np.int8), n)
    parent = np.arange(m)
    for j in range(1, 3 * m):
        if keys[j] == keys[j - 1] and lows[j] == lows[j - 1]:
            a = _root(parent, order[j] // 3)
            b = _root(parent, order[j - 1] // 3)
            if a < b:
                parent[b] = a
            elif b < a:
                parent[a] = b
    labels = np.empty(m, dtype=np.int64)
    numbered = np.full(m, -1, dtype=np.int64)
    count = 0
    for f in range(m):
        r = _root(parent, f)
        if numbered[r] < 0:
            numbered[r] = count
            count += 1
        labels[f] = numbered[r]
    return labels


def edge_pieces(faces: np.ndarray) -> np.ndarray:
    """(m,) int64: the piece of each of ``faces`` ((m, 3) int, m >= 1, ids >= 0), faces that
    share an edge being in one piece; pieces are numbered from 0 in the order of their first
    face (as :func:`scipy.sparse.csgraph.connected_components` numbers them)."""
    faces = _checked(faces)
    return _components(faces, int(faces.max()) + 1)


@njit(cache=True, nogil=True)
def _sides(faces: np.ndarray, orientation: np.ndarray) -> np.ndarray:
    """(3 m,) int8: for each half-edge, ``(side + 1)^2`` (0, 1 or 4) with ``side`` that of its
    face's third vertex: the face's orientation, negated when the half-edge runs from the
    higher end to the lower."""
    m = faces.shape[0]
    out = np.empty(3 * m, dtype=np.int8)
    for f in range(m):
        for c in range(3):
            side = orientation[f] if faces[f, c] < faces[f, (c + 1) % 3] else -orientation[f]
            out[3 * f + c] = (side + 1) * (side + 1)
    return out


@njit(cache=True, nogil=True)
def _walk_edges(
    lows: np.ndarray,
    highs: np.ndarray,
    sides: np.ndarray,
    boundary: np.ndarray,
    outline: np.ndarray,
) -> tuple[int, int]:
    """Walk the half-edges in edge order (their ends and ``sides``, :func:`_sides`): write the
    boundary and the outline edges' ends into ``boundary`` and ``outline`` ((k, 2), when they
    have rows) and return how many of each there are. An edge from a vertex to itself is no
    edge."""
    fill = boundary.shape[0] > 0 or outline.shape[0] > 0
    n_boundary = n_outline = 0
    uses = summed = 0
    a = b = -1
    k = lows.shape[0]
    for j in range(k + 1):
        here, there = (lows[j], highs[j]) if j < k else (-1, -1)  # -1: close the last edge
        if j < k and here == there:
            continue
        if here != a or there != b:
            if uses > 0 and not (uses == 2 and summed == 4):  # the edge ended is not smooth
                if fill:
                    outline[n_outline, 0], outline[n_outline, 1] = a, b
                n_outline += 1
                if uses == 1:
                    if fill:
                        boundary[n_boundary, 0], boundary[n_boundary, 1] = a, b
                    n_boundary += 1
            a, b, uses, summed = here, there, 0, 0
        if j < k:
            uses += 1
            summed += sides[j]
    return n_boundary, n_outline


@njit(cache=True, nogil=True)
def _classes(faces: np.ndarray, orientation: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    low, high = _ends(faces)
    _, lows, highs, sides = _edge_order(low, high, _sides(faces, orientation), n)
    none = np.empty((0, 2), dtype=np.int64)
    n_boundary, n_outline = _walk_edges(lows, highs, sides, none, none)
    boundary = np.empty((n_boundary, 2), dtype=np.int64)
    outline = np.empty((n_outline, 2), dtype=np.int64)
    if n_outline:
        _walk_edges(lows, highs, sides, boundary, outline)
    return boundary, outline


def edge_classes(
    faces: np.ndarray, orientation: np.ndarray, n_vertices: int
) -> tuple[np.ndarray, np.ndarray]:
    """The boundary and the outline edges of ``faces``, each ``(k, 2)`` int64 ``(low, high)``
    pairs in ascending order (docs/math.md, section 6).

    An edge is smooth interior when exactly two half-edges run along it and the third
    vertices of their faces lie on opposite sides of the plane through the centre and the
    edge: for face ``(v0, v1, v2)`` that side is its ``orientation`` (the sign of
    ``det[v0, v1, v2]``, the same for its three edges), negated when the half-edge runs from
    the higher id to the lower. The outline is every edge that is not smooth; the boundary,
    the edges with one half-edge.

    Parameters
    ----------
    faces : (m, 3) int, vertex ids below ``n_vertices``
    orientation : (m,) int8 in {-1, 0, 1}
    n_vertices : int
    """
    orientation = np.ascontiguousarray(orientation, dtype=np.int8)
    return _classes(_checked(faces, n_vertices), orientation, n_vertices)


def _checked(faces: np.ndarray, n_vertices: int = 0) -> np.ndarray:
    """``faces`` C-contiguous, once it is known that the half-edges and the vertex ids fit
    the kernels' 32-bit integers (far beyond any mesh the service's limits admit)."""
    faces = np.ascontiguousarray(faces)
    if 3 * len(faces) >= 2**31 or max(n_vertices, int(faces.max(initial=0)) + 1) >= 2**31:
        raise ValueError("more half-edges or vertices than 32-bit ids hold")
    return faces
