"""Per-face measurements of a region, in 3D and in the ``(phi, theta)`` layout, made in one
pass over cache-sized blocks of faces and shared by :mod:`.validation` and :mod:`.metrics`
(docs/math.md, sections 6 and 7).

Everything here is per face and elementwise, so the pass works block by block (whole blocks
vectorised): the temporaries of a block stay in cache and are reused, instead of some thirty
arrays of the region's size.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numba import njit

from .arrays import INDEX, as_angles, as_faces, as_points, unit_scale
from .cap import PoleCap
from .errors import TransformInputError
from .parallel import map_blocks
from .predicates import EPSILON, orient3d_sign_components

#: A triangle is degenerate when twice its area is at most this times the sum of its two
#: squared edges at corner 0 (a height below about 1e-12 of its edges), or when its layout
#: squashes it to that degree (the smaller stretch at most this times the larger).
DEGENERATE_RTOL = 1e-12

#: |fl(c0 . (e1 x e2)) - det[c0, c1, c2]| <= _ORIENT_BOUND * (|e1|^2 + |e2|^2) when every
#: coordinate is below 1 in magnitude: about 7 roundings on products bounded by
#: |c0|_1 |e1|_1 |e2|_1 <= 3 * 1.5 (|e1|^2 + |e2|^2); 64 leaves a margin over 31.5. The
#: absolute slack covers products that underflow.
_ORIENT_BOUND = 64.0 * EPSILON
_ORIENT_SLACK = 1e-290


@dataclass(frozen=True, eq=False)
class FaceMeasures:
    """What one pass over a region's faces measured. Arrays are ``(m,)``, one per face in
    the order of ``faces``.

    Attributes
    ----------
    faces : (m, 3) int, vertex indices
    vertices : (3, n) float, the vertices in the local frame scaled by ``scale``, as rows
    scale : float, a power of two taking the largest coordinate below 1, so no square or
        product overflows (coordinates below 2^-1022 of the largest would lose bits; the
        exact tests therefore read the unscaled coordinates)
    orientation : int8, exact sign of ``det[c0, c1, c2]`` with the centre at the origin: +1
        when the winding is counter-clockwise seen from outside
    double_area : float, ``|(c1 - c0) x (c2 - c0)|`` in scaled units
    layout_double_area : float, twice the signed area in the ``(phi, theta)`` plane
    degenerate : bool, zero area in 3D or in the layout (``DEGENERATE_RTOL``)
    crosses_seam : bool, the corners' ``phi`` span more than ``pi`` (the brief's seam test)
    contains_north, contains_south : bool, the ray from the centre through that singular
        point of ``cap`` meets the closed triangle (exactly)
    stretch_max, stretch_min : float, singular values ``s1 >= s2`` of the affine map from the
        triangle to its unscaled layout triangle (meaningless where degenerate)
    edge_bound : float, no 3D edge of any face is longer (scaled units; ``2 max |e1|, |e2|``)
    cap : PoleCap, the cap the singular points came from
    """

    faces: np.ndarray
    vertices: np.ndarray
    scale: float
    orientation: np.ndarray
    double_area: np.ndarray
    layout_double_area: np.ndarray
    degenerate: np.ndarray
    crosses_seam: np.ndarray
    contains_north: np.ndarray
    contains_south: np.ndarray
    stretch_max: np.ndarray
    stretch_min: np.ndarray
    edge_bound: float
    cap: PoleCap

    def __len__(self) -> int:
        return len(self.faces)

    def subset(self, keep: np.ndarray) -> FaceMeasures:
        """The measures of the faces ``keep`` (a (m,) bool mask or positions) alone: what a
        region of just those faces measures (its layout scale then comes from them)."""
        per_face = {
            name: getattr(self, name)[keep]
            for name in (
                "faces",
                "orientation",
                "double_area",
                "layout_double_area",
                "degenerate",
                "crosses_seam",
                "contains_north",
                "contains_south",
                "stretch_max",
                "stretch_min",
            )
        }
        return replace(self, **per_face)


def measure_faces(
    vertices_local, faces, theta, phi, cap: PoleCap, threads: int = 1, layout_theta=None
) -> FaceMeasures:
    """Measure every face of a region.

    Parameters
    ----------
    vertices_local : (n, 3) float, vertices in the local frame (centre at the origin)
    faces : (m, 3) int, indices into ``vertices_local``; at least one face
    theta, phi : (n,) float, the vertices' angles; ``(phi, theta)`` is the layout measured
    layout_theta : (n,) float or None, the layout's second coordinate instead of ``theta``
        (increasing with it; see :mod:`.layouts`)
    cap : PoleCap, the chart's cap (its singular points are tested)
    threads : int, threads to spread the blocks over

    Returns
    -------
    FaceMeasures

    Raises
    ------
    TransformInputError
        No faces, a face index out of range, or ``theta``/``phi`` of the wrong length.
    """
    vertices = as_points(vertices_local, "vertices")
    faces = as_faces(faces, len(vertices))
    if len(faces) == 0:
        raise TransformInputError("faces", "the region has no faces")
    theta, phi, _ = as_angles(theta, phi)
    if theta.shape != (len(vertices),):
        raise TransformInputError(
            "theta", f"theta and phi need one value per vertex ({len(vertices)}), got {theta.shape}"
        )
    if layout_theta is not None:  # the layout's second coordinate, in theta's place
        theta = np.ascontiguousarray(layout_theta, dtype=np.float64)
        if theta.shape != phi.shape or not np.isfinite(theta).all():
            raise TransformInputError("layout_theta", "must be finite, one value per vertex")
    return measure_checked(np.ascontiguousarray(vertices.T), faces, theta, phi, cap, threads)


def measure_checked(
    rows: np.ndarray,
    faces: np.ndarray,
    theta: np.ndarray,
    phi: np.ndarray,
    cap: PoleCap,
    threads: int = 1,
) -> FaceMeasures:
    """:func:`measure_faces` on input already checked: ``rows`` (3, n), the vertices in the
    local frame as C-contiguous finite float64 rows ``x, y, z``; ``faces`` (m >= 1, 3)
    C-contiguous indices in range; ``theta`` (the layout's second coordinate) and ``phi``
    (n,) finite float64. For callers that made them (:func:`.region.flatten_region`, the
    fit's energy), so that nothing is checked twice."""
    largest = float(np.abs(rows).max())
    scale = unit_scale(largest)
    unscaled_rows, rows = rows, rows * scale

    m = len(faces)
    out = {
        "orientation": np.empty(m, dtype=np.int8),
        "double_area": np.empty(m),
        "layout_double_area": np.empty(m),
        "degenerate": np.empty(m, dtype=bool),
        "crosses_seam": np.empty(m, dtype=bool),
        "contains_north": np.zeros(m, dtype=bool),
        "contains_south": np.zeros(m, dtype=bool),
        "stretch_max": np.empty(m),
        "stretch_min": np.empty(m),
    }
    # The one array layout the kernel is compiled for (no copy when it already is).
    phi, theta = np.ascontiguousarray(phi), np.ascontiguousarray(theta)
    sides = _sides_of_singular_lines(rows, cap, threads)
    recheck = np.empty(m, dtype=np.uint8)  # _UNSURE, _NEAR_NORTH, _NEAR_SOUTH bits
    faces = np.ascontiguousarray(faces, dtype=INDEX)  # the kernels' one index type

    def measure(block: slice) -> float:
        return _measure_block(
            rows,
            phi,
            theta,
            faces,
            sides,
            block.start,
            block.stop,
            out["orientation"],
            out["double_area"],
            out["layout_double_area"],
            out["degenerate"],
            out["crosses_seam"],
            out["stretch_max"],
            out["stretch_min"],
            recheck,
        )

    longest_legs = map_blocks(measure, m, threads)
    # Orientation seen from the centre, exact where the rounding bound left its sign in doubt.
    unsure = np.flatnonzero(recheck & _UNSURE)
    if unsure.size:
        (x0, x1, x2), (y0, y1, y2), (z0, z1, z2) = unscaled_rows[:, faces[unsure].T]
        out["orientation"][unsure] = orient3d_sign_components(x0, y0, z0, x1, y1, z1, x2, y2, z2)
    for point, bit, hit in (
        (cap.north, _NEAR_NORTH, out["contains_north"]),
        (cap.south, _NEAR_SOUTH, out["contains_south"]),
    ):
        near = np.flatnonzero(recheck & bit)
        if near.size:
            hit[near] = _contains_singular_point(
                unscaled_rows[:, faces[near].T], out["orientation"][near], point
            )
    # The third edge is at most the sum of the two at corner 0.
    edge_bound = 2.0 * math.sqrt(max(longest_legs))
    return FaceMeasures(
        faces=faces, vertices=rows, scale=scale, cap=cap, edge_bound=edge_bound, **out
    )


#: Bits of a face's recheck code from :func:`_measure_block`: its orientation's sign is in
#: doubt; it may hold the north, the south singular point (the exact tests decide).
_UNSURE, _NEAR_NORTH, _NEAR_SOUTH = np.uint8(1), np.uint8(2), np.uint8(4)


@njit(cache=True, nogil=True, error_model="numpy")
def _measure_block(
    rows,
    phi,
    second,
    faces,
    sides,
    first,
    last,
    orientation,
    double_area,
    layout_double_area,
    degenerate,
    crosses_seam,
    stretch_max,
    stretch_min,
    recheck,
) -> float:
    """Measure faces ``first:last`` into the per-face arrays (see :class:`FaceMeasures`);
    return the largest squared edge at corner 0. ``rows`` (3, n) are scaled, ``phi`` and
    ``second`` the layout, ``sides`` the vertices' codes (:func:`_sides_of_singular_lines`).
    ``recheck`` gets each face's bits for the exact tests left to numpy. One face at a time,
    every quantity in the order of operations the section's formulas give, so no (m,)
    temporary is made."""
    longest_leg = 0.0
    north_bits = _X_BITS | _NORTH_BITS | _AHEAD_NORTH_BIT
    south_bits = _X_BITS | _SOUTH_BITS | _AHEAD_SOUTH_BIT
    for f in range(first, last):
        i, j, k = faces[f, 0], faces[f, 1], faces[f, 2]
        x0, y0, z0 = rows[0, i], rows[1, i], rows[2, i]
        ax, ay, az = rows[0, j] - x0, rows[1, j] - y0, rows[2, j] - z0  # e1
        bx, by, bz = rows[0, k] - x0, rows[1, k] - y0, rows[2, k] - z0  # e2
        nx, ny, nz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
        area = math.sqrt(nx * nx + ny * ny + nz * nz)
        g11, g12, g22 = (
            ax * ax + ay * ay + az * az,
            ax * bx + ay * by + az * bz,
            bx * bx + by * by + bz * bz,
        )
        longest_leg = max(longest_leg, max(g11, g22))
        p0, p1, p2 = phi[i], phi[j], phi[k]
        f1u, f1v = p1 - p0, second[j] - second[i]
        f2u, f2v = p2 - p0, second[k] - second[i]
        layout_area = f1u * f2v - f1v * f2u
        # Orientation seen from the centre: c0 . (e1 x e2) = det[c0, c1, c2].
        det = x0 * nx + y0 * ny + z0 * nz
        orientation[f] = 1 if det > 0 else (-1 if det < 0 else 0)
        reference = g11 + g22
        code = _UNSURE if abs(det) <= _ORIENT_BOUND * reference + _ORIENT_SLACK else 0
        face_sides = sides[i] | sides[j] | sides[k]
        if face_sides & north_bits == north_bits:
            code |= _NEAR_NORTH
        if face_sides & south_bits == south_bits:
            code |= _NEAR_SOUTH
        recheck[f] = code
        double_area[f] = area
        layout_double_area[f] = layout_area
        crosses_seam[f] = max(max(p0, p1), p2) - min(min(p0, p1), p2) > math.pi
        # Singular values of the affine map from the triangle (in its own plane) to its
        # layout triangle. In the orthonormal basis (e1 / |e1|, its normal in the plane) the
        # 3D edges are columns [[p, q], [0, r]]; J = F [[p, q], [0, r]]^-1 with F the layout
        # edges. Then s1 = sqrt(E^2 + H^2) + sqrt(F^2 + G^2) from J's conformal and
        # anti-conformal parts, and s2 = |det J| / s1: sums of squares, accurate even for a
        # similarity (s1 = s2). Meaningless (inf or NaN) on degenerate faces, which the
        # metrics skip.
        p = math.sqrt(g11)
        shear = g12 / g11
        inverse_p = 1.0 / p
        inverse_r = p / area
        a, c = f1u * inverse_p, f1v * inverse_p
        b = (f2u - shear * f1u) * inverse_r
        d = (f2v - shear * f1v) * inverse_r
        s1 = (math.sqrt((a + d) * (a + d) + (c - b) * (c - b))
              + math.sqrt((a - d) * (a - d) + (c + b) * (c + b))) * 0.5  # fmt: skip
        s2 = abs(layout_area) / area / s1
        stretch_max[f], stretch_min[f] = s1, s2
        # Degenerate in 3D, or squashed flat in the layout (also NaN from a degenerate 3D
        # triangle).
        degenerate[f] = area <= DEGENERATE_RTOL * reference or not s2 > DEGENERATE_RTOL * s1
    return longest_leg


#: Bits of a vertex's side code: for the plane x = 0 and, for each singular point s, the
#: plane through the centre holding s and the x axis, whether the vertex is on the
#: non-negative and on the non-positive side (both when within _SIDE_SLACK of the plane).
_X_BITS = 0b00000011
_NORTH_BITS = 0b00001100
_SOUTH_BITS = 0b00110000
#: Whether the vertex is not behind the plane through the centre orthogonal to the north
#: (south) singular point: a triangle with every corner behind it cannot meet the ray.
_AHEAD_NORTH_BIT = 0b01000000
_AHEAD_SOUTH_BIT = 0b10000000
#: Far above the rounding of a plane distance (~1e-15 for coordinates below 1).
_SIDE_SLACK = 1e-13


def _sides_of_singular_lines(rows: np.ndarray, cap: PoleCap, threads: int = 1) -> np.ndarray:
    """(n,) uint8: each vertex's side code (see ``_X_BITS``) for the two planes through each
    singular line (the line through the centre and a singular point).

    Both singular points ``(0, cos rho, +-sin rho)`` lie in the plane ``x = 0``; the second
    plane for each has normal ``x_axis x s = (0, -+sin rho, cos rho)``. A triangle all on one
    side of a plane through a line cannot meet that line, and one with every corner behind
    the centre (``s . v < 0``) cannot meet the ray, so only faces whose corners' codes cover
    both sides of both planes and have a corner ahead need the exact test.
    """
    _, cos_rho, sin_rho = cap.north
    codes = np.empty(rows.shape[1], dtype=np.uint8)

    def code(block: slice) -> None:
        x, y, z = rows[:, block]
        out = codes[block]
        out[:] = 0
        bit = np.empty(x.shape, dtype=bool)
        for distance, bits in (
            (x, _X_BITS),
            (cos_rho * z - sin_rho * y, _NORTH_BITS),
            (cos_rho * z + sin_rho * y, _SOUTH_BITS),
        ):
            low_bit = np.uint8(bits & -bits)
            np.greater_equal(distance, -_SIDE_SLACK, out=bit)
            out |= bit.view(np.uint8) * low_bit
            np.less_equal(distance, _SIDE_SLACK, out=bit)
            out |= bit.view(np.uint8) * (low_bit << np.uint8(1))
        for along, ahead_bit in (
            (cos_rho * y + sin_rho * z, _AHEAD_NORTH_BIT),
            (cos_rho * y - sin_rho * z, _AHEAD_SOUTH_BIT),
        ):
            np.greater_equal(along, -_SIDE_SLACK, out=bit)
            out |= bit.view(np.uint8) * np.uint8(ahead_bit)

    map_blocks(code, len(codes), threads)
    return codes


def edge_signs(corners: np.ndarray, direction) -> np.ndarray:
    """(3, k) int: exact ``sign(det[s, c_i, c_j])`` over each triangle's edges ``(0, 1), (1, 2),
    (2, 0)``, ``s`` the ray ``direction`` ((3,) float) from the centre and ``corners`` (3, 3,
    k) ``[axis, corner, face]``: which side of each edge's plane through the centre the ray
    passes (:func:`.predicates.orient3d_sign_components`)."""
    sx, sy, sz = direction
    cx, cy, cz = corners
    return np.stack(
        [
            orient3d_sign_components(sx, sy, sz, cx[i], cy[i], cz[i], cx[j], cy[j], cz[j])
            for i, j in ((0, 1), (1, 2), (2, 0))
        ]
    )


def _contains_singular_point(corners: np.ndarray, orientation: np.ndarray, point) -> np.ndarray:
    """(k,) bool: whether the ray from the centre through the singular ``point`` meets each
    closed triangle (docs/math.md, section 6: "holds a singular point").

    Asked only of faces whose corners lie on both sides of both planes through the singular
    line and not all behind the centre as seen along the ray (see
    :func:`_sides_of_singular_lines`). With ``e_ij = det[s, c_i, c_j]`` over the three edges
    and ``d = det[c0, c1, c2]`` (``orientation``), all exact, the ray along ``s`` hits when
    all ``e_ij >= 0`` and ``d > 0``, or all ``e_ij <= 0`` and ``d < 0`` (their sum is
    ``s . n``; the hit is at ``t = d / (s . n) > 0``). When ``d = 0`` the plane of the
    triangle holds the centre, and the ray can only meet it inside that plane:
    :func:`_ray_in_plane_hits`.

    Parameters
    ----------
    corners : (3, 3, k) float, ``[axis, corner, face]``, unscaled
    orientation : (k,) int8, exact
    point : (3,) float, the singular point
    """
    signs = edge_signs(corners, point)
    all_nonnegative = (signs[0] >= 0) & (signs[1] >= 0) & (signs[2] >= 0)
    all_nonpositive = (signs[0] <= 0) & (signs[1] <= 0) & (signs[2] <= 0)
    hit = (all_nonnegative & (orientation > 0)) | (all_nonpositive & (orientation < 0))
    in_plane = np.flatnonzero(all_nonnegative & all_nonpositive & (orientation == 0))
    if in_plane.size:
        planar = corners[:, :, in_plane]
        e1, e2 = planar[:, 1] - planar[:, 0], planar[:, 2] - planar[:, 0]
        normal = np.stack([e1[(i + 1) % 3] * e2[(i + 2) % 3] - e1[(i + 2) % 3] * e2[(i + 1) % 3]
                           for i in range(3)])  # fmt: skip
        hit[in_plane] = _ray_in_plane_hits(planar, normal, point)
    return hit


def _ray_in_plane_hits(corners: np.ndarray, normal: np.ndarray, direction: np.ndarray):
    """Exact ray test when the triangle, the centre and ``direction`` share a plane.

    Dropping the coordinate along which the plane's normal is largest projects the plane to
    2D without loss (the projection only drops a number). With ``w_i = s x c_i`` the side of
    corner ``i`` of the line along ``s``, the ray meets the closed triangle where a corner lies
    on the ray (``w_i = 0``, ``c_i . s > 0``) or where an edge crosses the line
    (``w_i w_j < 0``) ahead of the centre, which is when ``c_i x c_j`` has the sign of ``w_j``.
    All signs are exact (:func:`.predicates.orient3d_sign_components` with a third coordinate
    of 1 computes 2D cross products).

    Parameters
    ----------
    corners : (3, 3, k) float, ``[axis, corner, face]``, unscaled
    normal : (3, k) float, the faces' normals (only their largest axis is used)
    direction : (3,) float

    Returns
    -------
    (k,) bool
    """
    drop = np.argmax(np.abs(normal), axis=0)
    kept = np.array([[1, 2], [0, 2], [0, 1]])[drop]  # the two coordinates left, per face
    k = corners.shape[2]
    faces = np.arange(k)
    u = corners[kept[:, 0], :, faces].T  # (corner, face)
    v = corners[kept[:, 1], :, faces].T
    su, sv = direction[kept[:, 0]], direction[kept[:, 1]]
    zero, one = np.zeros(k), np.ones(k)

    def cross(pu, pv, qu, qv):
        return orient3d_sign_components(zero, zero, one, pu, pv, one, qu, qv, one)

    side = [cross(su, sv, u[i], v[i]) for i in range(3)]
    ahead = [cross(u[i], v[i], -sv, su) for i in range(3)]  # sign of c_i . s
    hits = np.zeros(k, dtype=bool)
    for i, j in ((0, 1), (1, 2), (2, 0)):
        hits |= (side[i] == 0) & (ahead[i] > 0)
        crossing = side[i] * side[j] < 0
        hits |= crossing & (cross(u[i], v[i], u[j], v[j]) == side[j])
    return hits
