"""Untangling a layout: the vertices of flipped triangles, and as few neighbours as needed,
moved in 2D until every triangle has the map's orientation (docs/math.md, section 11).

The method is that of Garanzha, Kaporin, Kudryavtseva, Protais, Ray and Sokolov,
"Foldover-free maps in 50 lines of code" (ACM Trans. Graph. 40(4), SIGGRAPH 2021). Each
triangle's Jacobian ``J`` maps its 3D shape (laid flat in its own plane) to the layout; the
free vertices minimise the area-weighted sum of

    f_eps(J) = (1 - t) tr(J^T J) / chi(det J, eps) + t (det^2 J + 1) / chi(det J, eps),
    chi(D, eps) = (D + sqrt(eps^2 + D^2)) / 2,

a regularised shape-and-area energy that stays finite for flipped triangles while ``eps`` is
positive, with ``eps`` shrunk between minimisations (L-BFGS) by the paper's rule until every
triangle has a positive determinant. The free vertices are those of the flipped triangles and
the rings around them: one ring at first, more (2, 4, 8) only where that does not untangle.
Every other vertex keeps its coordinates to the bit. Orientations are decided exactly
(:func:`.predicates.orient3d_sign` on ``(x, y, 1)``), never with a tolerance; a triangle the
method leaves flipped or flat (where the region's own boundary folds over itself) is
reported.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize

from .checkpoints import checkpoint
from .predicates import orient3d_sign

#: Rings of neighbours a patch may take in, doubling each time: 1, 2, 4, 8.
RINGS = (1, 2, 4, 8)
#: Untangling is for folds, not for a map that is mostly wrong: beyond this share of the
#: triangles flipped it is not tried (the centre, not the layout, needs changing).
MAX_FLIPPED_SHARE = 0.1
#: The energy's area weight ``t`` (the paper's value) and its outer iterations.
_AREA_WEIGHT = 1.0 / 128.0
_OUTER = 20
#: eps never goes below this: at 0 a flipped triangle's energy would be infinite.
_SMALLEST_EPS = 1e-12


@dataclass(frozen=True)
class Untangled:
    """A layout after untangling.

    Attributes
    ----------
    x, y : (n,) float, the layout; exactly the input outside ``moved``
    moved : (k,) int, ascending positions of the vertices that moved
    largest_shift : float, the largest distance a vertex moved, in layout units
    flipped_before : (f,) int, positions of the triangles flipped (or flat) in the input
    flipped_after : (g,) int, those still flipped or flat
    note : str or None, why untangling was not tried (a closed region, or too many flips)
    """

    x: np.ndarray
    y: np.ndarray
    moved: np.ndarray
    largest_shift: float
    flipped_before: np.ndarray
    flipped_after: np.ndarray
    note: str | None = None


def orientation_signs(x: np.ndarray, y: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(m,) int8: the exact sign of each triangle's signed area in the ``(x, y)`` plane.

    Parameters
    ----------
    x, y : (n,) float
    faces : (m, 3) int
    """
    points = np.stack([x, y, np.ones_like(x)], axis=1)
    return orient3d_sign(points[faces[:, 0]], points[faces[:, 1]], points[faces[:, 2]])


def untangle(
    x: np.ndarray,
    y: np.ndarray,
    faces: np.ndarray,
    shapes: np.ndarray,
    orientation: int,
    fixed: np.ndarray | None = None,
) -> Untangled:
    """Move as few vertices as needed for every triangle to have ``orientation``.

    Parameters
    ----------
    x, y : (n,) float, the layout
    faces : (m, 3) int, its triangles
    shapes : (n, 3) float, the vertices in 3D (any frame): the triangles' own shapes
    orientation : +1 or -1, the sign of the signed area a correct triangle has
    fixed : (n,) bool or None, vertices that never move (default: none beyond those the
        patches leave out)

    Returns
    -------
    Untangled
    """
    x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    n = len(x)
    if fixed is None:
        fixed = np.zeros(n, dtype=bool)
    flipped = np.flatnonzero(orientation_signs(x, y, faces) != orientation)
    if flipped.size == 0:
        return Untangled(x, y, np.empty(0, np.int64), 0.0, flipped, flipped)
    note = _not_tried(faces, flipped.size)
    if note is not None:
        return Untangled(x, y, np.empty(0, np.int64), 0.0, flipped, flipped, note)
    # Work with positive determinants (mirror when the map's orientation is negative), and
    # with the layout scaled to the region's 3D area, which the energy's area term assumes.
    sign = 1.0 if orientation > 0 else -1.0
    inverse, areas = _reference_inverses(np.asarray(shapes, dtype=np.float64), faces)
    layout_area = 0.5 * np.abs(_dets(np.stack([sign * x, y], axis=1), faces)).sum()
    scale = math.sqrt(areas.sum() / layout_area) if layout_area > 0 else 1.0
    points = np.stack([sign * x, y], axis=1) * scale
    neighbours = _Rings(faces, n)
    remaining = flipped
    for rings in RINGS:
        near = neighbours.around(faces[remaining].ravel(), rings)
        free = near & ~fixed
        if not free.any():
            break
        active = np.flatnonzero(free[faces].any(axis=1))
        trial = _minimise(points, faces[active], inverse[active], areas[active], free)
        signs = orientation_signs(sign * trial[:, 0], trial[:, 1], faces)
        left = np.flatnonzero(signs != orientation)
        if left.size < remaining.size or left.size == 0:
            points, remaining = trial, left
        if remaining.size == 0:
            break
    start = np.stack([sign * x, y], axis=1) * scale
    unchanged = (points == start).all(axis=1)  # the others keep their coordinates to the bit
    new_x = np.where(unchanged, x, sign * points[:, 0] / scale)
    new_y = np.where(unchanged, y, points[:, 1] / scale)
    moved = np.flatnonzero(~unchanged)
    shift = float(np.hypot(new_x[moved] - x[moved], new_y[moved] - y[moved]).max(initial=0.0))
    after = np.flatnonzero(orientation_signs(new_x, new_y, faces) != orientation)
    return Untangled(new_x, new_y, moved, shift, flipped, after)


