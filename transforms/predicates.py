"""Exact orientation signs: on which side of a plane through the centre a point lies (used by
the exact ray-triangle test and the back-facing test, docs/math.md, section 6).

``orient3d_sign(a, b, c)`` is the sign of ``det[a, b, c] = a . (b x c)`` computed exactly for
any finite float64 input. Each vector is first scaled by a power of two to a largest component
in ``[0.5, 1)`` (the determinant is linear in each vector, so its sign is unchanged, and no
product can overflow); a floating-point filter with a proven error bound then decides almost
every row, and the few rows too close to call are recomputed from the original values with
integers (every float is an integer times a power of two).
"""

from __future__ import annotations

import numpy as np

from .errors import TransformInputError

EPSILON = 2.0**-53
#: |computed - exact| <= _ERROR_BOUND * permanent for the 3x3 determinant below (two products,
#: a difference, a product and a sum of three: at most 6 roundings; margin to 8).
_ERROR_BOUND = 8.0 * EPSILON
#: Covers products that underflow (each off by at most 2^-1074) and components flushed to zero
#: by the scaling; with every entry below 1 their effect on the determinant is far smaller.
_ABSOLUTE_SLACK = 1e-290


def orient3d_sign(a, b, c) -> np.ndarray:
    """The exact sign of ``det[a, b, c]`` (rows of three vectors), for every row.

    Parameters
    ----------
    a, b, c : (n, 3) or (3,) float, finite, broadcast against each other

    Returns
    -------
    (n,) int8 in {-1, 0, 1}: +1 when ``a, b, c`` form a right-handed triple

    Raises
    ------
    TransformInputError
        A NaN or Inf entry.
    """
    a, b, c = np.broadcast_arrays(
        np.atleast_2d(np.asarray(a, dtype=np.float64)),
        np.atleast_2d(np.asarray(b, dtype=np.float64)),
        np.atleast_2d(np.asarray(c, dtype=np.float64)),
    )
    if not (np.isfinite(a).all() and np.isfinite(b).all() and np.isfinite(c).all()):
        raise TransformInputError("points", "orientation needs finite coordinates")
    return orient3d_sign_components(
        a[:, 0], a[:, 1], a[:, 2], b[:, 0], b[:, 1], b[:, 2], c[:, 0], c[:, 1], c[:, 2]
    )


def orient3d_sign_components(ax, ay, az, bx, by, bz, cx, cy, cz) -> np.ndarray:
    """:func:`orient3d_sign` on coordinate rows (each ``(n,)`` float or a scalar, finite)."""
    original = np.broadcast_arrays(
        *(np.asarray(v, dtype=np.float64) for v in (ax, ay, az, bx, by, bz, cx, cy, cz))
    )
    shape = np.atleast_1d(original[0]).shape
    original = [np.atleast_1d(v) for v in original]
    (ax, ay, az), (bx, by, bz), (cx, cy, cz) = (
        _scaled(*original[i : i + 3]) for i in range(0, 9, 3)
    )
    m1, m2 = by * cz, bz * cy
    m3, m4 = bz * cx, bx * cz
    m5, m6 = bx * cy, by * cx
    det = ax * (m1 - m2) + ay * (m3 - m4) + az * (m5 - m6)
    permanent = (
        np.abs(ax) * (np.abs(m1) + np.abs(m2))
        + np.abs(ay) * (np.abs(m3) + np.abs(m4))
        + np.abs(az) * (np.abs(m5) + np.abs(m6))
    )
    sign = np.sign(det).astype(np.int8).reshape(shape)
    unsure = np.abs(det) <= _ERROR_BOUND * permanent + _ABSOLUTE_SLACK
    if unsure.any():
        rows = np.flatnonzero(unsure)
        sign[rows] = _exact_sign(np.stack([v[rows] for v in original], axis=1))
    return sign


def _scaled(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, ...]:
    """The vector rows scaled by powers of two to a largest magnitude in [0.5, 1) (zero rows
    stay zero)."""
    largest = np.maximum(np.maximum(np.abs(x), np.abs(y)), np.abs(z))
    exponent = np.frexp(largest)[1]
    return tuple(np.ldexp(v, -exponent) for v in (x, y, z))


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
