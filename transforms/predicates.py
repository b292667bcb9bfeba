"""Exact orientation signs: which side of a plane through the centre a point lies on.

``orient3d_sign(a, b, c)`` is the sign of ``det[a, b, c] = a . (b x c)`` computed exactly for
float64 input: a floating-point filter with a proven error bound decides almost every row, and
the few rows too close to call are recomputed with integers (every float is an integer times a
power of two, so the determinant of the scaled integers has the same sign).
"""

from __future__ import annotations

import numpy as np

_EPSILON = 2.0**-53
#: |computed - exact| <= _ERROR_BOUND * permanent for the 3x3 determinant below (two products,
#: a difference, a product and a sum of three: at most 6 roundings; margin to 8).
_ERROR_BOUND = 8.0 * _EPSILON
#: Below this permanent the products may be subnormal and the bound no longer holds.
_TINY = 1e-280


def orient3d_sign(a, b, c) -> np.ndarray:
    """The exact sign of ``det[a, b, c]`` (rows of three vectors), for every row.

    Parameters
    ----------
    a, b, c : (n, 3) or (3,) float, broadcast against each other

    Returns
    -------
    (n,) int8 in {-1, 0, 1}: +1 when ``a, b, c`` form a right-handed triple
    """
    a, b, c = np.broadcast_arrays(
        np.atleast_2d(np.asarray(a, dtype=np.float64)),
        np.atleast_2d(np.asarray(b, dtype=np.float64)),
        np.atleast_2d(np.asarray(c, dtype=np.float64)),
    )
    return orient3d_sign_components(
        a[:, 0], a[:, 1], a[:, 2], b[:, 0], b[:, 1], b[:, 2], c[:, 0], c[:, 1], c[:, 2]
    )


def orient3d_sign_components(ax, ay, az, bx, by, bz, cx, cy, cz) -> np.ndarray:
    """:func:`orient3d_sign` on coordinate rows (each ``(n,)`` float or a scalar)."""
    m1, m2 = by * cz, bz * cy
    m3, m4 = bz * cx, bx * cz
    m5, m6 = bx * cy, by * cx
    det = ax * (m1 - m2) + ay * (m3 - m4) + az * (m5 - m6)
    permanent = (
        np.abs(ax) * (np.abs(m1) + np.abs(m2))
        + np.abs(ay) * (np.abs(m3) + np.abs(m4))
        + np.abs(az) * (np.abs(m5) + np.abs(m6))
    )
    sign = np.sign(det).astype(np.int8)
    # A tiny permanent (products near or below the subnormal range) voids the bound.
    unsure = (np.abs(det) <= _ERROR_BOUND * permanent) | (permanent < _TINY)
    if unsure.any():
        rows = np.flatnonzero(np.broadcast_to(unsure, sign.shape))
        parts = [np.broadcast_to(v, sign.shape)[rows] for v in (ax, ay, az, bx, by, bz, cx, cy, cz)]
        sign[rows] = _exact_sign(np.stack(parts, axis=1))
    return sign


def _exact_sign(entries: np.ndarray) -> np.ndarray:
    """Exact sign of ``det`` for rows ``[ax, ay, az, bx, by, bz, cx, cy, cz]`` (k, 9).

    Each float is ``mantissa * 2**exponent`` with an integer 53-bit mantissa; shifting every
    entry of a row to the row's smallest exponent gives integers whose determinant has the
    sign of the real one. Python integers do the arithmetic, vectorised as object arrays.
    """
    fraction, exponent = np.frexp(entries)
    mantissa = (fraction * 2.0**53).astype(np.int64)  # exact: fraction has 53 bits
    exponent = exponent.astype(np.int64) - 53
    shift = exponent - exponent.min(axis=1, keepdims=True)
    v = np.left_shift(mantissa.astype(object), shift.astype(object))
    ax, ay, az, bx, by, bz, cx, cy, cz = v.T
    det = ax * (by * cz - bz * cy) + ay * (bz * cx - bx * cz) + az * (bx * cy - by * cx)
    return (det > 0).astype(np.int8) - (det < 0).astype(np.int8)
