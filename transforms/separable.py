"""The paper's alternative, "separable" coordinates (docs/math.md, section 5).

The two angles come from two separate formulas. With pole angle ``rho`` (the paper writes it
``sigma`` there) and ``k = 1 - 2 rho / pi``:

* azimuth ``phi = atan2(u_y - cos rho, u_x)``;
* polar angle ``theta = pi/2 - f`` with ``f`` the unique root in ``[-pi/2, pi/2]`` of
  ``F(f) = u_y sin(k f) + u_z cos(k f) - sin(f)``.

docs/math.md's names are used (slip 2): ``theta`` is polar-like, ``phi`` azimuth-like, as in eq. 1.

Solving for theta
-----------------
In terms of ``theta`` the equation reads ``G(theta) = s cos(A) - cos(theta) = 0`` with
``s = sqrt(u_y^2 + u_z^2)``, ``beta = atan2(u_z, u_y)`` and ``A = rho - beta + k theta``.
``G(0) <= 0 <= G(pi)`` and the root is unique (every chord of the family lies inside the unit
circle, their envelope outside it), with ``G' > 0`` there except at the two singular points.
:func:`separable_theta` evaluates ``G`` without cancellation,

    G = -2 sin((A + theta) / 2) sin((A - theta) / 2) - (1 - s) cos(A),  1 - s = u_x^2 / (1 + s),

so it keeps relative accuracy even next to the singular points, and finds the root for all
points at once: a starting guess from the exact root on the great circle ``x = 0`` refined by
fixed-point steps, then Halley's method inside a bracket with bisection as the fallback (as
in ``rtsafe``): the bracket at least halves every second step, so it always converges.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from functools import partial

import numpy as np

from .arrays import as_angles, as_points, numeric_array, unit_rows
from .cap import check_rho
from .errors import TransformInputError, listed_rows
from .spherical import half_open_azimuth, points_to_angles

#: Stop when a bisection step is below this (radians).
THETA_TOLERANCE = 1e-15
#: Stop when a Halley step is below this times the distance to the nearer singular point.
HALLEY_RTOL = 1e-6
#: The bracket halves at least every second step; 2 * 53 steps reach the float spacing at pi.
MAX_ITERATIONS = 120

#: A starting guess for the polar angle: ``(gamma, s, k)`` to ``theta`` (module docstring).
StartingGuess = Callable[[np.ndarray, np.ndarray, float], np.ndarray]


def separable_forward(
    points, rho: float, *, starting_guess: StartingGuess | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Separable coordinates of local points.

    Parameters
    ----------
    points : (n, 3) float, local frame
    rho : float, pole angle in radians, in ``[cap.RHO_MIN, cap.RHO_MAX]``
    starting_guess : where the root search for ``theta`` starts (:func:`separable_theta`);
        None: :func:`_starting_guess`

    Returns
    -------
    theta : (n,) float, in ``[0, pi]``
    phi : (n,) float, in ``(-pi, pi]``
    r : (n,) float

    Raises
    ------
    TransformInputError
        Non-finite coordinates, a point at the centre, or ``rho`` out of range.
    """
    angles_of = partial(separable_angles, rho=check_rho(rho), starting_guess=starting_guess)
    return points_to_angles(as_points(points), angles_of)


