"""The kernel of a region: the points every region triangle faces (docs/math.md, section 9:
back-facing is ``dot(centroid - c, outward normal) <= 0``, so the kernel is where no face is
back-facing).

Each face keeps the centre on the inner side of its plane: ``n . c < n . v0`` with ``n`` its
unit outward normal. An open region (a scalp) faces every point far enough behind it, so each
boundary loop adds the plane that closes it (through the loop's centroid, against the loop's
vector area): the kernel of the region with its holes closed. A box around the region in its
own inertia frame keeps the problem bounded when the region is flat.

The deepest point of the kernel (its Chebyshev centre: the centre of the largest ball inside)
is one small linear program, solved with scipy's HiGHS on a sample of the faces and re-solved
with the faces it violates added until it holds for every face.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import sparse
from scipy.optimize import linprog
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from ..arrays import blocks, unit_scale
from ..checkpoints import checkpoint
from ..errors import TransformInputError
from ..sampling import area_sample
from ..topology import region_edges

#: Faces in the first linear program, and the most violated faces added per round. A few
#: planes bind: on a region of up to ``_SMALL_REGION`` faces the first program takes
#: ``_FIRST_FACES_SMALL`` (a solve's cost grows with its rows), on a larger one
#: ``_FIRST_FACES``, so that fewer rounds check every plane.
_FIRST_FACES = 2048
_FIRST_FACES_SMALL = 256
_SMALL_REGION = 32_768
_ADDED_FACES = 4096
_ROUNDS = 30
#: Faces in the least-back-facing programs when the kernel is empty, and their rounds.
_EMPTY_KERNEL_FACES = 4096
_REWEIGHTING_ROUNDS = 3
#: The box around the region, as the solver's bounds on the frame coordinates (``_in_frame``).
_IN_THE_BOX = [(-1.0, 1.0)] * 3
#: Within this many region sizes of a face's plane, a centre counts as seeing it edge-on.
_EDGE_ON = 1e-9
#: How far, in region sizes, a least back-facing centre moves off the planes it lies on.
_NUDGE = 1e-4
#: The weight of the L1 distance from the region's middle (in region sizes) that makes the
#: least back-facing centre one point (:func:`_least_backfacing`).
_TIE_BREAK = 1e-7


@dataclass(frozen=True)
class KernelPlanes:
    """Half-spaces ``normals @ c < offsets`` whose intersection is the (closed) kernel.

    Attributes
    ----------
    normals : (k, 3) float, unit outward normals: the region's non-degenerate faces first,
        then one closing plane per boundary loop
    offsets : (k,) float
    areas : (k,) float, face areas (0 for the closing planes)
    faces : (j,) int, which face of the region each of the first ``j`` planes is
    size : float, the region's bounding radius (the box's half-width)
    middle : (3,) float, the area-weighted centroid of the region
    box_middle : (3,) float, the centre of its bounding box
    axes : (3, 3) float, the region's inertia axes (rows)
    boundary_vertices : (b,) int, ascending: the vertices on the region's boundary
    boundary_edges : (e, 2) int: the region's boundary edges (lower vertex first), as
        :func:`transforms.topology.region_edges` finds them
    """

    normals: np.ndarray
    offsets: np.ndarray
    areas: np.ndarray
    faces: np.ndarray
    size: float
    middle: np.ndarray
    box_middle: np.ndarray
    axes: np.ndarray
    boundary_vertices: np.ndarray
    boundary_edges: np.ndarray

    def depth(self, center: np.ndarray) -> float:
        """Distance from ``center`` to the nearest face plane (the closing planes left out),
        negative outside the region's own kernel."""
        j = len(self.faces)
        return float((self.offsets[:j] - self.normals[:j] @ center).min())

    def depths(self, centers: np.ndarray) -> np.ndarray:
        """(k,) :meth:`depth` of each of ``centers`` (k, 3), in one pass over the planes
        (block by block, so the (k, faces) distances are never held at once)."""
        nearest = np.full(len(centers), np.inf)
        for block in blocks(len(self.faces)):
            distances = self.offsets[block] - centers @ self.normals[block].T
            np.minimum(nearest, distances.min(axis=1), out=nearest)
        return nearest

    def backfacing_area(self, center: np.ndarray) -> float:
        """Area of the faces whose plane ``center`` is not inside of by more than
        ``_EDGE_ON`` region sizes: a linear program's answer lies on planes, and which side of
        them rounding puts it must not decide between candidates."""
        j = len(self.faces)
        inside = self.offsets[:j] - self.normals[:j] @ center
        return float(self.areas[:j][inside <= _EDGE_ON * self.size].sum())


