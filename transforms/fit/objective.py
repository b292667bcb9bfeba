"""The fit's objective (docs/math.md, section 9) for many candidates at once.

A candidate is a centre, a rotation and sigma: a few numbers. It changes a face only through
its corners' layout coordinates; the face's shape in 3D (its edges in its own plane, its
area, its plane) stays as it is. So the 3D part is measured once per face, and a batch of
``k`` candidates is evaluated as ``(k, n)`` arrays: the corners' local directions, their
angles, then per face the Jacobian of the affine map from the triangle to its layout
triangle (section 7) and the side its plane turns to the centre (section 6).

Only what the objective reads is computed: the isometric energy needs ``s1^2 + s2^2`` (the
Jacobian's squared Frobenius norm) and ``s1 s2`` (its determinant), not the singular values
themselves, and no percentile. With the layout scaled by ``k`` (the factor that gives it the
region's 3D area, ``k^2 = sum A / sum |L|``) a face's energy is
``(k^2 F + F / (k^2 D^2)) / 4`` for ``F = s1^2 + s2^2`` and ``D = s1 s2``, so the area-weighted
mean is ``(k^2 sum wF + sum wF/D^2 / k^2) / (4 sum w)``: one pass of sums, whatever ``k``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..arrays import unit_scale
from ..chart import Method
from ..faces import DEGENERATE_RTOL
from ..layouts import MERCATOR_THETA_MARGIN, Layout, measured_second
from ..separable import separable_angles
from ..spherical import MIN_RADIUS, angles, half_open_azimuth
from ..warp import plus_minus
from . import fused

#: What a candidate pays for each unit of the fraction of the area it sees from behind
#: (1% costs 10, more than any energy difference the faces seen from the front make).
BACKFACING_WEIGHT = 1000.0
#: Elements of one (candidates, faces) array: a batch is cut into chunks of about this size,
#: so its temporaries stay a few MB whatever the batch.
_CHUNK_ELEMENTS = 1 << 17


@dataclass(frozen=True)
class Candidates:
    """Centres, rotations and sigmas of ``k`` candidates.

    Attributes
    ----------
    centers : (k, 3) float, world coordinates
    rotations : (k, 3, 3) float, world-to-local (rows: local X, Y = the pole, Z)
    sigmas : (k,) float, the warp's sigma (ignored by the standard method)
    """

    centers: np.ndarray
    rotations: np.ndarray
    sigmas: np.ndarray

    @classmethod
    def of(cls, centers, rotations, sigmas) -> Candidates:
        """Candidates from arrays that broadcast to ``k`` rows (a single centre, rotation or
        sigma is repeated)."""
        centers = np.atleast_2d(np.asarray(centers, dtype=np.float64))
        rotations = np.asarray(rotations, dtype=np.float64)
        if rotations.ndim == 2:
            rotations = rotations[None]
        sigmas = np.atleast_1d(np.asarray(sigmas, dtype=np.float64))
        k = max(len(centers), len(rotations), len(sigmas))
        return cls(
            np.broadcast_to(centers, (k, 3)),
            np.broadcast_to(rotations, (k, 3, 3)),
            np.broadcast_to(sigmas, (k,)),
        )

    def __len__(self) -> int:
        return len(self.sigmas)

    def __getitem__(self, rows) -> Candidates:
        return Candidates(self.centers[rows], self.rotations[rows], self.sigmas[rows])


@dataclass(frozen=True)
class Scores:
    """What a batch of candidates measures. Arrays are ``(k,)``.

    Attributes
    ----------
    objective : float, ``J = BACKFACING_WEIGHT * hidden + energy`` (inf where it cannot be
        measured: a vertex at the centre, or no face left to measure)
    energy : float, the area-weighted isometric energy of the faces measured (those seen
        from the front, or all, see :meth:`FaceEnergy.scores`)
    hidden : float, the fraction of the area seen from behind
    cap_cosine : float, the largest cosine between the pole and the direction to a vertex:
        the cap around the pole that holds none of them has the angular radius ``acos``
    """

    objective: np.ndarray
    energy: np.ndarray
    hidden: np.ndarray
    cap_cosine: np.ndarray


@dataclass(frozen=True)
class Motion:
    """How a candidate moves with ``d`` coordinates: the derivatives of its rotation, its
    centre (world units) and its log sigma with respect to each.

    Attributes
    ----------
    rotation : (d, 3, 3) float
    center : (d, 3) float
    log_sigma : (d,) float
    """

    rotation: np.ndarray
    center: np.ndarray
    log_sigma: np.ndarray


@dataclass(frozen=True)
class Slope:
    """One candidate's scores and how they change as it moves (:class:`Motion`).

    Attributes
    ----------
    scores : Scores, of the one candidate
    energy : (d,) float, the gradient of ``scores.energy`` (the faces seen from behind are
        held fixed: the count of area behind changes only in steps)
    cap_cosine : (d,) float, the gradient of ``scores.cap_cosine``
    """

    scores: Scores
    energy: np.ndarray
    cap_cosine: np.ndarray


class FaceEnergy:
    """A set of faces, measured once in 3D, scored for many candidates at once.

    Parameters
    ----------
    points : (n, 3) float, world coordinates of the vertices the faces use (only those)
    faces : (m, 3) int, indices into ``points``
    method : the chart's method
    layout : the layout whose energy is measured (:mod:`transforms.layouts`)
    """

    def __init__(self, points: np.ndarray, faces: np.ndarray, method: Method, layout: Layout):
        self.method, self.layout = Method(method), Layout(layout)
        self.scale = _unit_scale(points)
        self.points = points * self.scale
        self.shapes = _FaceShapes(self.points, faces)

    def __len__(self) -> int:
        return len(self.shapes)

    def scores(self, candidates: Candidates, split_backfacing: bool = True) -> Scores:
        """Score every candidate.

        Parameters
        ----------
        candidates : Candidates, ``k`` of them
        split_backfacing : True for the objective of docs/math.md section 9 (the faces seen
            from behind counted by area, the rest measured alone); False for the plain energy
            of every face (section 7), with ``hidden`` 0

        Returns
        -------
        Scores
        """
        chunk = self._chunk if self.method is Method.SEPARABLE else self._fused
        per_chunk = max(1, _CHUNK_ELEMENTS // max(len(self), len(self.points), 1))
        parts = [
            chunk(candidates[start : start + per_chunk], split_backfacing)
            for start in range(0, len(candidates), per_chunk)
        ]
        return Scores(*(np.concatenate(column) for column in zip(*parts, strict=True)))

    def _fused(self, candidates: Candidates, split: bool) -> tuple[np.ndarray, ...]:
        """:meth:`_chunk` in compiled loops (:mod:`.fused`) round numpy's vectorised
        ``atan2``."""
        shapes = self.shapes
        centers = np.ascontiguousarray(candidates.centers * self.scale)
        across, height, second, first, at_centre, cap_cosine = fused.warp_batch(
            self.points,
            centers,
            np.ascontiguousarray(candidates.rotations),
            np.ascontiguousarray(candidates.sigmas),
            self.method is Method.DISTORTED,
        )
        theta = np.arctan2(across, height, out=height)
        phi = half_open_azimuth(np.arctan2(second, first, out=second))
        sums = fused.sums_batch(
            *shapes.arrays,
            centers,
            split,
            phi,
            measured_second(theta, self.layout),
        )
        return (*_objective(tuple(sums), at_centre), cap_cosine)

    def _chunk(self, candidates: Candidates, split: bool) -> tuple[np.ndarray, ...]:
        centers = candidates.centers * self.scale
        angles_ = _Angles.of(self.points, centers, candidates, self.method, self.layout)
        sums = self.shapes.sums(angles_.plane, centers if split else None)
        return (*_objective(sums, angles_.at_centre), angles_.cap_cosine)

    def slope(self, candidate: Candidates, motion: Motion) -> Slope:
        """The objective of one candidate (``split_backfacing``) and its gradients along
        ``motion``: reverse over the faces to each vertex's layout point, forward from the
        coordinates to the vertices' angles through the closed-form warp (docs/math.md,
        section 3). The standard and distorted methods only.

        Parameters
        ----------
        candidate : Candidates, one
        motion : Motion

        Returns
        -------
        Slope
        """
        if self.method is Method.SEPARABLE:
            raise ValueError("the separable method has no closed-form slope")
        center = candidate.centers[0] * self.scale
        rotation, sigma = candidate.rotations[0], float(candidate.sigmas[0])
        if self.method is Method.STANDARD:
            sigma = 1.0
        offsets = self.points - center
        mercator = self.layout is Layout.MERCATOR
        local, r, warped, theta, phi, second, at_centre, cap_cosine = fused.warp_one(
            offsets, np.ascontiguousarray(rotation), sigma, mercator, MERCATOR_THETA_MARGIN
        )
        shapes = self.shapes
        faces = (*shapes.arrays, np.ascontiguousarray(center))
        sums = fused.sums_of_plane(*faces, phi, second)
        objective, energy, hidden = _objective(tuple(sums[:, None]), np.array([at_centre]))
        scores = Scores(objective, energy, hidden, np.array([cap_cosine]))
        if not np.isfinite(objective[0]):
            zero = np.zeros(len(motion.log_sigma))
            return Slope(scores, zero, zero)
        by_phi, by_second = fused.energy_gradient(*faces, phi, second, len(phi), *sums[:5])
        gradient, cap_slope = fused.moved_gradient(
            offsets,
            np.ascontiguousarray(rotation),
            local,
            r,
            warped,
            theta,
            by_phi,
            by_second,
            np.ascontiguousarray(motion.rotation, dtype=np.float64),
            np.ascontiguousarray(motion.center * self.scale, dtype=np.float64),
            np.ascontiguousarray(motion.log_sigma, dtype=np.float64),
            sigma,
            0.0 if self.method is Method.STANDARD else 1.0,
            mercator,
            MERCATOR_THETA_MARGIN,
        )
        return Slope(scores, gradient, cap_slope)


def region_energy(
    points: np.ndarray,
    faces: np.ndarray,
    candidates: Candidates,
    method: Method,
    layout: Layout,
    block: int = 1 << 13,
) -> np.ndarray:
    """The area-weighted isometric energy of every face (docs/math.md, section 7) for each
    candidate: what :func:`transforms.region.flatten_region` reports as
    ``distortion.isometric.mean``, without the validation, the percentiles or any per-face
    array of the region's size.

    Parameters
    ----------
    points : (n, 3) float, world coordinates
    faces : (m, 3) int, indices into ``points``
    candidates : Candidates, ``k`` of them (a few: the angles of every vertex are kept
        for each)
    method, layout : as :class:`FaceEnergy`
    block : int, faces (and vertices) measured at a time: the temporaries are those of a
        block, a few MB

    Returns
    -------
    (k,) float, inf where a vertex is at the centre or every face is degenerate
    """
    scale = _unit_scale(points)
    scaled = points * scale
    centers = candidates.centers * scale
    plane = np.empty((len(candidates), len(points)), dtype=np.complex128)
    at_centre = np.zeros(len(candidates), dtype=bool)
    for start in range(0, len(points), block):
        found = _Angles.of(scaled[start : start + block], centers, candidates, method, layout)
        plane[:, start : start + block] = found.plane
        at_centre |= found.at_centre
    totals = np.zeros((6, len(candidates)))
    for start in range(0, len(faces), block):
        shapes = _FaceShapes(scaled, faces[start : start + block])
        totals += np.stack(shapes.sums(plane, None))
    return _objective(tuple(totals), at_centre)[1]


def _unit_scale(points: np.ndarray) -> float:
    """:func:`transforms.arrays.unit_scale` of the largest coordinate: the energy has no unit."""
    return unit_scale(float(np.abs(points).max()) if len(points) else 0.0)


def _objective(sums: tuple, at_centre: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(objective, energy, hidden)`` from :meth:`_FaceShapes.sums` (module docstring)."""
    seen_area, seen_layout, weight, frobenius, inverse, behind = sums
    with np.errstate(divide="ignore", invalid="ignore"):
        squared_scale = seen_area / seen_layout
        energy = 0.25 * (squared_scale * frobenius + inverse / squared_scale) / weight
        hidden = behind / (seen_area + behind)
    objective = energy + BACKFACING_WEIGHT * hidden
    broken = at_centre | ~(weight > 0) | ~np.isfinite(objective)
    return np.where(broken, math.inf, objective), energy, hidden