def _not_tried(faces: np.ndarray, flipped: int) -> str | None:
    """Why a layout is not worth untangling, or None."""
    if flipped > MAX_FLIPPED_SHARE * len(faces):
        return (
            f"{flipped:,} of {len(faces):,} triangles are flipped, more than "
            f"{MAX_FLIPPED_SHARE:.0%}: the centre sees too much of the region from behind for "
            'the layout to be repaired; choose another (center "auto", or /v1/fit)'
        )
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    if not (counts == 1).any():
        return "the region is closed (no boundary): its map cannot be made fold-free"
    return None


def _reference_inverses(shapes: np.ndarray, faces: np.ndarray):
    """Per triangle, the inverse of its 3D edge matrix laid flat in its own plane (2 x 2),
    and its 3D area."""
    p0, p1, p2 = (shapes[faces[:, k]] for k in range(3))
    e1, e2 = p1 - p0, p2 - p0
    length = np.linalg.norm(e1, axis=1)
    normal = np.cross(e1, e2)
    double_area = np.linalg.norm(normal, axis=1)
    ok = (length > 0) & (double_area > 0)
    safe_length = np.where(ok, length, 1.0)
    # Flat coordinates: e1 along the first axis, e2 = (e1 . e2 / |e1|, 2A / |e1|).
    a = np.where(ok, length, 1.0)
    b = np.where(ok, np.einsum("ij,ij->i", e1, e2) / safe_length, 0.0)
    c = np.where(ok, double_area / safe_length, 1.0)
    # [[a, b], [0, c]]^-1 = [[1/a, -b/(a c)], [0, 1/c]]
    inverse = np.zeros((len(faces), 2, 2))
    inverse[:, 0, 0] = 1.0 / a
    inverse[:, 0, 1] = -b / (a * c)
    inverse[:, 1, 1] = 1.0 / c
    areas = np.where(ok, 0.5 * double_area, 0.0)
    return inverse, areas


def _dets(points: np.ndarray, faces: np.ndarray) -> np.ndarray:
    d1 = points[faces[:, 1]] - points[faces[:, 0]]
    d2 = points[faces[:, 2]] - points[faces[:, 0]]
    return d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]


def _minimise(
    points: np.ndarray, faces: np.ndarray, inverse: np.ndarray, areas: np.ndarray, free
) -> np.ndarray:
    """The layout with the ``free`` vertices moved to minimise the regularised energy of
    the triangles ``faces``, worked on the patch's own vertices only (renumbered), so that
    each evaluation costs the patch, not the region."""
    used = np.unique(faces.ravel())
    result = points.copy()
    result[used] = _minimise_patch(
        points[used], np.searchsorted(used, faces), inverse, areas, free[used]
    )
    return result