@dataclass(frozen=True)
class Kernel:
    """The chosen centre and what the kernel looks like from it.

    Attributes
    ----------
    center : (3,) float, the Chebyshev centre, or where the kernel is empty the centre that
        leaves the least area-weighted back-facing distance
    inscribed_radius : float, radius of the largest ball in the kernel (0 when empty)
    empty : bool
    """

    center: np.ndarray
    inscribed_radius: float
    empty: bool


def kernel_planes(vertices: np.ndarray, faces: np.ndarray) -> KernelPlanes:
    """The half-spaces of a region's kernel.

    One pass over blocks of faces gives each face's plane and the region's moments: the
    area-weighted sums of the centroids and of their outer products (the middle and the
    inertia, ``sum w (c - m)(c - m)^T = sum w c c^T - W m m^T``), and the sums that fix the
    winding (``sum n . (c - m) = sum n . c - m . sum n``); the winding's sign then flips the
    planes, which is exact.

    Parameters
    ----------
    vertices : (n, 3) float, world coordinates
    faces : (m, 3) int, the region's faces

    Raises
    ------
    TransformInputError
        Every face is degenerate.
    """
    # In units where the largest coordinate is below 1 (a power of two: exact), so that no
    # square or product of coordinates over- or underflows; the planes are scaled back.
    scale = unit_scale(float(np.abs(vertices).max()))
    scaled = vertices * scale
    rows = np.ascontiguousarray(scaled.T)
    # The closing planes first (their side flips with the winding, found last), so that
    # every plane is written once into arrays of the final size.
    boundary, edges, closing_normals, closing_offsets = _closing_planes(scaled, faces)
    m, loops = len(faces), len(closing_offsets)
    normals, offsets, areas = np.empty((m + loops, 3)), np.empty(m + loops), np.zeros(m + loops)
    normals[m:], offsets[m:] = closing_normals, closing_offsets
    moments = _Moments()
    for block in blocks(m):
        corners = _corners(rows, faces[block])
        cross = _cross(corners)
        area = np.sqrt(_dot(cross, cross))
        areas[block] = area
        moments.add(corners, cross, area)
        with np.errstate(divide="ignore", invalid="ignore"):
            unit = cross / area
        normals[block] = unit.T
        offsets[block] = _dot(unit, corners[:, 0])
    del rows
    measured = areas[:m] > 0
    keep = np.flatnonzero(measured)
    if keep.size == 0:
        raise TransformInputError("faces", "every face of the region has zero area")
    if keep.size < m:  # degenerate faces have no plane
        rows_kept = np.concatenate([measured, np.ones(loops, dtype=bool)])
        normals, offsets, areas = normals[rows_kept], offsets[rows_kept], areas[rows_kept]
    middle, axes, winding = moments.middle_axes_winding()
    if winding < 0:  # the file's winding is inward: every plane turns round
        np.negative(normals, out=normals)
        np.negative(offsets, out=offsets)
    used = scaled[np.bincount(faces.ravel(), minlength=len(scaled)) > 0]
    del scaled
    reach = used - middle
    size = float(np.sqrt(_dot(reach.T, reach.T).max()))
    offsets /= scale
    areas *= 0.5 / scale**2  # the closing planes' stay 0
    return KernelPlanes(
        normals=normals,
        offsets=offsets,
        areas=areas,
        faces=keep,
        size=size / scale,
        middle=middle / scale,
        box_middle=(used.min(axis=0) + used.max(axis=0)) / (2.0 * scale),
        axes=axes.T,
        boundary_vertices=boundary,
        boundary_edges=edges,
    )


