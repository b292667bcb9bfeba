"""Standard spherical coordinates: the paper's eq. 1 and its true inverse (MATH.md, Slip 1).

``theta`` is the polar angle from local ``+Z`` in ``[0, pi]``; ``phi`` the azimuth from
``+X`` towards ``+Y`` in ``(-pi, pi]``. The paper's printed eq. 2 swaps the two angles and is
not the inverse of eq. 1; :func:`spherical_to_cartesian` is.
"""

from __future__ import annotations

import numpy as np

from .arrays import as_angles, as_points
from .errors import TransformInputError, listed_rows

#: A point closer than this to the centre has no direction: the centre is on the surface.
MIN_RADIUS = 1e-100


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
    x, y, z = as_points(points).T
    r = radii(x, y, z)
    check_radii(r)
    theta, phi = angles(x, y, z)
    return theta, phi, r


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
    out: the warp and the separable method use this to skip normalising.

    Parameters
    ----------
    x, y, z : (n,) float, not all zero in a row

    Returns
    -------
    theta : (n,) float, ``atan2(sqrt(x^2 + y^2), z)`` in ``[0, pi]``
    phi : (n,) float, ``atan2(y, x)`` in ``(-pi, pi]``
    """
    return np.arctan2(np.hypot(x, y), z), half_open_azimuth(np.arctan2(y, x))


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
