"""What every mesh reader returns, the limits they enforce, and their one error type."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


class MeshFormatError(ValueError):
    """The uploaded file cannot be read as a mesh; the message says where and why.

    Attributes
    ----------
    status : int, the HTTP status to answer with (422, or 413 for a limit)
    """

    def __init__(self, message: str, status: int = 422) -> None:
        super().__init__(message)
        self.status = status


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
    vertices : (n, 3) float, finite
    faces : (m, 3) int, vertex ids; face ``i`` is the file's ``i``-th triangle
    groups : name -> ascending face ids (OBJ g/o/usemtl names, glTF mesh and node names)
    format : str, the reader that produced it
    """

    vertices: np.ndarray
    faces: np.ndarray
    groups: dict[str, np.ndarray] = field(default_factory=dict)
    format: str = ""


def check_counts(n_vertices: int, n_faces: int, limits: Limits) -> None:
    """Refuse a mesh beyond the vertex or face limit (413), before reading it all."""
    if n_vertices > limits.max_vertices:
        raise MeshFormatError(
            f"the file has {n_vertices:,} vertices; the limit is {limits.max_vertices:,} "
            "(MESHFLAT_MAX_VERTICES)",
            status=413,
        )
    if n_faces > limits.max_faces:
        raise MeshFormatError(
            f"the file has {n_faces:,} triangles; the limit is {limits.max_faces:,} "
            "(MESHFLAT_MAX_FACES)",
            status=413,
        )