class _Moments:
    """The area-weighted moments of the faces' centroids, summed block by block."""

    def __init__(self) -> None:
        self.weight, self.first, self.second = 0.0, np.zeros(3), np.zeros((3, 3))
        self.normal, self.normal_at = np.zeros(3), 0.0

    def add(self, corners: np.ndarray, cross: np.ndarray, area: np.ndarray) -> None:
        """``corners`` (3, 3, k), ``cross`` (3, k) twice the faces' vector areas, ``area``
        (k,) their lengths (the weights)."""
        centroids = corners.sum(axis=1) / 3.0  # (axis, k)
        weighted = centroids * area
        self.weight += float(area.sum())
        self.first += weighted.sum(axis=1)
        self.second += weighted @ centroids.T
        self.normal += cross.sum(axis=1)
        self.normal_at += float(_dot(cross, centroids).sum())

    def middle_axes_winding(self) -> tuple[np.ndarray, np.ndarray, int]:
        """The area-weighted middle (3,), the inertia axes (columns) and the winding: +1
        when the signed volume seen from the middle is positive (the normals point out)."""
        middle = self.first / self.weight
        _, axes = np.linalg.eigh(self.second - self.weight * np.outer(middle, middle))
        # Each axis points along its largest component: the solver's frame is then the same
        # for the same surface (the eigen-solver's signs jump with rounding), as the fit,
        # run in the region's own frame (:mod:`.pose`), needs.
        largest = np.argmax(np.abs(axes), axis=0)
        axes = axes * np.sign(axes[largest, np.arange(3)])
        volume = self.normal_at - float(middle @ self.normal)
        return middle, axes, 1 if volume >= 0 else -1