@dataclass(frozen=True)
class _Angles:
    """Per candidate and vertex, ``(k, n)`` complex: the layout point ``phi + i s`` with ``s``
    the layout's measured second coordinate; per candidate, whether a vertex is at the centre
    and the cap cosine (:class:`Scores`)."""

    plane: np.ndarray
    at_centre: np.ndarray
    cap_cosine: np.ndarray

    @classmethod
    def of(cls, points, centers, candidates: Candidates, method: Method, layout: Layout):
        """The angles of ``points`` (n, 3) from ``centers`` (k, 3), in the same units, with
        the candidates' rotations and sigmas (docs/math.md, sections 2, 3 and 5)."""
        rotations = candidates.rotations
        k = len(rotations)
        # Every candidate's local rows in one matrix product: (3k, 3) @ (3, n).
        moved = np.einsum("kij,kj->ki", rotations, centers)[:, :, None]
        local = (rotations.reshape(3 * k, 3) @ points.T).reshape(k, 3, -1) - moved
        x, y, z = local[:, 0], local[:, 1], local[:, 2]
        r = np.sqrt(x * x + y * y + z * z)
        at_centre = r < MIN_RADIUS
        r[at_centre] = 1.0
        theta, phi = _chart_angles(x, y, z, r, candidates.sigmas, method)
        y /= r
        cap_cosine = y.max(axis=1)
        plane = np.empty(theta.shape, dtype=np.complex128)
        plane.real, plane.imag = phi, measured_second(theta, layout)
        return cls(plane, at_centre.any(axis=1), cap_cosine)


