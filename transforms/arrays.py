"""Turning caller input into the float64 arrays the transforms work on, or saying why not."""

from __future__ import annotations

import math

import numpy as np

from .checkpoints import checkpoint
from .errors import TransformInputError, listed_rows

#: Largest coordinate magnitude accepted: squares and triple products stay finite.
MAX_ABS_COORDINATE = 1e100


def numeric_array(value, field: str, what: str, kinds: str = "iuf") -> np.ndarray:
    """``value`` as a numpy array of real numbers (dtype kinds ``kinds``), or an error.

    Refuses what numpy would convert quietly or fail on: ragged lists, strings, booleans,
    complex numbers, objects, integers too large for a float.

    Raises
    ------
    TransformInputError
        Naming ``field`` and saying it must be ``what``.
    """
    try:
        array = np.asarray(value)
    except (TypeError, ValueError, OverflowError):
        raise TransformInputError(field, f"must be {what}") from None
    if array.size and array.dtype.kind not in kinds:
        raise TransformInputError(field, f"must be {what}, got {_kind_name(array)}")
    return array


def number(value, field: str) -> float:
    """``value`` as a Python float: a real number, not a string or a boolean.

    Raises
    ------
    TransformInputError
        Not a real number, or too large for a float.
    """
    if isinstance(value, (bool, np.bool_, str, bytes)):
        raise TransformInputError(field, f"must be a number, got {value!r}")
    try:
        return float(value)
    except (TypeError, ValueError):
        raise TransformInputError(field, f"must be a number, got {value!r}") from None
    except OverflowError:
        raise TransformInputError(field, "is too large for a 64-bit float") from None


def _kind_name(array: np.ndarray) -> str:
    names = {"b": "booleans", "c": "complex numbers", "U": "strings", "S": "bytes", "O": "objects"}
    return names.get(array.dtype.kind, str(array.dtype))


def as_points(points, field: str = "points", dims: int = 3) -> np.ndarray:
    """Return ``points`` as a C-contiguous ``(n, dims)`` float64 array of finite coordinates.

    Parameters
    ----------
    points : array_like, (n, dims)
    field : name used in error messages.
    dims : 3 for space, 2 for the map

    Raises
    ------
    TransformInputError
        Wrong shape, a NaN or Inf coordinate, or a magnitude above ``MAX_ABS_COORDINATE``;
        the message lists the offending rows.
    """
    array = numeric_array(points, field, f"an (n, {dims}) array of numbers")
    if array.ndim != 2 or array.shape[1] != dims:
        raise TransformInputError(field, f"must have shape (n, {dims}), got {array.shape}")
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
    return np.ascontiguousarray(array, dtype=np.float64)


def as_vector(vector, field: str) -> np.ndarray:
    """Return ``vector`` as a finite ``(3,)`` float64 array.

    Raises
    ------
    TransformInputError
        Not three finite numbers within ``MAX_ABS_COORDINATE``.
    """
    array = numeric_array(vector, field, "three numbers [x, y, z]").astype(np.float64)
    if array.shape != (3,):
        raise TransformInputError(
            field, f"must be three numbers [x, y, z], got shape {array.shape}"
        )
    if not np.isfinite(array).all() or (np.abs(array) > MAX_ABS_COORDINATE).any():
        raise TransformInputError(
            field, f"must be finite and within +-{MAX_ABS_COORDINATE:g}, got {array.tolist()}"
        )
    return array


def as_direction(vector, field: str) -> np.ndarray:
    """Return the direction of ``vector``, a caller's cone axis, pole or up, as a ``(3,)``
    unit float64 array: the one rule for every direction.

    Accepted when its three numbers are finite (within ``MAX_ABS_COORDINATE``) and not all
    zero. Only the direction matters, so no magnitude is too small: the vector is divided by
    its largest magnitude before its length is taken (:func:`unit_rows`), so the squares
    neither underflow nor overflow, and ``[1e-300, 0, 0]`` and the subnormal
    ``[1e-320, 0, 0]`` are ``[1, 0, 0]`` as exactly as ``[1, 0, 0]`` is.

    Raises
    ------
    TransformInputError
        Not three finite numbers, or all three zero.
    """
    units, zero = unit_rows(as_vector(vector, field)[None, :])
    if zero[0]:
        raise TransformInputError(
            field, "must be a non-zero direction (at least one component not 0), got [0, 0, 0]"
        )
    return units[0]


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
        array = numeric_array(value, name, "a list of numbers")
        arrays[name] = np.atleast_1d(array.astype(np.float64))
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


