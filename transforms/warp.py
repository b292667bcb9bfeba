"""The pole warp ``W_sigma`` (paper eq. 3) and distorted-pole coordinates (docs/math.md,
section 3).

``W_sigma`` is stereographic projection from ``+Y``, scaling by ``sigma``, and projection
back. On the unit sphere it has the singularity-free form

    D = sigma^2 (1 + y) + (1 - y)
    W(x, y, z) = (2 sigma x / D,  (sigma^2 (1 + y) - (1 - y)) / D,  2 sigma z / D)

which this module uses everywhere. ``W_{1/sigma}`` is its inverse (Theorem 1).
"""

from __future__ import annotations

from functools import partial

import numpy as np

from .arrays import as_angles, as_points, unit_rows
from .cap import check_sigma
from .errors import TransformInputError, listed_rows
from .spherical import angles, points_to_angles, unit_vectors


def pole_warp(directions, sigma: float) -> np.ndarray:
    """``W_sigma`` of the given directions, in the stable form.

    Parameters
    ----------
    directions : (n, 3) float, non-zero (each row is normalised first)
    sigma : float, in ``[cap.SIGMA_MIN, cap.SIGMA_MAX]``

    Returns
    -------
    (n, 3) float, unit vectors: ``+Y`` and ``-Y`` are fixed, ``W_1`` is the identity.

    Raises
    ------
    TransformInputError
        A zero or non-finite direction, or ``sigma`` out of range.
    """
    sigma = check_sigma(sigma)
    u, zero = unit_rows(as_points(directions, "directions"))
    if zero.any():
        text, rows = listed_rows(zero, "direction")
        raise TransformInputError("directions", f"{text}: zero vector has no direction", rows)
    x, y, z = u.T
    s2 = sigma * sigma
    one_plus_y, one_minus_y = plus_minus(x, y, z)
    denominator = s2 * one_plus_y + one_minus_y  # >= 2 min(sigma^2, 1) > 0 on the sphere
    warped = (
        np.stack([2.0 * sigma * x, s2 * one_plus_y - one_minus_y, 2.0 * sigma * z], axis=1)
        / denominator[:, None]
    )
    # Exact arithmetic gives |W| = 1; renormalising removes the rounding the division adds.
    return warped / np.linalg.norm(warped, axis=1)[:, None]


def distorted_forward(points, sigma: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Distorted-pole coordinates: ``(theta, phi) = sph(W_sigma(q / |q|))``, ``r = |q|``.

    Parameters
    ----------
    points : (n, 3) float, local frame
    sigma : float

    Returns
    -------
    theta : (n,) float, in ``[0, pi]``
    phi : (n,) float, in ``(-pi, pi]``
    r : (n,) float

    Raises
    ------
    TransformInputError
        Non-finite coordinates, a point at the centre, or ``sigma`` out of range.
    """
    return points_to_angles(as_points(points), partial(warped_angles, sigma=check_sigma(sigma)))


def warped_angles(
    x: np.ndarray, y: np.ndarray, z: np.ndarray, r: np.ndarray, sigma: float
) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 1's angles of ``W_sigma(q / r)`` for already checked local coordinates.

    Multiplying the stable form by ``D > 0`` changes no angle, so on the unit direction
    ``u = q / r``, with ``a = 2 sigma u_x``, ``b = sigma^2 (1 + u_y) - (1 - u_y)``,
    ``c = 2 sigma u_z``, the angles are ``theta = atan2(sqrt(a^2 + b^2), c)``,
    ``phi = atan2(b, a)``: no division by ``D``, and for ``sigma = 1`` exactly eq. 1. Near
    ``-Y`` the sum ``1 + u_y`` cancels; there it is ``(u_x^2 + u_z^2) / (1 - u_y)`` instead
    (and ``1 - u_y`` likewise near ``+Y``), which keeps full precision for any sigma. On the
    unit direction ``|a|, |b| <= 2 SIGMA_MAX^2``: their squares cannot overflow.

    Parameters
    ----------
    x, y, z : (n,) float, local coordinates
    r : (n,) float, ``|q| > 0``
    sigma : float, checked

    Returns
    -------
    theta, phi : (n,) float
    """
    to_unit = np.reciprocal(r)
    a = x * to_unit
    c = z * to_unit
    unit_y = y * to_unit
    if sigma == 1.0:
        return angles(a, unit_y, c)
    plus, minus = plus_minus(a, unit_y, c)
    plus *= sigma * sigma
    plus -= minus
    a *= 2.0 * sigma
    c *= 2.0 * sigma
    return angles(a, plus, c)


def plus_minus(x, y, z, r=1.0) -> tuple[np.ndarray, np.ndarray]:
    """``r + y`` and ``r - y`` without cancellation, for ``(x, y, z)`` of length ``r`` (a
    unit vector by default).

    Near ``-Y`` the sum cancels and near ``+Y`` the difference; there each is the other's
    complement ``(x^2 + z^2) / (r -+ y)`` (their product is ``x^2 + z^2``), exact to rounding.
    The one without cancellation is ``r + |y|``.
    """
    exact = np.abs(y)
    exact += r
    complement = x * x
    complement += z * z
    complement /= exact
    negative = y < 0.0
    plus = np.where(negative, complement, exact)
    minus = np.where(negative, exact, complement)
    return plus, minus


def distorted_inverse(theta, phi, r=1.0, *, sigma: float) -> np.ndarray:
    """Back from distorted-pole coordinates: direction of ``(theta, phi)``, then
    ``W_{1/sigma}``, then times ``r`` (the paper's last methodology step, with eq. 1's true
    inverse).

    Parameters
    ----------
    theta : (n,) float, in ``[0, pi]``
    phi : (n,) float, in ``[-pi, pi]``
    r : (n,) float or scalar, ``>= 0``
    sigma : float

    Returns
    -------
    (n, 3) float, local frame
    """
    sigma = check_sigma(sigma)
    theta, phi, r = as_angles(theta, phi, r)
    return pole_warp(unit_vectors(theta, phi), 1.0 / sigma) * r[:, None]
