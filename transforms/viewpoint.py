"""Whether a region has any area seen from a centre.

A face whose plane holds the centre is seen edge-on: its corners' directions lie on one great
circle, so in the chart it has no area. When that is true of every face with area (a flat
region seen from a point of its own plane: its centroid always is one, its bounding-box
centre is one when the plane is a plane of the axes or the region is symmetric in it, and
so is any point of its surface), nothing can be mapped, and the centre is at fault, not
the faces. A region whose faces have no area in 3D is a different fault, named by the
faces (:func:`.fit.kernel.kernel_planes`, :mod:`.metrics`).
"""

from __future__ import annotations

import math

import numpy as np

from .errors import TransformInputError, listed_rows
from .faces import DEGENERATE_RTOL
from .predicates import EPSILON
from .spherical import MIN_RADIUS

#: A face is seen edge-on when the centre's distance to its plane is at most
#: ``DEGENERATE_RTOL`` of the centre's distance to the face (a face so nearly edge-on is
#: squashed flat in the layout too) or what rounding of the mesh's coordinates explains:
#: ``_ROUNDING`` times the face's largest coordinate, amplified by the ratio of that distance
#: to the face's least height (a tilted normal swings the plane by that much). Measured on
#: rotated, moved and scaled flat grids, rounding stays below a third of it.
_ROUNDING = 16.0 * EPSILON

#: Faces looked at first; the count doubles up to ``_LARGEST_BLOCK`` while every face looked
#: at is edge-on (a region seen at all is usually decided by its first face).
_FIRST_BLOCK = 256
_LARGEST_BLOCK = 16384


def check_center_sees_area(vertices: np.ndarray, faces: np.ndarray, center: np.ndarray) -> None:
    """Refuse a centre from which every face of the region that has area is seen edge-on.

    Parameters
    ----------
    vertices : (n, 3) float, finite, world (or local) coordinates
    faces : (m, 3) int, indices into ``vertices``, in range
    center : (3,) float, finite, in the same coordinates

    Raises
    ------
    TransformInputError
        Naming ``center``, with a point off the region's plane to use instead. A region with
        no face of any area passes (its faces are named where the area is needed).
    """
    center = np.asarray(center, dtype=np.float64)
    start, size, normal = 0, _FIRST_BLOCK, None
    while start < len(faces):
        seen, block_normal = _seen_faces(vertices, faces[start : start + size], center)
        if seen:
            return
        normal = block_normal if normal is None else normal
        start, size = start + size, min(2 * size, _LARGEST_BLOCK)
    if normal is not None:
        message, on_vertices = _in_plane_message(vertices, faces, center, normal)
        raise TransformInputError("center", message, on_vertices)


def _seen_faces(
    vertices: np.ndarray, faces: np.ndarray, center: np.ndarray
) -> tuple[bool, np.ndarray | None]:
    """Whether any of ``faces`` is seen from ``center`` other than edge-on, and the normal of
    the largest face with area (None: no face has area)."""
    corners = np.ascontiguousarray(vertices[faces].transpose(2, 1, 0))  # (axis, corner, face)
    largest = max(float(np.abs(corners).max()), float(np.abs(center).max()))
    if largest == 0.0:
        return False, None
    # A power of two taking every coordinate below 1: exact, and no product over- or
    # underflows for coordinates within MAX_ABS_COORDINATE of each other.
    scale = 2.0 ** -math.frexp(largest)[1]
    corners *= scale
    e1 = corners[:, 1] - corners[:, 0]
    e2 = corners[:, 2] - corners[:, 0]
    normal = np.stack(
        [e1[(i + 1) % 3] * e2[(i + 2) % 3] - e1[(i + 2) % 3] * e2[(i + 1) % 3] for i in range(3)]
    )
    double_area = np.sqrt((normal * normal).sum(axis=0))
    squares = [(e * e).sum(axis=0) for e in (e1, e2, corners[:, 2] - corners[:, 1])]
    has_area = double_area > DEGENERATE_RTOL * (squares[0] + squares[1])
    if not has_area.any():
        return False, None
    keep = np.flatnonzero(has_area)
    normal, double_area, corners = normal[:, keep], double_area[keep], corners[:, :, keep]
    longest = np.sqrt(np.maximum(np.maximum(squares[0], squares[1]), squares[2])[keep])
    offsets = corners - (center * scale)[:, None, None]
    distance = np.abs((normal * offsets[:, 0]).sum(axis=0)) / double_area
    reach = np.sqrt((offsets * offsets).sum(axis=0).max(axis=0))
    # The mesh's own coordinates, not the centre's: a flat mesh is flat to their rounding.
    magnitude = np.abs(corners).max(axis=(0, 1))
    least_height = double_area / longest
    edge_on = DEGENERATE_RTOL * reach + _ROUNDING * magnitude * (1.0 + reach / least_height)
    return bool((distance > edge_on).any()), normal[:, int(np.argmax(double_area))]


def _in_plane_message(
    vertices: np.ndarray, faces: np.ndarray, center: np.ndarray, normal: np.ndarray
) -> tuple[str, list[int]]:
    """Why the centre sees no area, with the region's vertices it lies on (their rows), and
    a centre that would see it: off the plane of ``normal`` (a face's), on the side it turns
    away from, by half the region's size."""
    used = np.zeros(len(vertices), dtype=bool)
    used[faces.ravel()] = True
    points = vertices[used]
    low, high = points.min(axis=0), points.max(axis=0)
    scale = 2.0 ** -math.frexp(float(np.abs(points).max()))[1]  # no square overflows
    half_size = np.linalg.norm((high - low) * scale) / (2.0 * scale)
    away = -normal / np.linalg.norm(normal) * half_size
    suggestion = ", ".join(f"{value:.6g}" for value in low / 2.0 + high / 2.0 + away)
    shown = ", ".join(f"{value:.6g}" for value in center)
    at_centre = np.zeros(len(vertices), dtype=bool)
    at_centre[used] = np.linalg.norm(points - center, axis=1) < MIN_RADIUS
    on_vertices, rows = "", []
    if at_centre.any():
        text, rows = listed_rows(at_centre, "vertex")
        on_vertices = f" (here on {text})"
    message = (
        f"the centre [{shown}] lies in the plane of every face of the region, as when the "
        f"region is flat and the centre is in its plane or on its surface{on_vertices}, so "
        "every face is seen edge-on and the region has no area seen from it; move the centre "
        f"off that plane, for example to [{suggestion}]"
    )
    return message, rows