def unit_rows(vectors: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows of ``vectors`` scaled to unit length, and which rows are zero.

    Each row is divided by its largest magnitude before its length is taken, so neither
    tiny (1e-300) nor huge rows lose precision to underflow or overflow.

    Parameters
    ----------
    vectors : (n, 3) float, finite

    Returns
    -------
    units : (n, 3) float, unit rows (zero rows stay zero)
    zero : (n,) bool
    """
    magnitude = np.abs(vectors)
    largest = np.maximum(np.maximum(magnitude[:, 0], magnitude[:, 1]), magnitude[:, 2])
    zero = largest == 0.0
    scaled = vectors / np.where(zero, 1.0, largest)[:, None]
    return scaled / np.where(zero, 1.0, np.linalg.norm(scaled, axis=1))[:, None], zero


def as_faces(faces, n_vertices: int, field: str = "faces") -> np.ndarray:
    """Return ``faces`` as a C-contiguous ``(m, 3)`` array of vertex indices: int32 when the
    indices fit (half the memory traffic of int64 in every pass over faces), else int64.

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
    array = numeric_array(faces, field, "an (m, 3) array of integer vertex indices", "iu")
    if array.ndim != 2 or array.shape[1] != 3:
        raise TransformInputError(field, f"must have shape (m, 3), got {array.shape}")
    unsigned = np.dtype(f"u{array.dtype.itemsize}")  # negatives become huge: one pass
    if array.size and int(array.view(unsigned).max()) >= n_vertices:
        bad = ((array < 0) | (array >= n_vertices)).any(axis=1)
        text, rows = listed_rows(bad, "face")
        raise TransformInputError(
            field,
            f"{text}: vertex index outside [0, {n_vertices}) (there are {n_vertices} vertices)",
            rows,
        )
    return np.ascontiguousarray(array, dtype=np.int32 if n_vertices < 2**31 else np.int64)


#: The one type of vertex index the numba kernels are compiled for (transforms/kernels.py):
#: half the memory traffic of int64, and every mesh the service admits has fewer than 2^31
#: vertices and half-edges.
INDEX = np.int32

#: Rows handled at a time by the blocked passes: temporaries stay in cache and are reused by
#: the allocator instead of touching fresh pages (see docs/benchmarks.md).
BLOCK_ROWS = 32768


def unit_scale(largest: float) -> float:
    """The power of two that takes ``largest`` (a magnitude) below 1: scaling by it is exact,
    and no square or product of a few scaled coordinates over- or underflows (1 when
    ``largest`` is 0)."""
    return 2.0 ** -math.frexp(largest)[1] if largest > 0 else 1.0


def cross_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise ``a x b`` of (..., 3) arrays that broadcast (``np.cross`` copies its inputs
    and handles axes, which costs more than the products on a few rows)."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


def triangle_areas(points: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(m,) float: the areas of the triangles ``faces`` ((m, 3) int) of ``points`` ((k, 3)),
    half the norm of two sides' cross product.

    Coordinate by coordinate on contiguous (m,) arrays, mostly in place: on a million faces
    this takes about 60 % of the time of gathering (m, 3) corner rows and crossing them."""
    corners = np.ascontiguousarray(np.asarray(faces).T)
    sides = []
    for k in range(3):
        c = np.ascontiguousarray(points[:, k])[corners]  # (3, m)
        sides.append((c[1] - c[0], c[2] - c[0]))
    (ux, vx), (uy, vy), (uz, vz) = sides
    nx, ny, nz = uy * vz, uz * vx, ux * vy  # the cross product, then its squared norm
    nx -= uz * vy
    ny -= ux * vz
    nz -= uy * vx
    nx *= nx
    nx += ny * ny
    nx += nz * nz
    np.sqrt(nx, out=nx)
    nx *= 0.5
    return nx


def face_cross(points: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(m, 3) float: each triangle's sides' cross product ``(p1 - p0) x (p2 - p0)``: its normal
    following the winding, twice its area long."""
    corners = points[faces]
    return cross_rows(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])


def combine(values: np.ndarray, faces: np.ndarray, triangles, weights) -> np.ndarray:
    """(p, d) float: the corners' ``values`` ((k, d), per vertex) of ``faces[triangles]``
    combined with barycentric ``weights`` ((p, 3))."""
    return np.einsum("pk,pkd->pd", weights, values[faces[triangles]])


def blocks(n: int, size: int | None = None):
    """Slices ``[start, stop)`` covering ``range(n)`` in steps of ``size`` (``BLOCK_ROWS``),
    each after a :func:`~transforms.checkpoints.checkpoint`."""
    size = size or BLOCK_ROWS
    for start in range(0, n, size):
        checkpoint()
        yield slice(start, min(start + size, n))


#: A 2 x 2 matrix whose determinant is below this share of its squared size is solved by the
#: pseudo-inverse (a triangle of no area, on the map or on the surface).
SINGULAR = 1e-12


def solve_2x2(matrices: np.ndarray, right: np.ndarray) -> np.ndarray:
    """(p, 2) float: ``A^-1 b`` for (p, 2, 2) ``matrices`` and (p, 2) ``right``, in closed
    form (a hundred times numpy's batched pseudo-inverse), by the pseudo-inverse where ``A``
    is near singular."""
    a, b = matrices[:, 0, 0], matrices[:, 0, 1]
    c, d = matrices[:, 1, 0], matrices[:, 1, 1]
    det = a * d - b * c
    size = np.einsum("pij,pij->p", matrices, matrices)
    regular = np.abs(det) > SINGULAR * size
    out = np.empty_like(right)
    safe = np.where(regular, det, 1.0)
    out[:, 0] = (d * right[:, 0] - b * right[:, 1]) / safe
    out[:, 1] = (a * right[:, 1] - c * right[:, 0]) / safe
    if not regular.all():
        with np.errstate(divide="ignore", invalid="ignore"):
            pseudo = np.linalg.pinv(matrices[~regular])
        out[~regular] = np.einsum("pij,pj->pi", pseudo, right[~regular])
    return out


def triangle_boxes(vertices: np.ndarray, faces: np.ndarray, pad: float = 0.0):
    """(m, 3) float each: the least and the largest corner coordinates of the triangles
    ``faces`` ((m, 3) int) of ``vertices`` ((k, 3) float), less and plus ``pad``."""
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    return np.minimum(np.minimum(a, b), c) - pad, np.maximum(np.maximum(a, b), c) + pad