def _minimise_patch(
    points: np.ndarray, faces: np.ndarray, inverse: np.ndarray, areas: np.ndarray, free
) -> np.ndarray:
    """As :func:`_minimise`, on a patch whose ``faces`` use every one of its ``points``
    (the paper's outer loop over ``eps``)."""
    ids = np.flatnonzero(free)
    result = points.copy()
    weights = areas / areas.sum() if areas.sum() > 0 else np.full(len(areas), 1.0 / len(areas))

    def jacobians(flat_free: np.ndarray) -> np.ndarray:
        result[ids] = flat_free.reshape(-1, 2)
        d1 = result[faces[:, 1]] - result[faces[:, 0]]
        d2 = result[faces[:, 2]] - result[faces[:, 0]]
        edges = np.stack([d1, d2], axis=2)  # (m, 2 coordinates, 2 edges)
        return edges @ inverse

    def energy(flat_free: np.ndarray, eps: float):
        jac = jacobians(flat_free)
        det = jac[:, 0, 0] * jac[:, 1, 1] - jac[:, 0, 1] * jac[:, 1, 0]
        root = np.sqrt(eps * eps + det * det)
        # chi = (det + root) / 2, written without cancellation where det < 0.
        below = det < 0.0
        gap = np.where(below, root - det, 1.0)  # > 0 where used
        chi = np.where(below, 0.5 * eps * eps / gap, 0.5 * (det + root))
        dchi = chi / root
        frob = (jac * jac).sum(axis=(1, 2))
        t = _AREA_WEIGHT
        f = ((1 - t) * frob + t * (det * det + 1.0)) / chi
        # d f / d J: the Frobenius term's 2 J, the determinant's cofactor matrix.
        cofactor = np.stack(
            [
                np.stack([jac[:, 1, 1], -jac[:, 1, 0]], 1),
                np.stack([-jac[:, 0, 1], jac[:, 0, 0]], 1),
            ],
            axis=1,
        )
        d_det = (t * 2.0 * det - f * dchi) / chi
        grad_jac = ((1 - t) * 2.0 / chi)[:, None, None] * jac + d_det[:, None, None] * cofactor
        grad_jac *= weights[:, None, None]
        grad_edges = grad_jac @ np.transpose(inverse, (0, 2, 1))  # (m, 2, 2 edges)
        g1, g2 = grad_edges[:, :, 0], grad_edges[:, :, 1]
        gradient = np.zeros((len(points), 2))
        for corner, g in ((0, -(g1 + g2)), (1, g1), (2, g2)):
            for k in (0, 1):
                gradient[:, k] += np.bincount(
                    faces[:, corner], weights=g[:, k], minlength=len(points)
                )
        return float((weights * f).sum()), gradient[ids].ravel()

    def smallest_det(flat_free: np.ndarray) -> float:
        jac = jacobians(flat_free)
        return float((jac[:, 0, 0] * jac[:, 1, 1] - jac[:, 0, 1] * jac[:, 1, 0]).min())

    current = points[ids].ravel()
    least = smallest_det(current)
    eps = max(1e-3, math.sqrt(1e-12 + 0.04 * min(least, 0.0) ** 2))
    previous = energy(current, eps)[0]
    for _ in range(_OUTER):
        found = minimize(
            energy, current, args=(eps,), jac=True, method="L-BFGS-B",
            options={"maxiter": 60, "gtol": 1e-7}, callback=lambda _: checkpoint(),
        )  # fmt: skip
        if not np.isfinite(found.x).all():
            break  # keep the last finite layout
        current = found.x
        value = energy(current, eps)[0]
        least = smallest_det(current)
        eps = _next_eps(eps, least, value, previous)
        if least > 0 and abs(previous - value) <= 1e-5 * abs(value):
            break
        previous = energy(current, eps)[0]  # the energy the next step starts from
    result[ids] = current.reshape(-1, 2)
    return result


def _next_eps(eps: float, least: float, value: float, previous: float) -> float:
    """The paper's rule for the next eps, from the smallest determinant ``least`` and the
    energy's relative decrease; chi(least, eps) evaluated without cancellation."""
    sigma = max(1.0 - value / previous, 0.1) if previous > 0 else 0.1
    root = math.sqrt(eps * eps + least * least)
    chi = 0.5 * eps * eps / (root - least) if least < 0 else 0.5 * (least + root)
    mu = (1.0 - sigma) * chi
    return max(2.0 * math.sqrt(mu * (mu - least)) if least < mu else 0.0, _SMALLEST_EPS)


class _Rings:
    """Vertex neighbourhoods of a triangulation: which vertices lie within k rings."""

    def __init__(self, faces: np.ndarray, n: int) -> None:
        edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
        both = np.concatenate([edges, edges[:, ::-1]])
        order = np.argsort(both[:, 0], kind="stable")
        self.ids = both[order, 1]
        self.start = np.searchsorted(both[order, 0], np.arange(n + 1))
        self.n = n

    def around(self, vertices: np.ndarray, rings: int) -> np.ndarray:
        """(n,) bool: ``vertices`` and those within ``rings`` edges of them."""
        inside = np.zeros(self.n, dtype=bool)
        inside[vertices] = True
        frontier = np.unique(vertices)
        for _ in range(rings):
            counts = self.start[frontier + 1] - self.start[frontier]
            offsets = np.repeat(self.start[frontier] - np.cumsum(counts) + counts, counts)
            reached = self.ids[offsets + np.arange(int(counts.sum()))]
            frontier = np.unique(reached[~inside[reached]])
            inside[frontier] = True
        return inside
