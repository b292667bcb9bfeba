"""STL, binary or ASCII, read by trimesh after the triangle count is checked against the bytes
and the limits (so a lying header cannot make it allocate more than the file holds)."""

from __future__ import annotations

import io
import re
import struct

import numpy as np
import trimesh

from .mesh import Limits, Mesh, MeshFormatError, check_counts, checked_vertices


def read_stl(data: bytes, limits: Limits) -> Mesh:
    """An STL file. STL stores every triangle with its own three corners; they are kept
    (nothing is merged), so vertex ``3 i + k`` is corner ``k`` of triangle ``i``."""
    if len(data) >= 84:
        (count,) = struct.unpack_from("<I", data, 80)
        if len(data) == 84 + 50 * count:  # binary
            check_counts(3 * count, count, limits)
            return _checked(_load(data, "stl"), limits, "stl")
    if not re.match(rb"\s*solid", data[:1024]):
        raise MeshFormatError(
            "not an STL file: neither a binary STL (80-byte header, count, 50 bytes per "
            "triangle) nor ASCII ('solid ...')"
        )
    triangles = data.count(b"facet normal")
    check_counts(3 * triangles, triangles, limits)
    return _checked(_load(data, "stl"), limits, "stl")


def _load(data: bytes, file_type: str) -> trimesh.Trimesh:
    try:
        # A nameless BytesIO: trimesh cannot look for sibling files.
        mesh = trimesh.load(io.BytesIO(data), file_type=file_type, process=False, force="mesh")
    except Exception as exc:  # trimesh raises many types for malformed files
        raise MeshFormatError(f"could not read the {file_type.upper()} file: {exc}") from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise MeshFormatError(f"the {file_type.upper()} file holds no triangles")
    return mesh


def _checked(mesh: trimesh.Trimesh, limits: Limits, fmt: str) -> Mesh:
    faces = np.ascontiguousarray(mesh.faces, dtype=np.int64)
    check_counts(len(mesh.vertices), len(faces), limits)
    if faces.size and (faces.min() < 0 or faces.max() >= len(mesh.vertices)):
        raise MeshFormatError(f"the {fmt.upper()} file has faces referring to missing vertices")
    return Mesh(vertices=checked_vertices(mesh.vertices), faces=faces, format=fmt)
