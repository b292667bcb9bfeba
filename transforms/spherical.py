"""Standard spherical coordinates: the paper's eq. 1 and its true inverse (docs/math.md, section 2).

``theta`` is the polar angle from local ``+Z`` in ``[0, pi]``; ``phi`` the azimuth from
``+X`` towards ``+Y`` in ``(-pi, pi]``. The paper's printed eq. 2 swaps the two angles and is
not the inverse of eq. 1; :func:`spherical_to_cartesian` is.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from .arrays import as_angles, as_points
from .errors import TransformInputError, listed_rows
from .parallel import map_blocks

#: A point closer than this to the centre has no usable direction (its squared distance
#: would underflow): the centre is on the surface.
MIN_RADIUS = 1e-150

#: Computes ``(theta, phi)`` from rows ``x, y, z`` of checked local coordinates and their
#: distances ``r`` from the centre (each ``(n,)`` float).
AngleKernel = Callable[
    [np.ndarray, np.ndarray, np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]
]


def cartesian_to_spherical(points) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Paper eq. 1: local points to ``(theta, phi, r)``.

    Parameters
    ----------
    points : (n, 3) float, local frame (the centre at the origin)

    Returns
    -------
    theta : (n,) float, in ``[0, pi]``
    phi : (n,) float, in ``(-pi, pi]``
    r : (n,) float, ``> 0``

    Raises
    ------
    TransformInputError
        A non-finite coordinate, or a point at the centre (``r = 0``).
    """
    return points_to_angles(as_points(points), eq1_angles)


def points_to_angles(
    points: np.ndarray,
    kernel: AngleKernel,
    local_rows: Callable[[np.ndarray], np.ndarray] | None = None,
    threads: int = 1,
    field: str = "points",
    noun: str = "point",
    row_ids: np.ndarray | None = None,
    rows_out: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Run an angle kernel over checked points, block by block so temporaries stay in cache.

    Parameters
    ----------
    points : (n, 3) float, checked (``arrays.as_points``)
    kernel : AngleKernel, e.g. :func:`eq1_angles` or ``warp.warped_angles`` with its sigma
    local_rows : maps a block of points to local rows ``(3, b)``; ``None`` when the points
        are already local
    threads : int, threads to spread the blocks over
    field, noun, row_ids : how the error for a point at the centre names the input, a row,
        and each row's id (see :func:`check_radii`)
    rows_out : (3, n) float or None, receives the local rows ``x, y, z`` (for callers that
        measure the points next, without a second pass over them)

    Returns
    -------
    theta, phi, r : (n,) float
    """
    n = len(points)
    theta, phi, r = np.empty(n), np.empty(n), np.empty(n)

    def run(block: slice) -> None:
        if local_rows is None:
            x, y, z = np.ascontiguousarray(points[block].T)
        else:
            x, y, z = local_rows(points[block])
        if rows_out is not None:
            rows_out[0, block], rows_out[1, block], rows_out[2, block] = x, y, z
        radius = radii(x, y, z)
        check_radii(radius, field, noun, block.start, row_ids)
        r[block] = radius
        theta[block], phi[block] = kernel(x, y, z, radius)

    map_blocks(run, n, threads)
    return theta, phi, r


def eq1_angles(
    x: np.ndarray, y: np.ndarray, z: np.ndarray, r: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 1 as an :data:`AngleKernel`, on the unit directions (see :func:`angles`)."""
    to_unit = np.reciprocal(r)
    return angles(x * to_unit, y * to_unit, z * to_unit)


def spherical_to_cartesian(theta, phi, r=1.0) -> np.ndarray:
    """The true inverse of eq. 1: ``x = r sin(theta) cos(phi)``, ``y = r sin(theta) sin(phi)``,
    ``z = r cos(theta)``.

    Parameters
    ----------
    theta : (n,) float, in ``[0, pi]``
    phi : (n,) float, in ``[-pi, pi]``
    r : (n,) float or scalar, ``>= 0``

    Returns
    -------
    (n, 3) float, local frame
    """
    theta, phi, r = as_angles(theta, phi, r)
    return unit_vectors(theta, phi) * r[:, None]


def unit_vectors(theta: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """Unit directions for already checked angles (eq. 1 inverse with ``r = 1``).

    Parameters
    ----------
    theta, phi : (n,) float

    Returns
    -------
    (n, 3) float, unit rows
    """
    sin_theta = np.sin(theta)
    return np.stack([sin_theta * np.cos(phi), sin_theta * np.sin(phi), np.cos(theta)], axis=1)


def angles(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 1's two angles of the directions ``(x, y, z)``.

    Both are ``atan2`` of ratios, so any positive common factor of ``x, y, z`` may be left
    out (the warp uses this to skip dividing by its denominator). ``sqrt(x^2 + y^2)`` is
    formed directly, without ``hypot``'s rescaling (several times slower): callers pass
    directions scaled to about unit length, whose squares neither overflow nor, above
    ``1e-150``, underflow.

    Parameters
    ----------
    x, y, z : (n,) float, not all zero in a row, each at most ``1e150`` in magnitude

    Returns
    -------
    theta : (n,) float, ``atan2(sqrt(x^2 + y^2), z)`` in ``[0, pi]``
    phi : (n,) float, ``atan2(y, x)`` in ``(-pi, pi]``
    """
    across = x * x
    across += y * y
    return np.arctan2(np.sqrt(across, out=across), z), half_open_azimuth(np.arctan2(y, x))


def half_open_azimuth(phi: np.ndarray) -> np.ndarray:
    """Map ``-pi`` (from ``y = -0.0``, or a tiny negative ``y`` rounding there) to ``+pi``
    in place, so azimuths lie in ``(-pi, pi]``; returns ``phi``."""
    phi[phi == -np.pi] = np.pi
    return phi


def radii(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Distances from the centre, ``sqrt(x^2 + y^2 + z^2)``, of local coordinates within
    ``arrays.MAX_ABS_COORDINATE`` (no overflow).

    Parameters
    ----------
    x, y, z : (n,) float

    Returns
    -------
    (n,) float
    """
    return np.sqrt(x * x + y * y + z * z)


def check_radii(
    r: np.ndarray,
    field: str = "points",
    noun: str = "point",
    offset: int = 0,
    row_ids: np.ndarray | None = None,
) -> None:
    """Refuse points at the centre: they have no direction.

    Parameters
    ----------
    r : (n,) float, distances from the centre
    field, noun : how the error names the input and one of its rows
    offset : position of ``r[0]`` in the whole input (for a block of it)
    row_ids : (N,) int, the ids to report for the whole input's rows (default: positions)

    Raises
    ------
    TransformInputError
        A distance below ``MIN_RADIUS``.
    """
    at_centre = r < MIN_RADIUS
    if at_centre.any():
        positions = offset + np.flatnonzero(at_centre)
        ids = positions if row_ids is None else row_ids[positions]
        mask = np.zeros(int(ids.max()) + 1, dtype=bool)
        mask[ids] = True
        text, rows = listed_rows(mask, noun)
        raise TransformInputError(
            field,
            f"{text}: at the centre (distance below {MIN_RADIUS:g}), so no direction is "
            "defined; choose a centre that is not on the surface",
            rows,
        )
