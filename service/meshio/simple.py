"""PLY and STL, read by trimesh after their declared sizes are checked against the bytes and
the limits (so a lying header cannot make it allocate more than the file holds)."""

from __future__ import annotations

import io
import re
import struct

import numpy as np
import trimesh

from .mesh import Limits, Mesh, MeshFormatError, check_counts

_PLY_SIZES = {
    "char": 1, "uchar": 1, "int8": 1, "uint8": 1,
    "short": 2, "ushort": 2, "int16": 2, "uint16": 2,
    "int": 4, "uint": 4, "int32": 4, "uint32": 4, "float": 4, "float32": 4,
    "double": 8, "float64": 8,
}  # fmt: skip


def read_ply(data: bytes, limits: Limits) -> Mesh:
    """A PLY file (ASCII or binary); polygons are split into triangles in order."""
    end = data.find(b"end_header")
    if not data.startswith(b"ply") or end < 0:
        raise MeshFormatError("not a PLY file: no 'ply' ... 'end_header' header")
    header = data[:end].decode("ascii", "replace").splitlines()
    fmt = None
    elements: list[tuple[str, int, list[list[str]]]] = []
    for line in header:
        words = line.split()
        if words[:1] == ["format"] and len(words) >= 2:
            fmt = fmt or words[1]
        elif words[:1] == ["element"] and len(words) == 3 and words[2].isdigit():
            elements.append((words[1], int(words[2]), []))
        elif words[:1] == ["property"] and elements:
            if len(words) < 3 or (words[1] == "list" and len(words) < 5):
                raise MeshFormatError(f"the PLY header line {line.strip()!r} is incomplete")
            elements[-1][2].append(words[1:])
    counts = {name: count for name, count, _ in elements}
    check_counts(counts.get("vertex", 0), counts.get("face", 0), limits)
    if fmt and fmt.startswith("binary"):
        body = len(data) - (data.find(b"\n", end) + 1)
        needed = 0
        for _, count, properties in elements:
            row = 0
            for prop in properties:
                if prop[0] == "list":  # a count and at least three indices
                    row += _PLY_SIZES.get(prop[1], 1) + 3 * _PLY_SIZES.get(prop[2], 4)
                else:
                    row += _PLY_SIZES.get(prop[0], 4)
            needed += row * count
        if needed > body:
            raise MeshFormatError(
                f"the PLY header declares at least {needed:,} bytes of data but the file holds "
                f"{body:,}"
            )
    return _checked(_load(data, "ply"), limits, "ply")


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
    vertices = np.ascontiguousarray(mesh.vertices, dtype=np.float64)
    faces = np.ascontiguousarray(mesh.faces, dtype=np.int64)
    check_counts(len(vertices), len(faces), limits)
    if faces.size and (faces.min() < 0 or faces.max() >= len(vertices)):
        raise MeshFormatError(f"the {fmt.upper()} file has faces referring to missing vertices")
    finite = np.isfinite(vertices).all(axis=1)
    if not finite.all():
        raise MeshFormatError(f"vertex {int(np.flatnonzero(~finite)[0])} has a NaN or Inf position")
    return Mesh(vertices=vertices, faces=faces, groups={}, format=fmt)
