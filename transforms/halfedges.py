"""A mesh's half-edges grouped by their edge in linear time, and what is read from the groups:
the pieces faces sharing an edge make, and the edges' classes (docs/math.md, sections 6 and 8).

A half-edge of face ``f`` runs from corner ``c`` to corner ``c + 1`` (mod 3); its edge is
the pair ``(low, high)`` of its ends' vertex ids. Sorting ``3 m`` edge keys with numpy was the
slow part of both the pieces and the edge classes on a large scan, so here each half-edge is
packed into one integer whose high bits are its ``high`` end (and whose low bits carry what
is read of it: its row, or its side), the packed values are grouped by ``low`` with a
counting sort (vertex ids are small integers), and each vertex's few values are sorted: one
pass, linear in the half-edges, in compiled loops (numba; ``docs/architecture.md`` says why
numba). The scatter of the counting sort is bound by memory traffic, so the values are as
narrow as they can be.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .arrays import INDEX

#: A vertex's values are sorted by insertion below this many, by numpy's sort above (a fan of
#: thousands of faces round one vertex stays ``k log k``).
_INSERTION_BELOW = 33
#: The bits of a packed value below its ``high`` end: a row of up to 2^32 half-edges for the
#: pieces, a side code (0, 1 or 2) for the edge classes.
_ROW_BITS = 32
_SIDE_BITS = 2


@njit(cache=True, nogil=True)
def _grouped(low: np.ndarray, packed: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """``packed`` grouped by ``low`` (values below ``n``) and sorted within each group: the
    groups' starts ``(n + 1,)`` and the values ``(k,)``."""
    k = low.shape[0]
    start = np.zeros(n + 1, dtype=np.int32)  # k < 2^31 (_checked)
    for i in range(k):
        start[low[i] + 1] += 1
    for v in range(n):
        start[v + 1] += start[v]
    fill = start[:-1].copy()
    out = np.empty_like(packed)
    for i in range(k):
        at = fill[low[i]]
        out[at] = packed[i]
        fill[low[i]] = at + 1
    for v in range(n):
        first, last = start[v], start[v + 1]
        if last - first >= _INSERTION_BELOW:
            out[first:last] = np.sort(out[first:last])
            continue
        for j in range(first + 1, last):
            value = out[j]
            t = j
            while t > first and out[t - 1] > value:
                out[t] = out[t - 1]
                t -= 1
            out[t] = value
    return start, out


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
    low = np.empty(3 * m, dtype=np.int32)
    packed = np.empty(3 * m, dtype=np.int64)  # high << _ROW_BITS | half-edge row
    for f in range(m):
        for c in range(3):
            a, b = faces[f, c], faces[f, (c + 1) % 3]
            low[3 * f + c] = min(a, b)
            packed[3 * f + c] = (np.int64(max(a, b)) << _ROW_BITS) | (3 * f + c)
    start, grouped = _grouped(low, packed, n)
    parent = np.arange(m)
    mask = (np.int64(1) << _ROW_BITS) - 1
    for v in range(n):
        for j in range(start[v] + 1, start[v + 1]):
            if grouped[j] >> _ROW_BITS == grouped[j - 1] >> _ROW_BITS:  # the same edge
                a = _root(parent, (grouped[j] & mask) // 3)
                b = _root(parent, (grouped[j - 1] & mask) // 3)
                parent[max(a, b)] = min(a, b)
    # A larger root always joins a smaller, so a piece's root is its first face: numbered
    # when it is met, before the faces after it.
    labels = np.empty(m, dtype=np.int64)
    count = 0
    for f in range(m):
        r = _root(parent, f)
        if r == f:
            labels[f] = count
            count += 1
        else:
            labels[f] = labels[r]
    return labels


def edge_pieces(faces: np.ndarray) -> np.ndarray:
    """(m,) int64: the piece of each of ``faces`` ((m, 3) int, m >= 1, ids >= 0), faces that
    share an edge being in one piece; pieces are numbered from 0 in the order of their first
    face (as :func:`scipy.sparse.csgraph.connected_components` numbers them)."""
    faces = _checked(faces)
    return _components(faces, int(faces.max()) + 1)


@njit(cache=True, nogil=True)
def _side_values(faces: np.ndarray, orientation: np.ndarray, packed: np.ndarray) -> np.ndarray:
    """Fill ``packed`` ((3 m,), int32 or int64) with each half-edge's ``high << _SIDE_BITS |
    side + 1``, ``side`` that of its face's third vertex: the face's orientation, negated when
    the half-edge runs from the higher end to the lower; return the half-edges' ``low``."""
    m = faces.shape[0]
    low = np.empty(3 * m, dtype=np.int32)
    for f in range(m):
        for c in range(3):
            a, b = faces[f, c], faces[f, (c + 1) % 3]
            side = orientation[f] if a < b else -orientation[f]
            low[3 * f + c] = min(a, b)
            packed[3 * f + c] = (max(a, b) << _SIDE_BITS) | (side + 1)
    return low


@njit(cache=True, nogil=True)
def _walk_edges(
    start: np.ndarray, grouped: np.ndarray, boundary: np.ndarray, outline: np.ndarray
) -> tuple[int, int, int]:
    """Walk the half-edges grouped by edge: write the boundary and the outline edges' ends into
    ``boundary`` and ``outline`` ((k, 2), when they have rows) and return how many of each
    there are, and how many edges have an odd number of half-edges. An edge from a vertex to
    itself is no edge."""
    fill = boundary.shape[0] > 0 or outline.shape[0] > 0
    n_boundary = n_outline = n_odd = 0
    for v in range(start.shape[0] - 1):
        j, last = start[v], start[v + 1]
        while j < last:
            high = grouped[j] >> _SIDE_BITS
            uses = summed = 0
            while j < last and grouped[j] >> _SIDE_BITS == high:
                side = (grouped[j] & 3) - 1
                summed += (side + 1) * (side + 1)  # 0, 1 or 4
                uses += 1
                j += 1
            if high == v:
                continue
            n_odd += uses % 2
            # Smooth: two half-edges on opposite sides (the only two whose squares sum to 4).
            if uses == 2 and summed == 4:
                continue
            if fill:
                outline[n_outline, 0], outline[n_outline, 1] = v, high
            n_outline += 1
            if uses == 1:
                if fill:
                    boundary[n_boundary, 0], boundary[n_boundary, 1] = v, high
                n_boundary += 1
    return n_boundary, n_outline, n_odd


def edge_classes(
    faces: np.ndarray, orientation: np.ndarray, n_vertices: int
) -> tuple[np.ndarray, np.ndarray, int]:
    """The boundary and the outline edges of ``faces``, each ``(k, 2)`` int64 ``(low, high)``
    pairs in ascending order, and how many edges have an odd number of faces (docs/math.md,
    section 6).

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
    faces = _checked(faces, n_vertices)
    # 32-bit values while the ids leave room for the side's two bits: half the bytes to move.
    narrow = n_vertices < 2 ** (31 - _SIDE_BITS)
    packed = np.empty(3 * len(faces), dtype=np.int32 if narrow else np.int64)
    low = _side_values(faces, np.ascontiguousarray(orientation, dtype=np.int8), packed)
    start, grouped = _grouped(low, packed, n_vertices)
    none = np.empty((0, 2), dtype=np.int64)
    n_boundary, n_outline, n_odd = _walk_edges(start, grouped, none, none)
    boundary = np.empty((n_boundary, 2), dtype=np.int64)
    outline = np.empty((n_outline, 2), dtype=np.int64)
    if n_outline:
        _walk_edges(start, grouped, boundary, outline)
    return boundary, outline, n_odd


def _checked(faces: np.ndarray, n_vertices: int = 0) -> np.ndarray:
    """``faces`` as C-contiguous int32 (:data:`.arrays.INDEX`, the one type the kernels are
    compiled for), once it is known that the half-edges and the vertex ids fit the kernels'
    integers (far beyond any mesh the service's limits admit)."""
    faces = np.asarray(faces)
    limit = 2**31
    if 3 * len(faces) >= limit or max(n_vertices, int(faces.max(initial=0)) + 1) >= limit:
        raise ValueError("more half-edges or vertices than the kernels' integers hold")
    return np.ascontiguousarray(faces, dtype=INDEX)
