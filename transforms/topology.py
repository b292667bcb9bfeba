"""Edges of a region: its boundary, its boundary loops, and the edges where its outline seen
from the centre can run (docs/math.md, section 6: boundary loops and margins).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from .checkpoints import checkpoint
from .halfedges import edge_classes, edge_pieces


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
    odd_edges : int, how many edges have an odd number of faces (none: the faces close up,
        every edge an even number of times, folds allowed)
    """

    boundary: np.ndarray
    outline: np.ndarray
    odd_edges: int = 0

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
    in one piece; labels count from 0, in the order of each piece's first face. With
    ``positions`` ((n, 3) float, the vertices), the vertices at one position count as one
    (:func:`welded`): a triangle soup (an STL, a scan split at its texture seams) is joined
    where its triangles meet.

    The half-edges are grouped by their edge in linear time and the faces on one edge
    joined (:func:`.halfedges.edge_pieces`)."""
    if len(faces) == 0:
        return np.zeros(0, dtype=np.int64)
    if positions is not None:
        faces = welded(faces, positions)
    checkpoint()
    return edge_pieces(faces)


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
    position (itself when it is alone there), with no tolerance; -0.0 and 0.0 are one
    position: the weld of docs/math.md, section 8.

    The positions' bits go into a hash table in row order (:func:`_first_rows`), so each
    point finds the first row at its place in one probe or a few: linear time, where
    sorting a triangle soup's three million corners took over a second.
    """
    if len(points) >= 2**31:  # far beyond the service's limits: the table holds int32 rows
        raise ValueError("more points than 32-bit rows hold")
    # + 0.0 turns -0.0 into 0.0, so that equal positions have equal bits.
    exact = np.ascontiguousarray(points, dtype=np.float64) + 0.0
    return _first_rows(exact.view(np.uint64))


@njit(cache=True, nogil=True)
def _first_rows(bits: np.ndarray) -> np.ndarray:
    """(n,) int64: for each row of ``bits`` ((n, 3) uint64), the first row equal to it; an
    open-addressing table of row numbers, twice the rows in size, probed linearly."""
    n = bits.shape[0]
    size = 2
    while size < 2 * n:
        size *= 2
    mask = np.uint64(size - 1)
    table = np.full(size, -1, dtype=np.int32)  # rows below 2^31: see representatives
    found = np.empty(n, dtype=np.int64)
    for i in range(n):
        x, y, z = bits[i, 0], bits[i, 1], bits[i, 2]
        mixed = x * np.uint64(0x9E3779B97F4A7C15)
        mixed ^= y * np.uint64(0xC2B2AE3D27D4EB4F)
        mixed ^= z * np.uint64(0x165667B19E3779F9)
        slot = (mixed ^ (mixed >> np.uint64(29))) & mask
        while True:
            j = table[slot]
            if j < 0:
                table[slot] = i
                found[i] = i
                break
            if bits[j, 0] == x and bits[j, 1] == y and bits[j, 2] == z:
                found[i] = j
                break
            slot = (slot + np.uint64(1)) & mask
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


def region_edges(faces: np.ndarray, orientation: np.ndarray, n_vertices: int) -> RegionEdges:
    """Classify the edges of ``faces``.

    An edge ``(a, b)`` is smooth interior when exactly two faces share it and their third
    vertices lie on opposite sides of the plane through the centre, ``a`` and ``b``. For the
    face ``(v0, v1, v2)`` that side is, for each of its edges, the face's own orientation seen
    from the centre (``det[v0, v1, v2]`` is the same for all three cyclic orders), negated
    when the edge runs from the higher to the lower index. The half-edges are grouped by
    their edge in linear time (:func:`.halfedges.edge_classes`).

    Parameters
    ----------
    faces : (m, 3) int, vertex indices
    orientation : (m,) int8, sign of ``det[v0, v1, v2]`` with the centre at the origin
    n_vertices : int, one more than the largest vertex index

    Returns
    -------
    RegionEdges
    """
    checkpoint()
    boundary, outline, odd = edge_classes(faces, orientation, n_vertices)
    return RegionEdges(boundary=boundary, outline=outline, odd_edges=odd)
