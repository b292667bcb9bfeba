"""Nearest points, and the registration's last rounds on them (docs/math.md, section 15):
nearest points among points (:class:`NearestTree`, small_gicp's k-d tree), on a triangle mesh
(:class:`MeshNearest`), and the Gauss-Newton rounds that take a follow-up's points onto the
baseline's mesh itself (:func:`on_mesh`, eq. 15.4).

On a mesh, each point starts from the face of its nearest seed (a registration sample, or a
vertex; small_gicp's k-d tree) and walks: while a face sharing a corner with the best face so
far has a nearer point, it moves there (each triangle's nearest point in closed form, by the
Voronoi regions of its corners and edges: Ericson, Real-Time Collision Detection, 5.1.5).
That ends at a face nearer than every face around it: the nearest point of the mesh wherever
the point lies closer to the surface than the surface's own folds are wide (the
registration's pairs: a scan's noise from the other scan), and it costs about a microsecond
a point, compiled by numba, where libigl's bounding-box tree took 65 ms to build on 100,000
faces and 2 us a point to ask."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numba
import numpy as np
import small_gicp
from scipy.spatial.transform import Rotation

from .arrays import blocks, face_cross, unit_rows
from .checkpoints import checkpoint

#: The last rounds (:func:`on_mesh`) end when a step has moved the points by less than
#: ``EXACT`` of their spread, after ``MESH_ROUNDS`` at the most.
EXACT, MESH_ROUNDS = 1e-5, 10
#: They keep the pairs within this many times the 30th percentile of their distances: there
#: the distances are the scans' noise, whose 30th percentile is 0.385 of its standard
#: deviation, so 8 times it is 3 deviations, and leaves out almost no pair that has a
#: counterpart (at ICP's 2.5 times, about one deviation, a third of them went, and with them
#: half of the accuracy).
MESH_TRIM, TRIM_QUANTILE = 8.0, 30.0
#: ICP, and the last rounds, start on every ``SPARSE_EVERY``-th follow-up sample (when that
#: leaves at least ``SPARSE_LEAST``).
SPARSE_EVERY, SPARSE_LEAST = 4, 1_000


class NearestTree:
    """Nearest neighbours among ``(n, 3)`` points, by small_gicp's k-d tree (nanoflann's) on
    one thread: what scipy's ``cKDTree.query`` answers (the distances, then the indices),
    about 1.6 times as fast on a scan's samples, and the tree small_gicp's ICP takes."""

    def __init__(self, points: np.ndarray) -> None:
        points = np.ascontiguousarray(points, dtype=np.float64)
        self.kdtree = small_gicp.KdTree(points, num_threads=1)

    def query(self, points: np.ndarray, k: int = 1) -> tuple[np.ndarray, np.ndarray]:
        """(q,) distances and (q,) int indices of each point's nearest; with ``k`` above 1,
        (q, k) each, nearest first."""
        points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        if not len(points):
            shape = (0,) if k == 1 else (0, k)
            return np.empty(shape), np.empty(shape, dtype=np.int64)
        if k == 1:
            index, squared = self.kdtree.batch_nearest_neighbor_search(points, num_threads=1)
        else:
            index, squared = self.kdtree.batch_knn_search(points, k, num_threads=1)
        distance = np.sqrt(np.asarray(squared, dtype=np.float64))
        return distance, np.asarray(index, dtype=np.int64)


@dataclass(frozen=True)
class Foot:
    """Points' nearest points on a mesh: ``points`` (p, 3), the unit normals of the faces
    they lie on (p, 3), their distances (p,), and those faces (p,) int (for
    :meth:`MeshNearest.nearest`'s ``near``)."""

    points: np.ndarray
    normals: np.ndarray
    distance: np.ndarray
    faces: np.ndarray


class MeshNearest:
    """Nearest points on the triangles ``faces`` ((m, 3) int) of ``vertices`` ((n, 3)); the
    faces of no area left out (they have no normal). ``seeds``, when given: a k-d tree of
    points on the faces and the face (a row of ``faces``) each lies on, which the walks then
    start from (the registration's samples, whose tree is built already); else a tree of the
    vertices is built on first use."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, seeds=None) -> None:
        self.vertices = np.ascontiguousarray(vertices, dtype=np.float64)
        faces = np.asarray(faces, dtype=np.int64)
        normals, flat = unit_rows(face_cross(self.vertices, faces))
        self.normals = normals[~flat]
        self.faces = np.ascontiguousarray(faces[~flat])
        self._seeds = None
        if seeds is not None:
            tree, on = seeds
            renumbered = np.cumsum(~flat) - 1  # a seed on a face of no area: its neighbour's
            self._seeds = tree, np.maximum(renumbered[np.asarray(on, dtype=np.int64)], 0)

    @cached_property
    def _tree(self) -> tuple[small_gicp.KdTree, np.ndarray]:
        """A k-d tree of seeds, and the face each lies on."""
        if self._seeds is not None:
            return self._seeds
        used = np.unique(self.faces)
        offsets, faces_around = self._around
        tree = small_gicp.KdTree(self.vertices[used], num_threads=1)
        return tree, faces_around[offsets[used]]

    @cached_property
    def _around(self) -> tuple[np.ndarray, np.ndarray]:
        """The faces around each vertex: offsets (n + 1,) into face ids."""
        counts = np.bincount(self.faces.ravel(), minlength=len(self.vertices))
        offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        return offsets, _bucketed(self.faces, offsets)

    def nearest(self, points: np.ndarray, near: Foot | None = None) -> Foot:
        """Each point's nearest point on the faces, that face's normal, and the distance;
        the walk starts from the faces around each point's nearest vertex, or with ``near``
        (the same points' feet a little while ago) from its faces' corners."""
        points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        if not len(points) or not len(self.faces):
            count = len(points)
            return Foot(points.copy(), np.zeros_like(points), np.full(count, np.inf),
                        np.full(count, -1))  # fmt: skip
        offsets, faces_around = self._around
        foot, face = np.empty_like(points), np.empty(len(points), dtype=np.int64)
        squared = np.empty(len(points))
        # A block of points at a time, each after a checkpoint: a served job past its time
        # limit stops within a block, not after all of a large scan's vertices.
        for block in blocks(len(points)):
            if near is not None and len(near.faces) == len(points):
                starts = near.faces[block]
            else:  # the face of each point's nearest seed
                tree, on = self._tree
                index, _ = tree.batch_nearest_neighbor_search(points[block], num_threads=1)
                starts = on[np.asarray(index, dtype=np.int64)]
            foot[block], face[block], squared[block] = _walk(
                points[block], self.vertices, self.faces, offsets, faces_around,
                np.ascontiguousarray(starts, dtype=np.int64),
            )  # fmt: skip
        return Foot(foot, self.normals[face], np.sqrt(squared), face)


def onto_mesh(source, mesh: MeshNearest, start: np.ndarray, scale: bool, bounds) -> np.ndarray:
    """The last rounds (:func:`on_mesh`): the sparse samples onto the mesh, then the
    follow-up's vertices (``Surface.corners``), the few rounds that need all of them (for
    a follow-up that is :func:`dense`)."""
    matrix = start
    if len(source.points) >= SPARSE_EVERY * SPARSE_LEAST:
        matrix = on_mesh(source.sparse, mesh, matrix, scale, bounds)
    return on_mesh(source.corners, mesh, matrix, scale, bounds)


def dense(source) -> bool:
    """Whether the last rounds pay on this follow-up: it has at least as many vertices as
    samples. There its vertices carry more of its noise than the samples do (a 100k-face
    head with 0.1 mm of noise: 0.005 to 0.011 mm, against 0.04 to 0.10 from ICP on the
    samples); on a coarse scan they carried less, and ICP on the samples did better
    (fsaverage's 4,062 faces, 0.3 mm of noise: 0.03 to 0.15 mm against 0.045 to 0.077)."""
    return source.corners is not source and len(source.corners.points) >= len(source.points)


def on_mesh(
    source,
    mesh: MeshNearest,
    start: np.ndarray,
    scale: bool = False,
    bounds: tuple[float, float] | None = None,
    rounds: int = MESH_ROUNDS,
) -> np.ndarray:
    """The 4x4 transform from ``start`` that takes the follow-up's points (``source``: its
    samples, or its vertices) onto the baseline's mesh itself (eq. 15.4): each round pairs
    every moved point with its nearest point on the mesh (:class:`MeshNearest`),
    leaves out the pairs beyond the trimming distance, and takes one Gauss-Newton step of
    eq. 15.1 with that point and its face's normal (with ``scale``, of the scale about where
    the follow-up's centroid lands too, held within ``bounds``); until a step has moved the
    points by less than ``EXACT`` of their spread. The baseline's samples lie a sample's
    spacing apart, and a plane through the nearest one is off the surface by its curvature
    times the square of that spacing: on a head a few hundredths of a millimetre, the same
    way over the whole scan, which is what the last rounds remove."""
    matrix = np.array(start, dtype=np.float64)
    points = source.points
    spread = source.size + 1e-300
    centre = points.mean(axis=0)
    foot = None
    for _ in range(rounds):
        checkpoint()
        moved = points @ matrix[:3, :3].T + matrix[:3, 3]
        foot = mesh.nearest(moved, foot)
        keep = foot.distance <= MESH_TRIM * np.percentile(foot.distance, TRIM_QUANTILE) + 1e-12
        if not keep.any():
            break
        x, normal = moved[keep], foot.normals[keep]
        middle = x.mean(axis=0)
        gap = np.einsum("pd,pd->p", x - foot.points[keep], normal)
        columns = [np.cross(x - middle, normal), normal]
        grow = float(np.cbrt(np.linalg.det(matrix[:3, :3])))
        landed = matrix[:3, :3] @ centre + matrix[:3, 3]
        if scale:  # x = landed + grow R (p - c): a relative change of grow moves x by x - landed
            columns.append(np.einsum("pd,pd->p", x - landed, normal)[:, None])
        jacobian = np.column_stack(columns)
        normal_matrix = jacobian.T @ jacobian
        delta = -np.linalg.lstsq(normal_matrix, jacobian.T @ gap, rcond=None)[0]
        turn, shift = delta[:3], delta[3:6]
        change = 0.0
        if scale:
            grown_to = grow * (1.0 + delta[6])
            if bounds is not None:
                grown_to = float(np.clip(grown_to, *bounds))
            change = grown_to / grow - 1.0
        size = float(np.linalg.norm(turn)) * grow * spread + float(np.linalg.norm(shift))
        size += abs(change) * grow * spread
        if not np.isfinite(size):  # no step at all
            break
        rotation = Rotation.from_rotvec(turn).as_matrix()
        step = np.eye(4)
        step[:3, :3] = rotation
        step[:3, 3] = middle - rotation @ middle + shift
        if scale:
            grown = np.eye(4)
            grown[:3, :3] *= 1.0 + change
            grown[:3, 3] = -change * landed
            matrix = grown @ matrix
        matrix = step @ matrix
        if size < EXACT * grow * spread:  # settled: this step was the last
            break
    return matrix


@numba.njit(cache=True, nogil=True)
def _bucketed(faces, offsets):  # pragma: no cover - compiled
    """Each face's id at its corners' places: the faces around each vertex, in one pass."""
    filled = offsets[:-1].copy()
    around = np.empty(offsets[-1], dtype=np.int64)
    for face in range(faces.shape[0]):
        for k in range(3):
            vertex = faces[face, k]
            around[filled[vertex]] = face
            filled[vertex] += 1
    return around


@numba.njit(cache=True, nogil=True, inline="always")
def _closest(p0, p1, p2, a0, a1, a2, b0, b1, b2, c0, c1, c2):  # pragma: no cover - compiled
    """The nearest point of triangle ``abc`` to ``p`` (Ericson 5.1.5), as weights of b, c."""
    ab0, ab1, ab2 = b0 - a0, b1 - a1, b2 - a2
    ac0, ac1, ac2 = c0 - a0, c1 - a1, c2 - a2
    ap0, ap1, ap2 = p0 - a0, p1 - a1, p2 - a2
    d1 = ab0 * ap0 + ab1 * ap1 + ab2 * ap2
    d2 = ac0 * ap0 + ac1 * ap1 + ac2 * ap2
    if d1 <= 0.0 and d2 <= 0.0:
        return 0.0, 0.0
    bp0, bp1, bp2 = p0 - b0, p1 - b1, p2 - b2
    d3 = ab0 * bp0 + ab1 * bp1 + ab2 * bp2
    d4 = ac0 * bp0 + ac1 * bp1 + ac2 * bp2
    if d3 >= 0.0 and d4 <= d3:
        return 1.0, 0.0
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        return d1 / (d1 - d3), 0.0
    cp0, cp1, cp2 = p0 - c0, p1 - c1, p2 - c2
    d5 = ab0 * cp0 + ab1 * cp1 + ab2 * cp2
    d6 = ac0 * cp0 + ac1 * cp1 + ac2 * cp2
    if d6 >= 0.0 and d5 <= d6:
        return 0.0, 1.0
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        return 0.0, d2 / (d2 - d6)
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return 1.0 - w, w
    total = va + vb + vc
    if total == 0.0:  # a face of no area (left out before: kept for safety)
        return 0.0, 0.0
    return vb / total, vc / total


@numba.njit(cache=True, nogil=True, inline="always")
def _foot(p0, p1, p2, face, vertices, faces):  # pragma: no cover - compiled
    """The nearest point of ``face`` to ``p``, and its squared distance."""
    ia, ib, ic = faces[face, 0], faces[face, 1], faces[face, 2]
    a0, a1, a2 = vertices[ia, 0], vertices[ia, 1], vertices[ia, 2]
    b0, b1, b2 = vertices[ib, 0], vertices[ib, 1], vertices[ib, 2]
    c0, c1, c2 = vertices[ic, 0], vertices[ic, 1], vertices[ic, 2]
    s, t = _closest(p0, p1, p2, a0, a1, a2, b0, b1, b2, c0, c1, c2)
    h0 = a0 + s * (b0 - a0) + t * (c0 - a0)
    h1 = a1 + s * (b1 - a1) + t * (c1 - a1)
    h2 = a2 + s * (b2 - a2) + t * (c2 - a2)
    return (h0 - p0) ** 2 + (h1 - p1) ** 2 + (h2 - p2) ** 2, h0, h1, h2


@numba.njit(cache=True, nogil=True)
def _walk(points, vertices, faces, offsets, around, starts):  # pragma: no cover - compiled
    """For each point, from its face in ``starts`` ((p,) int), to a face around the best
    face's corners while one of them comes nearer: the foot, its face, its squared
    distance."""
    count = points.shape[0]
    foot = np.empty((count, 3))
    found = np.empty(count, dtype=np.int64)
    squared = np.empty(count)
    for i in range(count):
        p0, p1, p2 = points[i, 0], points[i, 1], points[i, 2]
        best = starts[i]
        best_d, x0, x1, x2 = _foot(p0, p1, p2, best, vertices, faces)
        improved = True
        while improved:
            improved = False
            centre = best
            for k in range(3):
                v = faces[centre, k]
                for j in range(offsets[v], offsets[v + 1]):
                    face = around[j]
                    dist, h0, h1, h2 = _foot(p0, p1, p2, face, vertices, faces)
                    if dist < best_d:
                        best_d, best, x0, x1, x2 = dist, face, h0, h1, h2
                        improved = True
        foot[i, 0], foot[i, 1], foot[i, 2] = x0, x1, x2
        found[i] = best
        squared[i] = best_d
    return foot, found, squared
