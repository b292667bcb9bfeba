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
            return _load(data, limits)
    if not re.match(rb"\s*solid", data[:1024]):
        raise MeshFormatError(
            "not an STL file: neither a binary STL (80-byte header, count, 50 bytes per "
            "triangle) nor ASCII ('solid ...')"
        )
    triangles = data.count(b"facet normal")
    check_counts(3 * triangles, triangles, limits)
    return _load(data, limits)


def _load(data: bytes, limits: Limits) -> Mesh:
    try:
        # A nameless BytesIO: trimesh cannot look for sibling files.
        mesh = trimesh.load(io.BytesIO(data), file_type="stl", process=False, force="mesh")
    except Exception as exc:  # trimesh raises many types for malformed files
        raise MeshFormatError(f"could not read the STL file: {exc}") from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise MeshFormatError("the STL file holds no triangles")
    faces = np.ascontiguousarray(mesh.faces, dtype=np.int64)
    check_counts(len(mesh.vertices), len(faces), limits)
    if faces.min() < 0 or faces.max() >= len(mesh.vertices):
        raise MeshFormatError("the STL file has faces referring to missing vertices")
    return Mesh(vertices=checked_vertices(mesh.vertices), faces=faces, format="stl")