def _corners(rows: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(3, 3, k) float, ``[axis, corner, face]``: the corners of ``faces`` (k, 3) from vertex
    rows (3, n)."""
    ids = np.ascontiguousarray(faces.T)
    return np.stack([np.take(rows[axis], ids) for axis in range(3)])


def _cross(corners: np.ndarray) -> np.ndarray:
    """(3, k) float: ``(c1 - c0) x (c2 - c0)`` of corners (3, 3, k)."""
    e1 = corners[:, 1] - corners[:, 0]
    e2 = corners[:, 2] - corners[:, 0]
    return np.stack(
        [e1[(i + 1) % 3] * e2[(i + 2) % 3] - e1[(i + 2) % 3] * e2[(i + 1) % 3] for i in range(3)]
    )


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(k,) row-wise dot product of (3, k) arrays."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _closing_planes(
    vertices: np.ndarray, faces: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The boundary's vertices (b,), its edges (e, 2) and one plane per boundary loop,
    ``(normals (l, 3), offsets (l,))``: through the loop's centroid, its normal against the
    loop's vector area (outward, the side the region's faces turn away from, when the faces
    are wound outward; the caller turns them round otherwise)."""
    n = len(vertices)
    boundary = region_edges(faces, np.ones(len(faces), dtype=np.int8), n).boundary
    if len(boundary) == 0:
        return np.zeros(0, dtype=np.int64), boundary, np.zeros((0, 3)), np.zeros(0)
    # Direct each boundary edge as its face runs it: only half-edges between two boundary
    # vertices can be boundary edges, so only those are looked up.
    boundary_vertex = np.zeros(n, dtype=bool)
    boundary_vertex[boundary.ravel()] = True
    corner_on = boundary_vertex[faces]
    half_edges = np.flatnonzero(corner_on & corner_on[:, [1, 2, 0]])  # (face, corner) runs
    del corner_on
    heads = faces.ravel()[half_edges].astype(np.int64)
    tails = faces.ravel()[half_edges - half_edges % 3 + (half_edges + 1) % 3].astype(np.int64)
    keys = np.minimum(heads, tails) * n + np.maximum(heads, tails)
    boundary_keys = np.sort(boundary[:, 0] * n + boundary[:, 1])
    spot = np.minimum(np.searchsorted(boundary_keys, keys), len(boundary_keys) - 1)
    on_boundary = boundary_keys[spot] == keys
    starts, ends = heads[on_boundary], tails[on_boundary]
    graph = coo_matrix((np.ones(len(starts)), (starts, ends)), shape=(n, n))
    _, labels = connected_components(graph, directed=False)
    loop = labels[starts]
    loops = np.unique(loop)
    a, b = vertices[starts], vertices[ends]
    vector_area = np.zeros((len(loops), 3))
    np.add.at(vector_area, np.searchsorted(loops, loop), 0.5 * np.cross(a, b))
    centroid = np.zeros((len(loops), 3))
    count = np.zeros(len(loops))
    np.add.at(centroid, np.searchsorted(loops, loop), a)
    np.add.at(count, np.searchsorted(loops, loop), 1.0)
    centroid /= count[:, None]
    length = np.linalg.norm(vector_area, axis=1)
    keep = length > 0
    normals = -vector_area[keep] / length[keep, None]
    on_boundary = np.flatnonzero(boundary_vertex)
    return on_boundary, boundary, normals, np.einsum("ij,ij->i", normals, centroid[keep])


def chebyshev_center(planes: KernelPlanes) -> Kernel:
    """The deepest point of the kernel; where the kernel is empty, the centre that minimises
    the area-weighted distance by which faces are seen from behind.

    Both are linear programs in the region's inertia frame, on an area-weighted sample of the
    faces; the Chebyshev one adds the faces its answer violates and solves again until its
    answer holds for all faces.
    """
    j = len(planes.faces)
    # A flat or nearly flat region's closing planes leave no room: its own half-spaces (and
    # the box) then make the kernel.
    for count in (len(planes.normals), j):
        found = _chebyshev(planes, count)
        if found is not None:
            center, radius = found
            return Kernel(center=center, inscribed_radius=radius, empty=False)
    return Kernel(center=_least_backfacing_area(planes), inscribed_radius=0.0, empty=True)


def _chebyshev(planes: KernelPlanes, count: int) -> tuple[np.ndarray, float] | None:
    """The largest ball inside the first ``count`` planes (faces first, then the closing
    ones) and the box, by constraint generation; None when there is none."""
    j = len(planes.faces)
    first = _FIRST_FACES_SMALL if j <= _SMALL_REGION else _FIRST_FACES
    rows = np.concatenate([area_sample(planes.areas[:j], first), np.arange(j, count)])
    normals, offsets = planes.normals[:count], planes.offsets[:count]
    for _ in range(_ROUNDS):
        checkpoint()
        center, radius = _deepest(planes, rows)
        if radius <= 1e-12 * planes.size:
            return None
        slack = offsets - normals @ center - radius
        violated = np.flatnonzero(slack < -1e-9 * planes.size)
        if violated.size == 0:
            return center, radius
        worst = violated[np.argsort(slack[violated], kind="stable")[:_ADDED_FACES]]
        rows = np.union1d(rows, worst)
    return None


def _least_backfacing_area(planes: KernelPlanes) -> np.ndarray:
    """A centre leaving little back-facing area: the minimiser of the area-weighted distance
    by which faces are seen from behind, then of the same reweighted by one over each face's
    distance (which approaches the area itself); the best of these, the region's middle and
    its box's centre, by the back-facing area over all faces."""
    j = len(planes.faces)
    rows = area_sample(planes.areas[:j], _EMPTY_KERNEL_FACES)
    weights = planes.areas[rows]
    candidates = [planes.middle, planes.box_middle]
    for _ in range(_REWEIGHTING_ROUNDS):
        checkpoint()
        center = _least_backfacing(planes, rows, weights)
        candidates.append(center)
        behind = np.maximum(planes.normals[rows] @ center - planes.offsets[rows], 0.0)
        weights = planes.areas[rows] / (behind + 1e-3 * planes.size)
    return _off_the_planes(planes, min(candidates, key=planes.backfacing_area))


def _off_the_planes(planes: KernelPlanes, center: np.ndarray) -> np.ndarray:
    """``center`` moved ``_NUDGE`` region sizes to the inner side of the face planes it lies
    on (within ``_EDGE_ON``), when that leaves no more area behind: a linear program's
    answer is a vertex of planes, from which their faces are seen edge-on, and the map of a
    face seen edge-on turns with the last bit of rounding."""
    j = len(planes.faces)
    inside = planes.offsets[:j] - planes.normals[:j] @ center
    on = np.abs(inside) <= _EDGE_ON * planes.size
    if not on.any():
        return center
    away = -(planes.areas[:j][on] @ planes.normals[:j][on])
    length = float(np.linalg.norm(away))
    if not length > 0:
        return center
    moved = center + _NUDGE * planes.size * away / length
    return moved if planes.backfacing_area(moved) <= planes.backfacing_area(center) else center


def _in_frame(planes: KernelPlanes, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The planes ``rows`` in the region's inertia frame, lengths in units of its size (the
    solver's tolerances are relative): ``local @ x <= scaled`` for ``c = middle + size x @
    axes``. In that frame the box around the region is ``|x_i| <= 1``: the solver's bounds."""
    normals = planes.normals[rows]
    return normals @ planes.axes.T, (planes.offsets[rows] - normals @ planes.middle) / planes.size


def _from_frame(planes: KernelPlanes, x: np.ndarray) -> np.ndarray:
    """World point of frame coordinates ``x`` (3,)."""
    return planes.middle + planes.size * (x[:3] @ planes.axes)


def _deepest(planes: KernelPlanes, rows: np.ndarray) -> tuple[np.ndarray, float]:
    """Centre and radius of the largest ball inside the planes ``rows`` and the box."""
    local, scaled = _in_frame(planes, rows)
    found = linprog(
        c=[0.0, 0.0, 0.0, -1.0],
        A_ub=np.column_stack([local, np.ones(len(rows))]),
        b_ub=scaled,
        bounds=[*_IN_THE_BOX, (None, 2.0)],
        method="highs",
        # Four unknowns and dense rows: presolve finds nothing to remove and costs as much
        # as the solve itself.
        options={"presolve": False},
    )
    if found.status != 0:
        return planes.middle.copy(), 0.0
    return _from_frame(planes, found.x), max(float(found.x[3]), 0.0) * planes.size


def _least_backfacing(planes: KernelPlanes, rows: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """The centre minimising ``sum(weights * max(0, n . c - offset))`` over the faces
    ``rows`` (in the box), plus ``_TIE_BREAK`` times its L1 distance from the middle in the
    region's frame: the sum alone is often least on a whole edge or facet, whose vertex the
    solver picks by rounding, so that the same surface turned could get another centre."""
    local, scaled = _in_frame(planes, rows)
    count = len(rows)
    # n . c - offset <= s_f: one slack per face, so sparse; |x_i| <= u_i.
    eye = sparse.identity(3, format="csr")
    a_ub = sparse.bmat(
        [
            [sparse.csr_matrix(local), -sparse.identity(count), None],
            [eye, None, -eye],
            [-eye, None, -eye],
        ]
    )
    found = linprog(
        c=np.concatenate([np.zeros(3), weights / weights.sum(), np.full(3, _TIE_BREAK)]),
        A_ub=a_ub.tocsr(),
        b_ub=np.concatenate([scaled, np.zeros(6)]),
        bounds=[*_IN_THE_BOX] + [(0.0, None)] * (count + 3),
        method="highs",
    )
    if found.status != 0:
        return planes.middle.copy()
    return _from_frame(planes, found.x)
