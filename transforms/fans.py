"""A triangle's part beyond an edge of an outline, seen from a point inside it, by the fan of
the triangle's three sectors about that point: its area and its first moment (docs/math.md,
section 12, eqs. 12.2 and 12.3), and the centroids of zones' parts of triangles from those.

Every piece of the fan is a triangle with a corner at the point ``O``: the area of ``O, P, Q``
is ``cross(P - O, Q - O) / 2`` and its first moment about ``O`` is that area times
``(P + Q - 2 O) / 3``, so moments are summed exactly as areas are.
"""

from __future__ import annotations

import numpy as np


def cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(p,) float: the z of ``u x v`` for (p, 2) arrays."""
    return u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]


def beyond(corners, reference, a, b) -> tuple[np.ndarray, np.ndarray]:
    """``s_e area(T & beyond_O(e))`` of eq. 12.2 and that part's first moment about ``O``.

    Parameters
    ----------
    corners : (p, 3, 2) float, counter-clockwise triangles ``T``
    reference : (p, 2) float, the points ``O``, inside them
    a, b : (p, 2) float, the edges' parts inside them

    Returns
    -------
    area : (p,) float, signed by ``s_e``
    moment : (p, 2) float, about ``O``, signed by ``s_e`` as well
    """
    u, v = a - reference, b - reference
    turn = cross(u, v)
    swap = turn < 0
    u, v = np.where(swap[:, None], v, u), np.where(swap[:, None], u, v)
    fan = np.zeros(len(a))
    fan_moment = np.zeros((len(a), 2))
    for i in range(3):
        p = corners[:, i] - reference
        q = corners[:, (i + 1) % 3] - reference
        area, moment = _sector_part(p, q, u, v)
        fan += area
        fan_moment += moment
    # The triangle O, a, b the angle holds on this side of the edge is not beyond it.
    sign = -np.sign(turn)
    near_moment = (0.5 * np.abs(turn) / 3.0)[:, None] * (u + v)
    return sign * (fan - 0.5 * np.abs(turn)), sign[:, None] * (fan_moment - near_moment)


def _sector_part(p, q, u, v) -> tuple[np.ndarray, np.ndarray]:
    """The area ((n,) float) and the first moment about ``O`` ((n, 2) float) of the sector
    ``O, O + p, O + q`` (counter-clockwise, ``O`` the origin) within the angle from ``u`` to
    ``v`` (counter-clockwise, below pi)."""
    u_in = (cross(p, u) >= 0) & (cross(u, q) >= 0)
    v_in = (cross(p, v) >= 0) & (cross(v, q) >= 0)
    p_in = (cross(u, p) >= 0) & (cross(p, v) >= 0)
    q_in = (cross(u, q) >= 0) & (cross(q, v) >= 0)
    start = np.where(u_in[:, None], u, p)
    stop = np.where(v_in[:, None], v, q)
    meets = (u_in | p_in) & (v_in | q_in)
    edge = q - p
    reach = cross(p, edge)
    with np.errstate(divide="ignore", invalid="ignore"):
        start = start * (reach / cross(start, edge))[:, None]
        stop = stop * (reach / cross(stop, edge))[:, None]
        area = 0.5 * cross(start, stop)
        moment = (area / 3.0)[:, None] * (start + stop)
    return np.where(meets, area, 0.0), np.where(meets[:, None], moment, 0.0)


def part_centroids(corners, centre, reference, moment, inside, least) -> np.ndarray:
    """The centroids of parts of triangles from their first moments about points in them.

    Parameters
    ----------
    corners : (q, 3, 2) float, the triangles, counter-clockwise
    centre : (q, 2) float, their centroids
    reference : (q, 2) float, the points ``O`` the moments are about
    moment : (q, 2) float, each part's first moment about ``O``
    inside : (q,) float, each part's area
    least : (q,) float, an area below which a part has no centroid to speak of

    Returns
    -------
    (q, 2) float: ``O + moment / inside``; the triangle's centroid where the part's area is
    not above ``least``; moved into the triangle where rounding left it outside.
    """
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        centroid = reference + moment / inside[:, None]
    usable = (inside > least) & np.isfinite(centroid).all(axis=1)
    centroid = np.where(usable[:, None], centroid, centre)
    # The centroid of a part of a triangle is in it, but for a sliver the rounding of moments
    # about a point far from it, over its small area, can put it outside: its barycentric
    # weights (times twice the triangle's area) are clipped at 0.
    p = corners[:, [1, 2, 0]] - centroid[:, None]
    q = corners[:, [2, 0, 1]] - centroid[:, None]
    weights = p[..., 0] * q[..., 1] - p[..., 1] * q[..., 0]
    clamped = np.maximum(weights, 0.0)
    total = clamped.sum(axis=1)
    outside = (weights < 0).any(axis=1) & (total > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        moved = np.einsum("qk,qkd->qd", clamped, corners) / total[:, None]
    return np.where(outside[:, None], moved, centroid)