def separable_angles(
    x: np.ndarray,
    y: np.ndarray,
    z: np.ndarray,
    r: np.ndarray,
    rho: float,
    *,
    starting_guess: StartingGuess | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Both separable angles of already checked local coordinates.

    Parameters
    ----------
    x, y, z : (n,) float, local coordinates
    r : (n,) float, ``|q| > 0``
    rho : float, checked pole angle
    starting_guess : as for :func:`separable_theta`

    Returns
    -------
    theta, phi : (n,) float
    """
    phi = half_open_azimuth(np.arctan2(y - r * math.cos(rho), x))
    theta = separable_theta(
        x / r, np.hypot(y, z) / r, np.arctan2(z, y), rho, starting_guess=starting_guess
    )
    return theta, phi


def separable_theta(
    u_x: np.ndarray,
    s: np.ndarray,
    beta: np.ndarray,
    rho: float,
    *,
    starting_guess: StartingGuess | None = None,
) -> np.ndarray:
    """The polar angle: the root of ``G`` (module docstring) for every direction at once.

    Parameters
    ----------
    u_x : (n,) float, x component of the unit direction
    s : (n,) float, ``sqrt(u_y^2 + u_z^2)``
    beta : (n,) float, ``atan2(u_z, u_y)``
    rho : float, pole angle in radians
    starting_guess : callable ``(gamma, s, k) -> theta`` on (n,) arrays (``gamma = rho -
        beta`` as below, ``k = 1 - 2 rho / pi``), where the search starts; any guess in
        ``[0, pi]`` converges (the bracket starts as ``[0, pi]``), a good one sooner.
        None: :func:`_starting_guess`

    Returns
    -------
    (n,) float, theta in ``[0, pi]``
    """
    k = 1.0 - 2.0 * rho / math.pi
    one_minus_s = u_x * u_x / (1.0 + s)
    # gamma = rho - beta, taken in (2 rho - 2 pi, 2 rho] so that A = gamma + k theta.
    gamma = rho - beta
    gamma = np.where(gamma > 2.0 * rho, gamma - 2.0 * math.pi, gamma)
    theta = (_starting_guess if starting_guess is None else starting_guess)(gamma, s, k)

    result = np.empty_like(theta)
    active = np.arange(theta.size)
    low, high = np.zeros_like(theta), np.full_like(theta, math.pi)
    step, step_before = np.full_like(theta, math.pi), np.full_like(theta, math.pi)
    for _ in range(MAX_ITERATIONS):
        if active.size == 0:
            break
        a = gamma + k * theta
        cos_a = np.cos(a)
        g = -2.0 * np.sin(0.5 * (a + theta)) * np.sin(0.5 * (a - theta)) - one_minus_s * cos_a
        slope = np.sin(theta) - k * (1.0 - one_minus_s) * np.sin(a)
        curvature = np.cos(theta) - k * k * (1.0 - one_minus_s) * cos_a
        low = np.where(g < 0.0, theta, low)
        high = np.where(g > 0.0, theta, high)
        with np.errstate(divide="ignore", invalid="ignore"):
            halley = 2.0 * g * slope / (2.0 * slope * slope - g * curvature)
        # Bisect when Halley's step leaves the bracket or does not halve the step before last.
        candidate = theta - halley
        # (or where G' <= 0: only next to a singular point, where the step is meaningless).
        bisect = (
            ~((candidate >= low) & (candidate <= high))
            | (np.abs(2.0 * halley) > np.abs(step_before))
            | (slope <= 0.0)
        )
        step_before = step
        step = np.where(bisect, 0.5 * (high - low), halley)
        exact = g == 0.0
        previous, theta = theta, np.where(bisect, low + step, candidate)
        # After a Halley step of size d the error is about C d^3 with C ~ 1 / t^2, t the
        # distance to the nearer singular point (theta or pi - theta; G' vanishes only
        # there): d below HALLEY_RTOL * t leaves ~1e-16 t. Bisection steps must reach
        # THETA_TOLERANCE itself.
        nearer = np.maximum(np.minimum(theta, math.pi - theta), THETA_TOLERANCE)
        small = np.where(bisect, THETA_TOLERANCE, HALLEY_RTOL * nearer)
        done = (np.abs(step) < small) | exact
        if done.any():
            keep = ~done
            result[active[done]] = np.where(exact, previous, theta)[done]
            active, gamma, one_minus_s = active[keep], gamma[keep], one_minus_s[keep]
            theta, low, high = theta[keep], low[keep], high[keep]
            step, step_before = step[keep], step_before[keep]
    result[active] = 0.5 * (low + high)  # not reached in practice: the bracket is ~1e-15 wide
    return result


def _starting_guess(gamma: np.ndarray, s: np.ndarray, k: float) -> np.ndarray:
    """A cheap estimate of the root, typically within 1e-9 rad.

    On the great circle ``x = 0`` (``s = 1``) the root is exact: ``gamma / (1 - k)`` or
    ``-gamma / (1 + k)``. From there the fixed-point map ``theta -> acos(s cos(gamma + k
    theta))`` with two rounds of Aitken's extrapolation (Steffensen's method).
    """
    on_circle = np.where(gamma >= 0.0, gamma / (1.0 - k), -gamma / (1.0 + k))
    # The first fixed-point step is cheap: cos(gamma + k on_circle) = cos(on_circle).
    theta = _aitken(_fixed_point_step(on_circle, s), gamma, s, k)
    return _aitken(theta, gamma, s, k)


def _fixed_point_step(angle: np.ndarray, s: np.ndarray) -> np.ndarray:
    """``acos(s cos(angle))``, its argument clipped to [-1, 1] against rounding."""
    return np.arccos(np.clip(s * np.cos(angle), -1.0, 1.0))


def _aitken(theta: np.ndarray, gamma: np.ndarray, s: np.ndarray, k: float) -> np.ndarray:
    """Two fixed-point steps from ``theta`` and Aitken's extrapolation of the three values."""
    second = _fixed_point_step(gamma + k * theta, s)
    third = _fixed_point_step(gamma + k * second, s)
    curvature = (third - second) - (second - theta)
    with np.errstate(divide="ignore", invalid="ignore"):
        extrapolated = third - (third - second) ** 2 / curvature
    return np.clip(np.where(np.isfinite(extrapolated), extrapolated, third), 0.0, math.pi)


