"""Angular distances on the unit sphere from the projected outline of a region to the singular
points and to the seam (MATH.md, "Validation a region needs": margins).

Seen from the centre, a straight edge ``(a, b)`` projects to the minor great-circle arc between
the unit directions ``a`` and ``b``. The seam is an arc of a small circle (angle ``rho`` from
``+Y``, side ``x <= 0``). All inputs are ``(k, 3)`` unit directions; all outputs radians.
"""

from __future__ import annotations

import math

import numpy as np

from .cap import PoleCap


def angles_between(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(k,) float: angle between rows of ``u`` and ``v`` (``(k, 3)`` or ``(3,)``), accurate
    at 0 and pi (``atan2(|u x v|, u . v)``)."""
    return np.arctan2(np.linalg.norm(np.cross(u, v), axis=-1), np.sum(u * v, axis=-1))


def arcs_to_point(a: np.ndarray, b: np.ndarray, point: np.ndarray) -> np.ndarray:
    """Distance from a unit ``point`` (3,) to each minor arc ``a -> b``.

    Parameters
    ----------
    a, b : (k, 3) float, unit arc ends
    point : (3,) float, unit

    Returns
    -------
    (k,) float, radians in ``[0, pi]``
    """
    normal = np.cross(a, b)
    length = np.linalg.norm(normal, axis=1)
    ends = np.minimum(angles_between(a, point), angles_between(b, point))
    with np.errstate(divide="ignore", invalid="ignore"):
        unit_normal = normal / length[:, None]
    off_plane = unit_normal @ point  # sine of the distance to the whole great circle
    in_plane = point[None, :] - off_plane[:, None] * unit_normal
    # The foot of the perpendicular lies on the arc when it is between a and b.
    between = (
        (length > 0)
        & (np.sum(np.cross(a, point) * normal, axis=1) >= 0)
        & (np.sum(np.cross(point, b) * normal, axis=1) >= 0)
    )
    to_circle = np.arctan2(np.abs(off_plane), np.linalg.norm(in_plane, axis=1))
    return np.where(between, np.minimum(to_circle, ends), ends)


def arcs_to_seam(a: np.ndarray, b: np.ndarray, cap: PoleCap) -> np.ndarray:
    """Distance from the seam of ``cap`` to each minor arc ``a -> b``.

    A point ``u`` with ``x <= 0`` is ``|angle(u, +Y) - rho|`` from the seam (the nearest
    point of the circle is on its own meridian); one with ``x > 0`` is nearest to a singular
    point. So the distance of an arc is the least of its distances to the two singular points
    and of ``|angle(u, +Y) - rho|`` over its part with ``x <= 0``, which is zero when that
    part crosses the circle and otherwise is reached at an end of that part (an arc end, or a
    point with ``x = 0``) or where ``angle(u, +Y)`` is extreme along the great circle.

    Parameters
    ----------
    a, b : (k, 3) float, unit arc ends
    cap : PoleCap

    Returns
    -------
    (k,) float, radians
    """
    to_singular = np.minimum(arcs_to_point(a, b, cap.north), arcs_to_point(a, b, cap.south))
    return np.minimum(to_singular, _circle_part_distance(a, b, cap.rho))


def _circle_part_distance(a: np.ndarray, b: np.ndarray, rho: float) -> np.ndarray:
    """(k,) float: least ``|angle(u, +Y) - rho|`` over the points of arc ``a -> b`` with
    ``x <= 0`` (inf where there are none)."""
    span = angles_between(a, b)
    # u(t) = a cos t + e sin t, 0 <= t <= span, with e the unit tangent at a towards b.
    e = b - np.sum(a * b, axis=1)[:, None] * a
    e_norm = np.linalg.norm(e, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        e = np.where(e_norm[:, None] > 0, e / e_norm[:, None], 0.0)
    x_peak = np.arctan2(e[:, 0], a[:, 0])
    y_peak = np.arctan2(e[:, 1], a[:, 1])
    t = np.stack(
        [
            np.zeros_like(span),
            span,
            y_peak,
            y_peak + math.pi,
            x_peak + 0.5 * math.pi,  # x(t) = 0 here
            x_peak - 0.5 * math.pi,
        ],
        axis=1,
    ) % (2.0 * math.pi)
    on_arc = t <= span[:, None]
    u = a[:, None, :] * np.cos(t)[..., None] + e[:, None, :] * np.sin(t)[..., None]
    on_seam_side = u[..., 0] <= 0.0
    on_seam_side[:, 4:] = True  # rounding may leave x slightly positive where it is zero
    usable = on_arc & on_seam_side
    polar = np.arctan2(np.hypot(u[..., 0], u[..., 2]), u[..., 1])  # angle from +Y
    low = np.where(usable, polar, np.inf).min(axis=1)
    high = np.where(usable, polar, -np.inf).max(axis=1)
    crosses = (low <= rho) & (high >= rho)
    nearest = np.where(usable, np.abs(polar - rho), np.inf).min(axis=1)
    return np.where(crosses, 0.0, nearest)
