"""Edges of a region: its boundary, its boundary loops, and the edges where its outline seen
from the centre can run (docs/math.md, section 6: boundary loops and margins).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix, csr_matrix
from scipy.sparse.csgraph import connected_components

from .checkpoints import checkpoint
from .parallel import map_blocks


@dataclass(frozen=True)
class RegionEdges:
    """Undirected edges of a region, each as a vertex-index pair ``(a, b)`` with ``a < b``.

    Attributes
    ----------
    boundary : (k, 2) int, edges used by exactly one region face
    outline : (j, 2) int, every edge that is not a smooth interior edge: the boundary, plus
        folds (the two faces on the same side of the edge as seen from the centre), edges of
        faces seen edge-on, and edges with more than two faces. Seen from the centre, the
        outline of the region lies on these edges.
    """

    boundary: np.ndarray
    outline: np.ndarray

    def boundary_loops(self) -> int:
        """Number of boundary loops: connected components of the boundary edges (a disk has
        one, an annulus two, a closed surface none)."""
        if len(self.boundary) == 0:
            return 0
        ids, compact = np.unique(self.boundary, return_inverse=True)
        compact = compact.reshape(-1, 2)
        graph = coo_matrix(
            (np.ones(len(compact), dtype=np.int8), (compact[:, 0], compact[:, 1])),
            shape=(len(ids), len(ids)),
        )
        return int(connected_components(graph, directed=False)[0])


def face_components(faces: np.ndarray, positions: np.ndarray | None = None) -> np.ndarray:
    """(m,) int: the label of each face's piece, faces ((m, 3) int) that share an edge being
    in one piece; labels count from 0. With ``positions`` ((n, 3) float, the vertices), the
    vertices at one position count as one (:func:`welded`): a triangle soup (an STL, a scan
    split at its texture seams) is joined where its triangles meet.

    The half-edges are sorted by their edge (one sort of 3 m keys); two in a row on one edge
    join their faces, and the pieces are the components of that graph on the faces."""
    m = len(faces)
    if m == 0:
        return np.zeros(0, dtype=np.int64)
    if positions is not None:
        faces = welded(faces, positions)
    checkpoint()
    n = int(faces.max()) + 1
    # An edge as one number, low * n + high, built in place: two (m, 3) temporaries.
    high = faces[:, [1, 2, 0]].astype(np.int64)
    keys = np.minimum(faces, high, dtype=np.int64)
    np.maximum(faces, high, out=high)
    keys *= n
    keys += high
    del high
    # Stable: a scan's faces come in runs of neighbours, which a stable sort merges fast
    # (about 2.5 times quicker than the default on a subdivided head); the pairs and so the
    # pieces do not depend on the order of equal keys.
    order = np.argsort(keys.ravel(), kind="stable")
    checkpoint()
    ordered = keys.ravel()[order]
    pairs = np.flatnonzero(ordered[1:] == ordered[:-1])
    checkpoint()
    graph = coo_matrix(
        (np.ones(len(pairs), dtype=np.int8), (order[pairs] // 3, order[pairs + 1] // 3)),
        shape=(m, m),
    )
    return connected_components(graph, directed=False)[1]


def piece_sizes(labels: np.ndarray) -> np.ndarray:
    """(p,) int: the face count of each piece of :func:`face_components`' ``labels``
    ((m,) int), largest first (docs/math.md, section 8: welding and pieces)."""
    return -np.sort(-np.bincount(labels))


def largest_piece(labels: np.ndarray) -> np.ndarray:
    """(m,) bool: the faces of the largest piece (of most faces; of two as large, the one
    with the lowest label, the piece of the first face among them)."""
    return labels == np.argmax(np.bincount(labels))


def representatives(points: np.ndarray) -> np.ndarray:
    """(n,) int: for each of ``points`` ((n, 3) float), the lowest row at exactly its
    position (itself when it is alone there), found by sorting (no tolerance; -0.0 and 0.0
    are one position): the weld of docs/math.md, section 8.

    One sort of the first coordinate finds the points that share it with another; only those
    are sorted by all three (none, on most scans: the weld is then the identity).
    """
    points = np.asarray(points)
    n = len(points)
    found = np.arange(n)
    by_x = np.argsort(points[:, 0], kind="stable")
    x = points[by_x, 0]
    tied = np.zeros(n, dtype=bool)
    tied[1:] = x[1:] == x[:-1]
    tied[:-1] |= tied[1:]
    if not tied.any():
        return found
    rows = np.sort(by_x[tied])
    chosen = points[rows]
    order = rows[np.lexsort((rows, chosen[:, 2], chosen[:, 1], chosen[:, 0]))]
    ordered = points[order]
    fresh = np.ones(len(order), dtype=bool)
    fresh[1:] = (ordered[1:] != ordered[:-1]).any(axis=1)
    # The first of each run of equal points is its lowest row (the rows break the ties).
    found[order] = order[fresh][np.cumsum(fresh) - 1]
    return found


def welded_by(faces: np.ndarray, weld: np.ndarray) -> np.ndarray:
    """(m, 3) int: ``faces`` with each vertex replaced by ``weld``'s ((n,) int, from
    :func:`representatives`); ``faces`` itself when ``weld`` is the identity."""
    if (weld == np.arange(len(weld))).all():
        return faces
    return weld[faces]


def welded(faces: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """(m, 3) int: ``faces`` ((m, 3) int into ``positions``, (n, 3) float) with each vertex
    replaced by the lowest of the vertices they use at its exact position
    (:func:`representatives`): the same triangles, joined where their corners coincide."""
    used, inverse = np.unique(faces, return_inverse=True)
    same = representatives(np.asarray(positions)[used])
    return used[same][inverse.reshape(faces.shape)]


#: Per half-edge value summed per edge: the count in the low bits, (side + 1)^2 above. Two
#: uses with sides -1 and +1 (a smooth interior edge) sum to exactly 2 + (4 << count bits);
#: any other count or pair of sides gives another sum. int32 values (half the memory to
#: scatter) hold every sum while no edge has 2^13 uses: the sides then sum below 2^15.
_NARROW = (np.int32, 13)
_WIDE = (np.int64, 32)


def _value_table(dtype, count_bits: int) -> np.ndarray:
    """The value by ``3 * backwards + orientation + 1``, where ``backwards`` is 1 when the
    half-edge runs from the higher to the lower index (its side is then minus the
    orientation)."""
    by_side_plus_one = [1 + (k * k << count_bits) for k in range(3)]
    return np.array(by_side_plus_one + by_side_plus_one[::-1], dtype=dtype)


def region_edges(
    faces: np.ndarray, orientation: np.ndarray, n_vertices: int, threads: int = 1
) -> RegionEdges:
    """Classify the edges of ``faces``.

    An edge ``(a, b)`` is smooth interior when exactly two faces share it and their third
    vertices lie on opposite sides of the plane through the centre, ``a`` and ``b``. For the
    face ``(v0, v1, v2)`` that side is, for each of its edges, the face's own orientation seen
    from the centre (``det[v0, v1, v2]`` is the same for all three cyclic orders), negated
    when the edge runs from the higher to the lower index.

    Each half-edge contributes ``1 + 2^b (side + 1)^2`` at ``(low, high)`` of a sparse
    matrix whose construction sums the uses of each edge (a counting sort by row, no full
    sort): a smooth edge sums to ``2 + 4 * 2^b``, a boundary edge has count 1. With ``b = 13``
    first; should an edge have ``2^13`` uses or more (the counts then do not add up to the
    half-edges), once more with ``b = 32`` and 64-bit sums.

    Parameters
    ----------
    faces : (m, 3) int, vertex indices
    orientation : (m,) int8, sign of ``det[v0, v1, v2]`` with the centre at the origin
    n_vertices : int, one more than the largest vertex index
    threads : int, threads for building the per-half-edge arrays

    Returns
    -------
    RegionEdges
    """
    m = len(faces)
    index = np.int32 if n_vertices < 2**31 else np.int64  # what scipy would convert to
    low = np.empty(3 * m, dtype=index)
    high = np.empty(3 * m, dtype=index)
    code = np.empty(3 * m, dtype=np.int8)  # 3 * backwards + orientation + 1

    def half_edges(block: slice) -> bool:
        heads = faces[block].T  # (corner, face); each half-edge runs to the next corner
        tails = heads[[1, 2, 0]]
        rows = slice(3 * block.start, 3 * block.stop)
        shape = heads.shape
        np.minimum(heads, tails, out=low[rows].reshape(shape), casting="unsafe")
        np.maximum(heads, tails, out=high[rows].reshape(shape), casting="unsafe")
        codes = code[rows].reshape(shape)
        np.greater(heads, tails, out=codes.view(bool))
        codes *= 3
        codes += orientation[block] + 1
        return bool((heads == tails).any())  # a face repeating a vertex

    loops = any(map_blocks(half_edges, m, threads))
    if loops:  # an edge from a vertex to itself is no edge
        keep = low != high
        low, high, code = low[keep], high[keep], code[keep]
    for dtype, count_bits in (_NARROW, _WIDE):
        value = np.take(_value_table(dtype, count_bits), code)
        sums = csr_matrix((value, (low, high)), shape=(n_vertices, n_vertices))
        counts = sums.data & ((1 << count_bits) - 1)
        if int(counts.sum(dtype=np.int64)) == len(low):
            break
    outline = np.flatnonzero(sums.data != 2 + (4 << count_bits))
    boundary = outline[counts[outline] == 1]
    return RegionEdges(boundary=_pairs(sums, boundary), outline=_pairs(sums, outline))


def _pairs(matrix: csr_matrix, entries: np.ndarray) -> np.ndarray:
    """(k, 2) int: ``(row, column)`` of stored entries of a CSR matrix."""
    rows = np.searchsorted(matrix.indptr, entries, side="right") - 1
    return np.stack([rows, matrix.indices[entries]], axis=1).astype(np.int64)