@dataclass(frozen=True)
class _Warped:
    """One candidate's vertices through the frame and the warp, kept for the slope: local
    rows, distances, the warped direction ``(a, b, c)`` (times ``r``), and the angles."""

    offsets: np.ndarray
    rotation: np.ndarray
    sigma: float
    layout: Layout
    local: np.ndarray
    r: np.ndarray
    warped: np.ndarray
    theta: np.ndarray
    plane: np.ndarray
    at_centre: bool
    cap_cosine: float

    @classmethod
    def of(cls, offsets: np.ndarray, rotation: np.ndarray, sigma: float, layout: Layout):
        """``offsets`` (n, 3): the vertices less the centre, scaled."""
        local = rotation @ offsets.T  # (3, n)
        x, y, z = local
        r = np.sqrt(x * x + y * y + z * z)
        at_centre = bool((r < MIN_RADIUS).any())
        r[r < MIN_RADIUS] = 1.0
        plus, minus = plus_minus(x, y, z, r)
        warped = np.stack([2.0 * sigma * x, sigma * sigma * plus - minus, 2.0 * sigma * z])
        theta, phi = angles(*warped)
        plane = np.empty(len(r), dtype=np.complex128)
        plane.real, plane.imag = phi, measured_second(theta, layout)
        cap_cosine = float((y / r).max())
        return cls(
            offsets,
            rotation,
            sigma,
            Layout(layout),
            local,
            r,
            warped,
            theta,
            plane,
            at_centre,
            cap_cosine,
        )

    def moves(self, motion: Motion, scale: float, sigma_moves: float) -> _Moves:
        """(d, n) derivatives of each vertex's azimuth and measured second coordinate, and
        (d,) of the cap cosine, along ``motion`` (``sigma_moves`` 0: sigma stays)."""
        x, y, z = self.local
        r, sigma = self.r, self.sigma
        d = len(motion.log_sigma)
        moved = (motion.rotation.reshape(3 * d, 3) @ self.offsets.T).reshape(d, 3, -1)
        moved -= (self.rotation @ (motion.center * scale).T).T[:, :, None]
        dx, dy, dz = moved[:, 0], moved[:, 1], moved[:, 2]
        dr = (x * dx + y * dy + z * dz) / r
        dsigma = (sigma_moves * sigma * motion.log_sigma)[:, None]
        a, b, c = self.warped
        da = 2.0 * (sigma * dx + x * dsigma)
        dc = 2.0 * (sigma * dz + z * dsigma)
        db = (
            (sigma * sigma - 1.0) * dr + (sigma * sigma + 1.0) * dy + 2.0 * sigma * (r + y) * dsigma
        )
        across = a * a + b * b
        rho = np.sqrt(across)
        dphi = (a * db - b * da) / across
        drho = (a * da + b * db) / rho
        dtheta = (c * drho - rho * dc) / (across + c * c)
        if self.layout is Layout.MERCATOR:
            # d ln tan(theta / 2) = d theta / sin theta, inside the clip of layouts.
            inside = (self.theta > MERCATOR_THETA_MARGIN) & (
                self.theta < np.pi - MERCATOR_THETA_MARGIN
            )
            dtheta = np.where(inside, dtheta / np.sin(self.theta), 0.0)
        top = int(np.argmax(y / r))
        cap = (dy[:, top] - (y[top] / r[top]) * dr[:, top]) / r[top]
        return _Moves(dphi, dtheta, cap)


