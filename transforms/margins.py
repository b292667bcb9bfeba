"""Angular distances on the unit sphere from the projected outline of a region to the singular
points and to the seam (docs/math.md, section 6: margins).

Seen from the centre, a straight edge ``(a, b)`` projects to the minor great-circle arc between
the unit directions ``a`` and ``b``. The seam is an arc of a small circle (angle ``rho`` from
``+Y``, side ``x <= 0``). Inputs are ``(k, 3)`` unit directions, outputs radians; inside, the
arithmetic runs on coordinate rows (short ``(k, 3)`` rows are slow in numpy).
"""

from __future__ import annotations

import math

import numpy as np

from .cap import PoleCap

#: An arc end with ``x`` at most this counts as on the seam's side (``x <= 0``), so that an
#: end on ``x = 0`` is not lost to rounding. Measuring a point with ``0 < x <= _SIDE_SLACK``
#: from the whole circle rather than from the seam is off by about its ``x``, far below the
#: validation's touch tolerance (``1e-12``).
_SIDE_SLACK = 1e-14
#: An arc whose ends' cross product is shorter than this is measured from its ends. Below it
#: the squares that give the product's length turn subnormal, and the "unit" normal is not
#: (ends 1e-162 apart once put a point 7 degrees too near). Such an arc is shorter than this,
#: so no point of it is nearer than its ends by more (or its ends are as good as antipodal,
#: and it is no one minor arc).
_POINT_ARC = 1e-150


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
    return _arcs_to_point(_rows(a), _rows(b), _rows(point))


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
    a_rows, b_rows = _rows(a), _rows(b)
    to_singular = np.minimum(
        _arcs_to_point(a_rows, b_rows, _rows(cap.north)),
        _arcs_to_point(a_rows, b_rows, _rows(cap.south)),
    )
    return np.minimum(to_singular, _circle_part_distance(a_rows, b_rows, cap.rho))


def _rows(vectors: np.ndarray) -> tuple[np.ndarray, ...]:
    """Coordinate rows ``x, y, z`` of ``(k, 3)`` vectors (or scalars of a ``(3,)`` vector)."""
    vectors = np.asarray(vectors, dtype=np.float64)
    if vectors.ndim == 1:
        return tuple(float(c) for c in vectors)
    return tuple(np.ascontiguousarray(vectors.T))


def _cross(p, q):
    return (p[1] * q[2] - p[2] * q[1], p[2] * q[0] - p[0] * q[2], p[0] * q[1] - p[1] * q[0])


def _dot(p, q):
    return p[0] * q[0] + p[1] * q[1] + p[2] * q[2]


def _norm(p):
    return np.sqrt(_dot(p, p))


def _angle(p, q):
    return np.arctan2(_norm(_cross(p, q)), _dot(p, q))


def _arcs_to_point(a, b, point) -> np.ndarray:
    """:func:`arcs_to_point` on rows."""
    normal = _cross(a, b)
    length = _norm(normal)
    ends = np.minimum(_angle(a, point), _angle(b, point))
    # Where a and b are parallel (or as good as: ``_POINT_ARC``) the arc is a point: only
    # ``ends`` counts, and a stand-in length keeps the unused arithmetic finite.
    arc = length > _POINT_ARC
    safe_length = np.where(arc, length, 1.0)
    unit_normal = tuple(c / safe_length for c in normal)
    off_plane = _dot(unit_normal, point)  # sine of the distance to the whole great circle
    in_plane = tuple(p - off_plane * n for p, n in zip(point, unit_normal, strict=True))
    # The foot of the perpendicular lies on the arc when it is between a and b.
    between = arc & (_dot(_cross(a, point), normal) >= 0) & (_dot(_cross(point, b), normal) >= 0)
    to_circle = np.arctan2(np.abs(off_plane), _norm(in_plane))
    return np.where(between, np.minimum(to_circle, ends), ends)


def _circle_part_distance(a, b, rho: float) -> np.ndarray:
    """(k,) float: least ``|angle(u, +Y) - rho|`` over the points of arc ``a -> b`` with
    ``x <= 0`` (inf where there are none).

    That part of the arc is one arc; the angle from ``+Y`` is continuous on it, so its range
    is spanned by the values at the part's two ends (arc ends, or points where the great
    circle meets ``x = 0``) and where it is extreme along the great circle. Both ends of the
    part must be among the candidates: with one missing, a part that crosses the circle can
    look as if it stays on one side of it. The arc ends are taken as given, not recomputed,
    and count as on the seam's side within ``_SIDE_SLACK`` of ``x = 0``: a meeting with
    ``x = 0`` at an end of the arc may be found just past that end, and the end is then the
    part's end.
    """
    span = _angle(a, b)
    # u(t) = a cos t + e sin t, 0 <= t <= span, with e the unit tangent at a towards b.
    along = _dot(a, b)
    e = tuple(q - along * p for p, q in zip(a, b, strict=True))
    e_norm = _norm(e)
    with np.errstate(divide="ignore", invalid="ignore"):
        e = tuple(np.where(e_norm > _POINT_ARC, c / e_norm, 0.0) for c in e)
    x_peak = np.arctan2(e[0], a[0])
    y_peak = np.arctan2(e[1], a[1])
    t = np.stack(
        [
            y_peak,
            y_peak + math.pi,
            x_peak + 0.5 * math.pi,  # x(t) = 0 here
            x_peak - 0.5 * math.pi,
        ],
        axis=1,
    ) % (2.0 * math.pi)
    cos_t, sin_t = np.cos(t), np.sin(t)
    u = [p[:, None] * cos_t + q[:, None] * sin_t for p, q in zip(a, e, strict=True)]
    usable = t <= span[:, None]
    usable[:, :2] &= u[0][:, :2] <= 0.0  # x = 0 at the other two: on the side
    usable = np.column_stack([a[0] <= _SIDE_SLACK, b[0] <= _SIDE_SLACK, usable])
    polar = np.column_stack([_polar(a), _polar(b), _polar(u)])
    low = np.where(usable, polar, np.inf).min(axis=1)
    high = np.where(usable, polar, -np.inf).max(axis=1)
    crosses = (low <= rho) & (high >= rho)
    nearest = np.where(usable, np.abs(polar - rho), np.inf).min(axis=1)
    return np.where(crosses, 0.0, nearest)


def _polar(u) -> np.ndarray:
    """The angle of rows ``u`` from ``+Y``."""
    return np.arctan2(np.sqrt(u[0] * u[0] + u[2] * u[2]), u[1])
