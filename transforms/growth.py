"""The direction hair grows: a field drawn on the map, smooth between flow curves, turning
once round each whorl, and pushed forward onto the surface (docs/math.md, section 19).

The field is solved on the map, where the paper's application makes a hair's assets by image
processing: the map is seam-free, so one flat grid holds the whole field with no seam to cut
it. A map direction is a unit complex number ``d``. The whorls' part is factored out,

    d(z) = u(z) prod_k s_k (z - w_k) / |z - w_k|                                   (19.1)

with ``w_k`` a whorl's map point and ``s_k = exp(i turn_k SPIRAL)`` its spiral; ``u`` is
then smooth, and is the harmonic interpolation, on a grid over the map's box, of the flow
curves' directions (divided by the whorls' part) and of 1 at each whorl (so that the spiral
about it is the one asked for). ``d`` is ``u`` times the whorls' part, normalised. On the
triangles a flow curve crosses, the map direction is the curve's own (its pieces' directions
in the triangle, weighed by length): there the field is the lifted curve's tangent exactly.

A map direction ``d`` in a triangle is pushed forward by the triangle's linear map from the
map to the surface, ``J = E3 E2^-1`` (its edges on the surface and on the map), to the
tangent ``J d``; at a site it is made orthogonal to the site's normal and unit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix, diags
from scipy.sparse.linalg import splu

from .arrays import solve_2x2
from .checkpoints import checkpoint
from .mapping import MapTriangles
from .zones import Polyline

#: Grid cells along the longer side of the map's box: the field's resolution (it varies over
#: tens of cells; a site takes it bilinearly).
GRID_CELLS = 256
#: The angle between the hair and the ray out of a whorl, radians: a spiral, turning as the
#: whorl's ``turn`` says (as seen on the map).
SPIRAL = np.radians(45.0)
#: A map direction whose interpolated strength falls below this (|u|, 1 on a flow curve) is
#: between flows that point against each other.
WEAK = 0.1
#: Directions that meet in a triangle or a grid cell and whose mean is shorter than this share
#: of their count point against each other.
AGREE = 0.5


class FlowsDisagree(ValueError):
    """Two flow curves (``first``, ``second``; equal for one curve against itself) point
    against each other near the map point ``where``."""

    def __init__(self, first: int, second: int, where: np.ndarray) -> None:
        self.first, self.second, self.where = first, second, np.asarray(where, dtype=np.float64)
        super().__init__(f"flows {first} and {second} point against each other")


@dataclass(frozen=True)
class GrowthField:
    """A growth field on a region's map (eq. 19.1).

    Attributes
    ----------
    low : (2,) float, the map point of the grid's first cell centre
    step : float, the grid's cell side, map units
    smooth : (h, w) complex, ``u`` at the cell centres
    whorls : (k, 2) float, the whorls' map points
    spins : (k,) complex, unit: each whorl's ``s_k``
    on_faces : (m,) complex, the flow curves' own direction on the triangles they cross (0
        on the others)
    """

    low: np.ndarray
    step: float
    smooth: np.ndarray
    whorls: np.ndarray
    spins: np.ndarray
    on_faces: np.ndarray

    def whorl_part(self, points: np.ndarray) -> np.ndarray:
        """(p,) complex, unit: ``prod_k s_k (z - w_k) / |z - w_k|`` at map ``points`` ((p, 2));
        1 at a whorl itself (no direction there)."""
        z = points[:, 0] + 1j * points[:, 1]
        part = np.ones(len(z), dtype=complex)
        for whorl, spin in zip(self.whorls, self.spins, strict=True):  # a few whorls
            ray = z - (whorl[0] + 1j * whorl[1])
            size = np.abs(ray)
            part *= np.where(size > 0, spin * ray / np.where(size > 0, size, 1.0), 1.0)
        return part

    def strength(self, points: np.ndarray) -> np.ndarray:
        """(p,) float: ``|u|`` at map ``points`` ((p, 2)), bilinearly (1 on a flow)."""
        return np.abs(self._smooth_at(points))

    def map_directions(self, points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
        """(p, 2) float, unit: the field at map ``points`` ((p, 2)) in ``triangles`` ((p,)
        int, positions in the region's faces): a flow curve's own direction on its
        triangles, else eq. 19.1 (``u`` bilinearly)."""
        value = self._smooth_at(points) * self.whorl_part(points)
        own = self.on_faces[triangles]
        value = np.where(own != 0, own, value)
        size = np.abs(value)
        value = np.where(size > 0, value / np.where(size > 0, size, 1.0), 1.0)
        return np.column_stack([value.real, value.imag])

    def _smooth_at(self, points: np.ndarray) -> np.ndarray:
        h, w = self.smooth.shape
        at = (points - self.low) / self.step
        col = np.clip(at[:, 0], 0.0, w - 1.0)
        row = np.clip(at[:, 1], 0.0, h - 1.0)
        c0 = np.minimum(col.astype(np.int64), w - 2) if w > 1 else np.zeros(len(col), np.int64)
        r0 = np.minimum(row.astype(np.int64), h - 2) if h > 1 else np.zeros(len(row), np.int64)
        fc, fr = col - c0, row - r0
        c1, r1 = np.minimum(c0 + 1, w - 1), np.minimum(r0 + 1, h - 1)
        grid = self.smooth
        return ((1 - fr) * ((1 - fc) * grid[r0, c0] + fc * grid[r0, c1])
                + fr * ((1 - fc) * grid[r1, c0] + fc * grid[r1, c1]))  # fmt: skip


def growth_field(
    triangles: MapTriangles,
    flows: list[Polyline],
    whorls: np.ndarray,
    turns: np.ndarray,
    cells: int = GRID_CELLS,
) -> GrowthField:
    """The field of the lifted ``flows`` and the ``whorls`` on the map of ``triangles``
    (eq. 19.1).

    Parameters
    ----------
    triangles : MapTriangles, the region's
    flows : list of Polyline, the flow curves lifted (:func:`transforms.zones.lift_curve`),
        each running the way the hair grows; their pieces off the region are left out
    whorls : (k, 2) float, map points
    turns : (k,) int, +1 for a whorl turning counter-clockwise on the map, -1 clockwise
    cells : int, the grid's cells along the longer side of the map's box

    Raises
    ------
    FlowsDisagree
        Two flows (or one against itself) point against each other in a triangle or a grid
        cell, or their interpolation fades between them (``WEAK``).
    """
    whorls = np.asarray(whorls, dtype=np.float64).reshape(-1, 2)
    spins = np.exp(1j * SPIRAL * np.asarray(turns, dtype=np.float64).reshape(-1))
    low_box, high_box = triangles.map_points.min(axis=0), triangles.map_points.max(axis=0)
    step = float(max(high_box - low_box)) / (cells - 3)
    if not step > 0:
        step = 1.0
    low = low_box - step
    shape = tuple(int(n) for n in np.ceil((high_box + step - low) / step).astype(np.int64) + 1)
    w, h = shape
    bare = GrowthField(low, step, np.ones((h, w), dtype=complex), whorls, spins,
                       np.zeros(len(triangles), dtype=complex))  # fmt: skip
    pieces = _pieces(flows)
    if pieces is None:
        return bare
    on_faces = _on_faces(len(triangles), pieces)
    checkpoint()
    cells_fixed, values = _fixed_cells(bare, pieces, (h, w))
    smooth = _harmonic((h, w), cells_fixed, values)
    field = GrowthField(low, step, smooth, whorls, spins, on_faces)
    _check_strength(field, triangles, pieces)
    return field


@dataclass(frozen=True)
class _Pieces:
    """The flows' pieces on the region: start and end map points ((q, 2) each), triangle
    ((q,) int), flow ((q,) int) and unit map direction ((q,) complex)."""

    start: np.ndarray
    end: np.ndarray
    triangle: np.ndarray
    flow: np.ndarray
    direction: np.ndarray


def _pieces(flows: list[Polyline]) -> _Pieces | None:
    starts, ends, faces, owners = [], [], [], []
    for k, line in enumerate(flows):  # a few flows, each vectorised
        on = line.faces >= 0
        starts.append(line.map_points[:-1][on])
        ends.append(line.map_points[1:][on])
        faces.append(line.faces[on])
        owners.append(np.full(int(on.sum()), k))
    if not flows or sum(len(f) for f in faces) == 0:
        return None
    start, end = np.concatenate(starts), np.concatenate(ends)
    step = (end[:, 0] - start[:, 0]) + 1j * (end[:, 1] - start[:, 1])
    length = np.abs(step)
    keep = length > 0
    return _Pieces(start[keep], end[keep], np.concatenate(faces)[keep],
                   np.concatenate(owners)[keep], step[keep] / length[keep])  # fmt: skip


def _on_faces(m: int, pieces: _Pieces) -> np.ndarray:
    """(m,) complex: the length-weighed mean direction of the pieces on each triangle, unit
    (0 on triangles no piece crosses)."""
    length = np.hypot(*(pieces.end - pieces.start).T)
    total = np.bincount(pieces.triangle, length, m)
    summed = np.bincount(pieces.triangle, length * pieces.direction.real, m) + 1j * np.bincount(
        pieces.triangle, length * pieces.direction.imag, m
    )
    crossed = total > 0
    weak = np.flatnonzero(crossed & (np.abs(summed) < AGREE * total))
    if len(weak):
        on = pieces.triangle == weak[0]
        met = np.unique(pieces.flow[on])
        raise FlowsDisagree(int(met[0]), int(met[-1]), pieces.start[on][0])
    out = np.zeros(m, dtype=complex)
    out[crossed] = summed[crossed] / np.abs(summed[crossed])
    return out


def _fixed_cells(field: GrowthField, pieces: _Pieces, shape) -> tuple[np.ndarray, np.ndarray]:
    """The grid cells the flows pass through (and each whorl's), and ``u`` there: the mean of
    the flows' directions in the cell divided by the whorls' part at its centre (1 at a
    whorl)."""
    h, w = shape
    length = np.hypot(*(pieces.end - pieces.start).T)
    samples = np.maximum(1, np.ceil(2.0 * length / field.step).astype(np.int64))
    owner = np.repeat(np.arange(len(samples)), samples)
    offset = np.arange(len(owner)) - np.repeat(np.cumsum(samples) - samples, samples)
    t = (offset + 0.5) / samples[owner]
    points = pieces.start[owner] + t[:, None] * (pieces.end - pieces.start)[owner]
    cell = _cell_of(field, points, shape)
    summed = np.bincount(cell, pieces.direction.real[owner], h * w) + 1j * np.bincount(
        cell, pieces.direction.imag[owner], h * w
    )
    count = np.bincount(cell, minlength=h * w)
    fixed = np.flatnonzero(count)
    weak = fixed[np.abs(summed[fixed]) < AGREE * count[fixed]]
    if len(weak):
        met = np.unique(pieces.flow[owner[cell == weak[0]]])
        raise FlowsDisagree(int(met[0]), int(met[-1]), _centres(field, weak[:1], w)[0])
    centres = _centres(field, fixed, w)
    values = summed[fixed] / np.abs(summed[fixed]) / field.whorl_part(centres)
    if len(field.whorls):
        at_whorls = _cell_of(field, field.whorls, shape)
        fixed = np.concatenate([fixed, at_whorls])
        values = np.concatenate([values, np.ones(len(at_whorls), dtype=complex)])
        fixed, first = np.unique(fixed[::-1], return_index=True)  # a whorl's 1 wins
        values = values[::-1][first]
    return fixed, values


def _cell_of(field: GrowthField, points: np.ndarray, shape) -> np.ndarray:
    h, w = shape
    at = np.rint((points - field.low) / field.step).astype(np.int64)
    return np.clip(at[:, 1], 0, h - 1) * w + np.clip(at[:, 0], 0, w - 1)


def _centres(field: GrowthField, cells: np.ndarray, w: int) -> np.ndarray:
    return field.low + field.step * np.column_stack([cells % w, cells // w])


def _harmonic(shape, fixed: np.ndarray, values: np.ndarray) -> np.ndarray:
    """(h, w) complex: the grid's harmonic interpolation of ``values`` at the cells
    ``fixed`` (the 4-neighbour graph Laplacian, natural at the grid's border)."""
    h, w = shape
    n = h * w
    index = np.arange(n).reshape(h, w)
    pairs = np.concatenate([
        np.column_stack([index[:, :-1].ravel(), index[:, 1:].ravel()]),
        np.column_stack([index[:-1, :].ravel(), index[1:, :].ravel()]),
    ])  # fmt: skip
    adjacency = coo_matrix(
        (
            np.ones(2 * len(pairs)),
            (np.r_[pairs[:, 0], pairs[:, 1]], np.r_[pairs[:, 1], pairs[:, 0]]),
        ),
        shape=(n, n),
    ).tocsr()
    laplacian = diags(np.asarray(adjacency.sum(axis=1)).ravel()) - adjacency
    free = np.ones(n, dtype=bool)
    free[fixed] = False
    out = np.empty(n, dtype=complex)
    out[fixed] = values
    if free.any():
        system = laplacian[free][:, free].tocsc()
        right = -(laplacian[free][:, fixed] @ values)
        checkpoint()
        solved = splu(system).solve(np.column_stack([right.real, right.imag]))
        out[free] = solved[:, 0] + 1j * solved[:, 1]
    return out.reshape(h, w)


def _check_strength(field: GrowthField, triangles: MapTriangles, pieces: _Pieces) -> None:
    """Refuse a field whose ``|u|`` falls below ``WEAK`` at a triangle's centroid on the map:
    flows there point against each other, or against a whorl; named by the flow nearest
    the place and the nearest other one."""
    centroids = np.column_stack([triangles.corner_x.mean(axis=0), triangles.corner_y.mean(axis=0)])
    strength = field.strength(centroids)
    weakest = int(np.argmin(strength)) if len(strength) else 0
    if not len(strength) or strength[weakest] >= WEAK:
        return
    where = centroids[weakest]
    middle = 0.5 * (pieces.start + pieces.end)
    distance = np.hypot(*(middle - where).T)
    first = int(pieces.flow[np.argmin(distance)])
    others = pieces.flow != first
    second = int(pieces.flow[others][np.argmin(distance[others])]) if others.any() else first
    raise FlowsDisagree(min(first, second), max(first, second), where)


def triangle_edges(triangles: MapTriangles, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``E2`` (p, 2, 2) and ``E3`` (p, 3, 2): the edges from the first corner of ``faces``
    ((p,) int) on the map and on the surface, as columns (the linear map ``J = E3 E2^-1``)."""
    corners = triangles.faces[faces]
    on_map, on_surface = triangles.map_points[corners], triangles.surface_points[corners]
    e2 = np.stack([on_map[:, 1] - on_map[:, 0], on_map[:, 2] - on_map[:, 0]], axis=2)
    e3 = np.stack(
        [on_surface[:, 1] - on_surface[:, 0], on_surface[:, 2] - on_surface[:, 0]], axis=2
    )
    return e2, e3


def pushed_forward(
    triangles: MapTriangles, faces: np.ndarray, directions: np.ndarray, normals: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Map ``directions`` ((p, 2), unit) in ``faces`` ((p,) int, positions in the region's
    faces) as surface tangents at points whose unit ``normals`` are given ((p, 3)).

    Each is pushed forward by its triangle's linear map ``J = E3 E2^-1`` (section 19), made
    orthogonal to the normal and unit; a triangle of no area on the map (whose map has no
    direction) takes the pseudo-inverse of ``E2``, and a tangent that vanishes there, its
    first edge's.

    Returns
    -------
    tangent : (p, 3) float, unit, orthogonal to the normal
    map_direction : (p, 2) float, unit: the tangent's direction on the map (``E2 E3^+``)
    """
    e2, e3 = triangle_edges(triangles, faces)
    along = solve_2x2(e2, directions)
    tangent = np.einsum("pij,pj->pi", e3, along)
    tangent -= np.einsum("pi,pi->p", tangent, normals)[:, None] * normals
    size = np.linalg.norm(tangent, axis=1)
    lost = ~(size > 1e-300)
    if lost.any():  # a tangent the map cannot give: the triangle's first edge, in plane
        edge = e3[lost, :, 0]
        tangent[lost] = edge - np.einsum("pi,pi->p", edge, normals[lost])[:, None] * normals[lost]
        size[lost] = np.linalg.norm(tangent[lost], axis=1)
    tangent /= np.where(size > 0, size, 1.0)[:, None]
    # E3^+ t = (E3^T E3)^-1 E3^T t: the normal equations of a 3 x 2 system.
    gram = np.einsum("pki,pkj->pij", e3, e3)
    on_map = np.einsum("pij,pj->pi", e2, solve_2x2(gram, np.einsum("pki,pk->pi", e3, tangent)))
    length = np.linalg.norm(on_map, axis=1)
    on_map /= np.where(length > 0, length, 1.0)[:, None]
    return tangent, on_map
