"""The pole warp ``W_sigma`` (paper eq. 3) and distorted-pole coordinates (MATH.md, "The pole
warp W_sigma").

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
    one_plus_y, one_minus_y = _plus_minus(x, y, z, 1.0)
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

    Multiplying the stable form by ``r D > 0`` changes no angle, so with
    ``a = 2 sigma x``, ``b = sigma^2 (r + y) - (r - y)``, ``c = 2 sigma z`` the angles are
    ``theta = atan2(sqrt(a^2 + b^2), c)``, ``phi = atan2(b, a)``: no division by ``D``, no
    normalisation, and for ``sigma = 1`` exactly eq. 1 (``a, b, c = 2 x, 2 y, 2 z``). Near
    ``-Y`` the sum ``r + y`` cancels; there it is ``(x^2 + z^2) / (r - y)`` instead (and
    ``r - y`` likewise near ``+Y``), which keeps full precision for any sigma.

    Parameters
    ----------
    x, y, z : (n,) float, local coordinates
    r : (n,) float, ``|q| > 0``
    sigma : float, checked

    Returns
    -------
    theta, phi : (n,) float
    """
    a = x * (2.0 * sigma)
    c = z * (2.0 * sigma)
    if sigma == 1.0:
        return angles(a, y * 2.0, c)
    plus, minus = _plus_minus(x, y, z, r)
    plus *= sigma * sigma
    plus -= minus
    return angles(a, plus, c)


def _plus_minus(x, y, z, r) -> tuple[np.ndarray, np.ndarray]:
    """``r + y`` and ``r - y`` without cancellation, for ``r = |(x, y, z)|``.

    Near ``-Y`` the sum cancels and near ``+Y`` the difference; there each is the other's
    complement ``(x^2 + z^2) / (r -+ y)`` (their product is ``x^2 + z^2``), exact to rounding.
    """
    across = x * x
    across += z * z
    plus, minus = r + y, r - y
    with np.errstate(divide="ignore", invalid="ignore"):
        plus = np.where(y < 0.0, across / minus, plus)
        minus = np.where(y > 0.0, across / plus, minus)
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