@dataclass(frozen=True)
class _Moves:
    phi: np.ndarray
    second: np.ndarray
    cap_cosine: np.ndarray


def _chart_angles(x, y, z, r, sigmas, method: Method) -> tuple[np.ndarray, np.ndarray]:
    """(k, n) theta and phi of local rows, a sigma per candidate."""
    if method is Method.SEPARABLE:
        rows = [
            separable_angles(x[i], y[i], z[i], r[i], 2.0 * math.atan(sigmas[i]))
            for i in range(len(sigmas))
        ]
        return np.stack([t for t, _ in rows]), np.stack([p for _, p in rows])
    if method is Method.STANDARD:
        return angles(x, y, z)
    # warp.warped_angles with a sigma per row, times r > 0 (which changes no angle):
    # (2 sigma x, sigma^2 (r + y) - (r - y), 2 sigma z), the sums without cancellation.
    sigma = sigmas[:, None]
    plus, minus = plus_minus(x, y, z, r)
    plus *= sigma * sigma
    plus -= minus
    return angles(2.0 * sigma * x, plus, 2.0 * sigma * z)


class _FaceShapes:
    """What a face's 3D shape contributes, measured once: its metric in its own plane, its
    area, its plane (docs/math.md, sections 6 and 7).

    With ``G`` the Gram matrix of the edges ``e1, e2`` at corner 0 and ``F`` the layout's
    edges, the Jacobian's squared norm is ``s1^2 + s2^2 = tr(F G^-1 F^T)``, and
    ``det G = |e1 x e2|^2``: with the edges as complex numbers ``z1, z2`` of the layout that
    is ``(g22 |z1|^2 - 2 g12 Re(conj(z1) z2) + g11 |z2|^2) / A^2`` (``A`` twice the area), and
    ``s1 s2 = |Im(conj(z1) z2)| / A``.
    """

    def __init__(self, points: np.ndarray, faces: np.ndarray) -> None:
        self.faces = np.ascontiguousarray(faces.T, dtype=np.intp)  # (corner, face)
        v0, v1, v2 = (points[corner] for corner in self.faces)
        e1, e2 = v1 - v0, v2 - v0
        g11 = np.einsum("ij,ij->i", e1, e1)
        g12 = np.einsum("ij,ij->i", e1, e2)
        g22 = np.einsum("ij,ij->i", e2, e2)
        self.normals = np.cross(e1, e2)  # (m, 3), |n| = twice the area
        area = np.sqrt(np.einsum("ij,ij->i", self.normals, self.normals))
        self.offsets = np.einsum("ij,ij->i", self.normals, v0)
        self.measurable = area > DEGENERATE_RTOL * (g11 + g22)
        safe = np.where(self.measurable, area, 1.0)
        self.metric = np.stack([g22, -2.0 * g12, g11]) / (safe * safe)  # G^-1's terms
        self.metric[:, ~self.measurable] = 0.0
        self.double_area = area
        self.cubed_area = np.where(self.measurable, area, 0.0) ** 3

    def __len__(self) -> int:
        return self.faces.shape[1]

    @property
    def arrays(self) -> tuple[np.ndarray, ...]:
        """What the compiled sums and gradient read of the faces (:mod:`.fused`), in their
        arguments' order."""
        return (
            self.faces,
            self.metric,
            self.double_area,
            self.cubed_area,
            self.measurable,
            self.normals,
            self.offsets,
        )

    def sums(self, plane, centers) -> tuple[np.ndarray, ...]:
        """Per candidate, ``(k,)``: the area and the layout area of the faces seen from the
        front, the measured faces' area, their sums of area times ``F`` and ``F / D^2``, and
        the area seen from behind. ``centers`` (k, 3) None: every face counts as seen from
        the front."""
        i0, i1, i2 = self.faces
        corner = plane[:, i0]
        z1 = plane[:, i1] - corner
        z2 = plane[:, i2] - corner
        product = z1.conj() * z2
        layout_area = np.abs(product.imag)
        g22, g12, g11 = self.metric
        frobenius = g22 * _abs2(z1) + g12 * product.real + g11 * _abs2(z2)  # s1^2 + s2^2
        # s2 <= DEGENERATE_RTOL s1 is squashed flat by the layout; s1^2 <= F bounds it.
        area = self.double_area
        measured = layout_area > DEGENERATE_RTOL * frobenius * area
        measured &= self.measurable
        if centers is None:
            seen_area = np.full(len(plane), area.sum())
            seen_layout = layout_area.sum(axis=1)
        else:
            # Seen from behind as validation judges it: against the faces' own winding.
            distance = self.offsets - centers @ self.normals.T
            ahead, behind = distance > 0.0, distance < 0.0
            winding = ahead.sum(axis=1) >= behind.sum(axis=1)
            front = np.where(winding[:, None], ahead, behind)
            measured &= front
            seen_area = front @ area
            seen_layout = np.einsum("kf,kf->k", front, layout_area)
        frobenius *= measured
        inverse = np.zeros_like(frobenius)
        np.divide(frobenius, layout_area * layout_area, out=inverse, where=measured)
        return (
            seen_area,
            seen_layout,
            measured @ area,
            frobenius @ area,
            inverse @ self.cubed_area,
            area.sum() - seen_area,
        )


