"""What every mesh reader returns, the checks they share, and their one error type."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from transforms import MAX_ABS_COORDINATE
from transforms.selection import faces_of_groups


class MeshFormatError(ValueError):
    """The uploaded file cannot be read as a mesh; the message says where and why."""


class MeshTooLargeError(MeshFormatError):
    """The file, a buffer in it, or its vertex or face count is beyond a limit; the message
    names the limit."""


@dataclass(frozen=True)
class Limits:
    """How much of a mesh the service reads.

    Attributes
    ----------
    max_vertices, max_faces : int
    max_bytes : int, the largest file (and largest decoded buffer) accepted
    """

    max_vertices: int = 5_000_000
    max_faces: int = 5_000_000
    max_bytes: int = 256 * 2**20


@dataclass(frozen=True)
class Mesh:
    """A triangle mesh in the file's own order.

    Attributes
    ----------
    vertices : (n, 3) float, finite, within ``MAX_ABS_COORDINATE``
    faces : (m, 3) int, vertex ids; face ``i`` is the file's ``i``-th triangle
    groups : name -> (k, 2) int ranges ``[start, stop)`` of face ids (OBJ g/o/usemtl names,
        glTF mesh and node names); ranges, not ids, so a name on many faces costs nothing
        until a request asks for it
    format : str, the reader that produced it
    """

    vertices: np.ndarray
    faces: np.ndarray
    groups: dict[str, np.ndarray] = field(default_factory=dict)
    format: str = ""

    def group_faces(self, names: list[str]) -> np.ndarray:
        """Ascending face ids in any of the groups ``names``
        (:func:`transforms.selection.faces_of_groups`: an unknown name is refused, naming
        the groups the file has)."""
        return faces_of_groups(self.groups, names, len(self.faces))


def checked_vertices(vertices: np.ndarray, file_lines: np.ndarray | None = None) -> np.ndarray:
    """``vertices`` as a contiguous (n, 3) float64 array, refusing a NaN, an Inf or a
    coordinate beyond ``MAX_ABS_COORDINATE``, named by its vertex id (and its line in the
    file, 0-based ``file_lines``, for text formats)."""
    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    bad = ~(np.abs(vertices) <= MAX_ABS_COORDINATE).all(axis=1)  # NaN fails the test too
    if bad.any():
        first = int(np.flatnonzero(bad)[0])
        where = f" (line {file_lines[first] + 1})" if file_lines is not None else ""
        raise MeshFormatError(
            f"vertex {first}{where} has the position {vertices[first].tolist()}; coordinates "
            f"must be finite and within +-{MAX_ABS_COORDINATE:g} ({int(bad.sum())} vertices "
            "are not)"
        )
    return vertices


def fan_triangles(items: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """(sum(corners) - 2 * len(corners), 3) int: polygon ``(a, b, c, d, ...)`` becomes
    ``(a, b, c), (a, c, d), ...``, polygon after polygon.

    Parameters
    ----------
    items : (sum(corners),) int, the polygons' vertex ids, flat, in order
    corners : (polygons,) int, each polygon's corner count, at least 3
    """
    triangles = corners - 2
    first_corner = np.concatenate(([0], np.cumsum(corners)[:-1]))
    polygon = np.repeat(np.arange(len(corners)), triangles)
    step = np.arange(len(polygon)) - np.repeat(np.cumsum(triangles) - triangles, triangles)
    base = first_corner[polygon]
    return np.stack([items[base], items[base + step + 1], items[base + step + 2]], axis=1)


def check_counts(n_vertices: int, n_faces: int, limits: Limits) -> None:
    """Refuse a mesh beyond the vertex or face limit (413), before reading it all."""
    if n_vertices > limits.max_vertices:
        raise MeshTooLargeError(
            f"the file has {n_vertices:,} vertices; the limit is {limits.max_vertices:,} "
            "(MESHFLAT_MAX_VERTICES)"
        )
    if n_faces > limits.max_faces:
        raise MeshTooLargeError(
            f"the file has {n_faces:,} triangles; the limit is {limits.max_faces:,} "
            "(MESHFLAT_MAX_FACES)"
        )
