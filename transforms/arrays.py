"""Turning caller input into the float64 arrays the transforms work on, or saying why not."""

from __future__ import annotations

import numpy as np

from .errors import TransformInputError, listed_rows

#: Largest coordinate magnitude accepted: squares and triple products stay finite.
MAX_ABS_COORDINATE = 1e100


def as_points(points, field: str = "points") -> np.ndarray:
    """Return ``points`` as a C-contiguous ``(n, 3)`` float64 array of finite coordinates.

    Parameters
    ----------
    points : array_like, (n, 3)
    field : name used in error messages.

    Raises
    ------
    TransformInputError
        Wrong shape, a NaN or Inf coordinate, or a magnitude above ``MAX_ABS_COORDINATE``;
        the message lists the offending rows.
    """
    try:
        array = np.ascontiguousarray(points, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TransformInputError(field, f"must be an (n, 3) array of numbers ({exc})") from None
    if array.ndim != 2 or array.shape[1] != 3:
        raise TransformInputError(field, f"must have shape (n, 3), got {array.shape}")
    # One pass on the happy path: NaN fails the comparison, Inf exceeds the bound.
    if not (np.abs(array) <= MAX_ABS_COORDINATE).all():
        finite = np.isfinite(array).all(axis=1)
        if not finite.all():
            text, rows = listed_rows(~finite)
            raise TransformInputError(field, f"NaN or Inf coordinate in {text}", rows)
        text, rows = listed_rows((np.abs(array) > MAX_ABS_COORDINATE).any(axis=1))
        raise TransformInputError(
            field, f"coordinate beyond +-{MAX_ABS_COORDINATE:g} in {text}", rows
        )
    return array


def as_vector(vector, field: str) -> np.ndarray:
    """Return ``vector`` as a finite ``(3,)`` float64 array.

    Raises
    ------
    TransformInputError
        Not three finite numbers within ``MAX_ABS_COORDINATE``.
    """
    try:
        array = np.asarray(vector, dtype=np.float64)
    except (TypeError, ValueError):
        raise TransformInputError(field, "must be three numbers [x, y, z]") from None
    if array.shape != (3,):
        raise TransformInputError(
            field, f"must be three numbers [x, y, z], got shape {array.shape}"
        )
    if not np.isfinite(array).all() or (np.abs(array) > MAX_ABS_COORDINATE).any():
        raise TransformInputError(
            field, f"must be finite and within +-{MAX_ABS_COORDINATE:g}, got {array.tolist()}"
        )
    return array


def as_angles(theta, phi, r=1.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Check spherical coordinates and broadcast them to three ``(n,)`` float64 arrays.

    Parameters
    ----------
    theta : (n,) float, polar angle in ``[0, pi]``
    phi : (n,) float, azimuth in ``[-pi, pi]``
    r : (n,) float or scalar, distance from the centre, ``>= 0``

    Raises
    ------
    TransformInputError
        Lengths differ, a value is not finite, or an angle or distance is out of range.
    """
    arrays = {}
    for name, value in (("theta", theta), ("phi", phi), ("r", r)):
        try:
            arrays[name] = np.atleast_1d(np.asarray(value, dtype=np.float64))
        except (TypeError, ValueError):
            raise TransformInputError(name, "must be a list of numbers") from None
        if arrays[name].ndim != 1:
            raise TransformInputError(
                name, f"must be one-dimensional, got shape {arrays[name].shape}"
            )
    try:
        theta_b, phi_b, r_b = np.broadcast_arrays(arrays["theta"], arrays["phi"], arrays["r"])
    except ValueError:
        lengths = {name: len(a) for name, a in arrays.items()}
        raise TransformInputError(
            "theta", f"theta, phi and r must have one length, got {lengths}"
        ) from None
    limits = (
        ("theta", theta_b, 0.0, np.pi, "[0, pi]"),
        ("phi", phi_b, -np.pi, np.pi, "[-pi, pi]"),
        ("r", r_b, 0.0, MAX_ABS_COORDINATE, f"[0, {MAX_ABS_COORDINATE:g}]"),
    )
    for name, values, low, high, shown in limits:
        bad = ~((values >= low) & (values <= high))  # NaN fails both comparisons
        if bad.any():
            text, rows = listed_rows(bad)
            raise TransformInputError(name, f"not finite or outside {shown} at {text}", rows)
    return (
        np.ascontiguousarray(theta_b, dtype=np.float64),
        np.ascontiguousarray(phi_b, dtype=np.float64),
        np.ascontiguousarray(r_b, dtype=np.float64),
    )


def as_faces(faces, n_vertices: int, field: str = "faces") -> np.ndarray:
    """Return ``faces`` as a C-contiguous ``(m, 3)`` int64 array of vertex indices.

    Parameters
    ----------
    faces : array_like of int, (m, 3)
    n_vertices : int, number of vertices the indices refer to

    Raises
    ------
    TransformInputError
        Wrong shape, non-integer entries, or an index outside ``[0, n_vertices)``; the message
        lists the offending faces.
    """
    array = np.asarray(faces)
    if array.ndim != 2 or array.shape[1] != 3:
        raise TransformInputError(field, f"must have shape (m, 3), got {array.shape}")
    if array.size and not np.issubdtype(array.dtype, np.integer):
        raise TransformInputError(field, f"must hold integer vertex indices, got {array.dtype}")
    array = np.ascontiguousarray(array, dtype=np.int64)
    if array.size and (array.min() < 0 or array.max() >= n_vertices):
        bad = ((array < 0) | (array >= n_vertices)).any(axis=1)
        text, rows = listed_rows(bad, "face")
        raise TransformInputError(
            field,
            f"{text}: vertex index outside [0, {n_vertices}) (there are {n_vertices} vertices)",
            rows,
        )
    return array


#: Rows handled at a time by the blocked passes: temporaries stay in cache and are reused by
#: the allocator instead of touching fresh pages (see docs/benchmarks.md).
BLOCK_ROWS = 32768


def blocks(n: int, size: int | None = None):
    """Slices ``[start, stop)`` covering ``range(n)`` in steps of ``size`` (``BLOCK_ROWS``)."""
    size = size or BLOCK_ROWS
    for start in range(0, n, size):
        yield slice(start, min(start + size, n))