def _energy_gradient(shapes: _FaceShapes, plane, center, sums) -> np.ndarray:
    """(n,) complex: the gradient of the energy of the faces seen from the front
    (:func:`_objective`) with respect to each vertex's layout point, ``dE/dphi + i dE/ds``,
    for one candidate whose sums (:meth:`_FaceShapes.sums`) are given; the faces seen from
    behind and the measured ones are held as they are. The slope runs its compiled twin,
    :func:`.fused.energy_gradient`; this is the reference the tests hold it to."""
    seen_area, seen_layout, weight, frobenius_sum, inverse_sum, _ = (float(v[0]) for v in sums)
    i0, i1, i2 = shapes.faces
    corner = plane[i0]
    z1, z2 = plane[i1] - corner, plane[i2] - corner
    product = z1.conj() * z2
    signed_area = product.imag
    layout_area = np.abs(signed_area)
    g22, g12, g11 = shapes.metric
    frobenius = g22 * _abs2(z1) + g12 * product.real + g11 * _abs2(z2)
    area = shapes.double_area
    distance = shapes.offsets - shapes.normals @ center
    ahead, behind = distance > 0.0, distance < 0.0
    front = ahead if ahead.sum() >= behind.sum() else behind
    measured = shapes.measurable & front & (layout_area > DEGENERATE_RTOL * frobenius * area)
    # E = (k^2 S1 + S2 / k^2) / (4 W) with k^2 = A / L: its partial derivatives.
    squared_scale = seen_area / seen_layout
    by_frobenius_sum = squared_scale / (4.0 * weight)
    by_inverse_sum = 1.0 / (4.0 * weight * squared_scale)
    by_layout_sum = -(frobenius_sum - inverse_sum / squared_scale**2) / (4.0 * weight)
    by_layout_sum *= squared_scale / seen_layout
    safe = np.where(measured, layout_area, 1.0)
    cubed = shapes.cubed_area
    by_frobenius = np.where(
        measured, area * by_frobenius_sum + cubed / safe**2 * by_inverse_sum, 0.0
    )
    by_area = np.where(front, by_layout_sum, 0.0)
    by_area -= np.where(measured, 2.0 * cubed * frobenius / safe**3 * by_inverse_sum, 0.0)
    by_signed = by_area * np.sign(signed_area)
    # F = g22 |z1|^2 + g12 Re(conj(z1) z2) + g11 |z2|^2 and L = Im(conj(z1) z2).
    x1, y1, x2, y2 = z1.real, z1.imag, z2.real, z2.imag
    first = by_frobenius * (2.0 * g22 * z1 + g12 * z2) + by_signed * (y2 - 1j * x2)
    second = by_frobenius * (2.0 * g11 * z2 + g12 * z1) + by_signed * (-y1 + 1j * x1)
    n = len(plane)
    total = np.zeros(n, dtype=np.complex128)
    for ids, values in ((i1, first), (i2, second), (i0, -(first + second))):
        total.real += np.bincount(ids, values.real, minlength=n)
        total.imag += np.bincount(ids, values.imag, minlength=n)
    return total


def _abs2(z: np.ndarray) -> np.ndarray:
    """``|z|^2`` of complex ``z``, without the square root of ``np.abs``."""
    return z.real * z.real + z.imag * z.imag