def separable_residual(f, points, rho: float) -> np.ndarray:
    """docs/math.md's ``F(f) = u_y sin(k f) + u_z cos(k f) - sin(f)``, for checking roots.

    Parameters
    ----------
    f : (n,) float, chord parameter (``f = pi/2 - theta``)
    points : (n, 3) float, local frame, not at the centre (normalised here)
    rho : float, pole angle in radians

    Returns
    -------
    (n,) float
    """
    rho = check_rho(rho)
    u, zero = unit_rows(as_points(points))
    if zero.any():
        text, rows = listed_rows(zero, "point")
        raise TransformInputError("points", f"{text}: at the centre, no direction", rows)
    f = numeric_array(f, "f", "a list of numbers").astype(np.float64)
    if f.shape != (len(u),):
        raise TransformInputError("f", f"needs one value per point ({len(u)}), got {f.shape}")
    k = 1.0 - 2.0 * rho / math.pi
    return u[:, 1] * np.sin(k * f) + u[:, 2] * np.cos(k * f) - np.sin(f)


def separable_inverse(theta, phi, r=1.0, *, rho: float) -> np.ndarray:
    """Back from separable coordinates, in closed form.

    ``phi`` puts the point on the half-plane ``(u_x, u_y - cos rho) = t (cos phi, sin phi)``,
    ``t >= 0``; ``theta`` on the chord plane ``u_y cos(psi) + u_z sin(psi) = cos(theta)`` with
    ``psi = rho + k theta`` (in ``(0, pi)``, so ``sin(psi) > 0``). Their line meets the unit
    sphere where ``A t^2 + 2 B t + c0 = 0``; ``c0 <= 0`` (the line starts inside the sphere on
    the axis between the singular points), so the root ``t >= 0`` is unique.

    Parameters
    ----------
    theta : (n,) float, in ``[0, pi]``
    phi : (n,) float, in ``[-pi, pi]``
    r : (n,) float or scalar, ``>= 0``
    rho : float, pole angle in radians

    Returns
    -------
    (n, 3) float, local frame
    """
    rho = check_rho(rho)
    theta, phi, r = as_angles(theta, phi, r)
    k = 1.0 - 2.0 * rho / math.pi
    cos_rho = math.cos(rho)
    psi = rho + k * theta
    cos_psi, sin_psi = np.cos(psi), np.sin(psi)
    sin_phi, cos_phi = np.sin(phi), np.cos(phi)
    # Height where the chord plane meets the axis x = 0, y = cos rho, and its distances to the
    # two singular points (half-angle forms: both vanish at a singular point without
    # cancelling).
    z0 = (np.cos(theta) - cos_psi * cos_rho) / sin_psi
    below_north = -2.0 * np.sin(0.5 * (1.0 + k) * theta) * np.sin(0.5 * (1.0 - k) * theta) / sin_psi
    above_south = (
        -2.0
        * np.sin(0.5 * (theta + 2.0 * rho + k * theta))
        * np.sin(0.5 * (theta - 2.0 * rho - k * theta))
        / sin_psi
    )
    z1 = -cos_psi * sin_phi / sin_psi
    a = 1.0 + z1 * z1
    b = cos_rho * sin_phi + z0 * z1
    c0 = np.minimum(below_north * above_south, 0.0)
    root = np.sqrt(np.maximum(b * b - a * c0, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(b > 0.0, -c0 / (b + root), (root - b) / a)
    t = np.maximum(np.nan_to_num(t, nan=0.0), 0.0)
    u = np.stack([t * cos_phi, cos_rho + t * sin_phi, z0 + z1 * t], axis=1)
    return u * r[:, None]
