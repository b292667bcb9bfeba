"""What every mesh reader returns, the checks they share, and their one error type."""

from __future__ import annotations

from collections.abc import Callable
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
    on_counts : called with the vertex and face counts once they pass the limits, before the
        arrays are built (the service charges its memory budget there); may be called again
        with larger counts, and may raise to refuse the mesh
    """

    max_vertices: int = 5_000_000
    max_faces: int = 5_000_000
    max_bytes: int = 256 * 2**20
    on_counts: Callable[[int, int], None] | None = field(default=None, compare=False)


@dataclass(frozen=True)
class Attributes:
    """What a file says of its vertices and faces besides where they are, in its own order.

    Attributes
    ----------
    colors : (n, 4) float32 RGBA in [0, 1] a vertex, or None (PLY ``red green blue
        alpha``, glTF ``COLOR_0``, OBJ ``v x y z r g b``; alpha 1 where the file has none)
    uv : (k, 2) float64 texture coordinates, or None (glTF ``TEXCOORD_0`` and PLY ``u v``
        a vertex, OBJ ``vt`` lines), in glTF's convention: ``(0, 0)`` the image's top-left
        corner, ``v`` growing down (OBJ's and PLY's ``v``, which grows up, is read as
        ``1 - v``)
    uv_faces : (m, 3) int64, the row of ``uv`` at each face corner (-1: the file gives that
        corner none), or None
    vertex : name -> (n,) float64, numeric values a vertex (PLY scalar vertex properties
        other than the position, the colour and the UVs; glTF attributes such as
        ``_FEATURE_ID_0``)
    face : name -> (m,) float64, numeric values a face (PLY scalar face properties, each
        polygon's value on every triangle it fans into)
    """

    colors: np.ndarray | None = None
    uv: np.ndarray | None = None
    uv_faces: np.ndarray | None = None
    vertex: dict[str, np.ndarray] = field(default_factory=dict)
    face: dict[str, np.ndarray] = field(default_factory=dict)

    def described(self) -> str:
        """What the file has, in words, for a refusal that names it."""
        have = []
        if self.colors is not None:
            have.append("vertex colours")
        if self.uv is not None:
            have.append("texture coordinates")
        have += [f"vertex property {name!r}" for name in self.vertex]
        have += [f"face property {name!r}" for name in self.face]
        return ", ".join(have) if have else "no colours, texture coordinates or properties"


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
    attributes : :class:`Attributes`, the file's colours, texture coordinates and properties
    """

    vertices: np.ndarray
    faces: np.ndarray
    groups: dict[str, np.ndarray] = field(default_factory=dict)
    format: str = ""
    attributes: Attributes = field(default_factory=Attributes)

    def group_faces(self, names: list[str]) -> np.ndarray:
        """Ascending face ids in any of the groups ``names``
        (:func:`transforms.selection.faces_of_groups`: an unknown name is refused, naming
        the groups the file has)."""
        return faces_of_groups(self.groups, names, len(self.faces))


#: Rows of vertices checked at a time (the check's temporaries stay this small).
_CHECK_ROWS = 1 << 16


def out_of_range(vertices: np.ndarray) -> np.ndarray:
    """(n,) bool: the rows of (n, 3) ``vertices`` with a NaN, an Inf or a coordinate beyond
    ``MAX_ABS_COORDINATE``."""
    return ~(np.abs(vertices) <= MAX_ABS_COORDINATE).all(axis=1)  # NaN fails the test too


def vertex_error(first: int, position, count: int, line: int | None = None) -> MeshFormatError:
    """The refusal of ``count`` vertices out of range, the first of them vertex ``first``
    at ``position`` (on 0-based ``line`` of a text file)."""
    where = f" (line {line + 1})" if line is not None else ""
    return MeshFormatError(
        f"vertex {first}{where} has the position {np.asarray(position).tolist()}; coordinates "
        f"must be finite and within +-{MAX_ABS_COORDINATE:g} ({count} vertices are not)"
    )


def checked_vertices(vertices: np.ndarray, file_lines: np.ndarray | None = None) -> np.ndarray:
    """``vertices`` as a contiguous (n, 3) float64 array, refusing a NaN, an Inf or a
    coordinate beyond ``MAX_ABS_COORDINATE``, named by its vertex id (and its line in the
    file, 0-based ``file_lines``, for text formats). Checked a block of rows at a time, so
    the check needs no array as long as ``vertices``."""
    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    first, count = -1, 0
    for start in range(0, len(vertices), _CHECK_ROWS):
        bad = np.flatnonzero(out_of_range(vertices[start : start + _CHECK_ROWS]))
        if bad.size and first < 0:
            first = start + int(bad[0])
        count += len(bad)
    if count:
        line = int(file_lines[first]) if file_lines is not None else None
        raise vertex_error(first, vertices[first], count, line)
    return vertices


def fan_into(out: np.ndarray, items: np.ndarray, corners: np.ndarray) -> None:
    """Write into ``out`` ((sum(corners) - 2 * len(corners), 3) int) the fan triangles of
    polygons ``(a, b, c, d, ...)``: ``(a, b, c), (a, c, d), ...``, polygon after polygon.

    Parameters
    ----------
    items : (sum(corners),) int, the polygons' vertex ids, flat, in order
    corners : (polygons,) int, each polygon's corner count, at least 3
    """
    first = np.cumsum(corners) - corners  # each polygon's first item
    # Column 0 holds each polygon's first corner on all its triangles: a running sum of
    # the changes at the polygons' first triangles, computed in place.
    lead = out[:, 0]
    lead[:] = 0
    lead[np.cumsum(corners - 2) - (corners - 2)] = np.diff(items[first], prepend=0)
    np.cumsum(lead, out=lead)
    # Columns 1 and 2 are the items less each polygon's first and last (first two).
    keep = np.ones(len(items), dtype=bool)
    keep[first] = False
    keep[first + corners - 1] = False
    np.compress(keep, items, out=out[:, 1])
    keep[first + corners - 1] = True
    keep[first + 1] = False
    np.compress(keep, items, out=out[:, 2])


def check_counts(n_vertices: int, n_faces: int, limits: Limits) -> None:
    """Refuse a mesh beyond the vertex or face limit (413), before reading it all; then tell
    ``limits.on_counts``."""
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
    if limits.on_counts is not None:
        limits.on_counts(n_vertices, n_faces)
