"""Reading uploaded mesh files from memory: OBJ, glTF, GLB, PLY, STL.

Only the uploaded bytes are read (never a file or URL they refer to), and the file's own
order is kept: vertex ``i`` and face ``i`` are the file's ``i``-th vertex and triangle.
"""

from __future__ import annotations

from .gltf import read_glb, read_gltf
from .mesh import Limits, Mesh, MeshFormatError
from .obj import read_obj
from .ply import read_ply
from .stl import read_stl

READERS = {
    "obj": read_obj,
    "gltf": read_gltf,
    "glb": read_glb,
    "ply": read_ply,
    "stl": read_stl,
}

__all__ = ["READERS", "Limits", "Mesh", "MeshFormatError", "format_of", "read_mesh"]


def format_of(filename: str | None, declared: str | None) -> str:
    """The format to read: ``declared`` when given, else the file name's extension.

    Raises
    ------
    MeshFormatError
        Neither names a supported format.
    """
    supported = ", ".join(READERS)
    if declared:
        fmt = declared.lower().lstrip(".")
        if fmt not in READERS:
            raise MeshFormatError(f"format {declared!r} is not one of {supported}")
        return fmt
    if not filename:
        raise MeshFormatError(
            f"the file part has no file name to tell its format by: send one ending in one "
            f"of {supported}, or set params.format"
        )
    extension = filename.rsplit(".", 1)[-1].lower() if "." in filename else ""
    if extension not in READERS:
        raise MeshFormatError(
            f"cannot tell the format of {filename!r}: name the file with one of the "
            f"extensions {supported}, or set params.format"
        )
    return extension


def read_mesh(data: bytes, fmt: str, limits: Limits) -> Mesh:
    """Read a mesh of a known format from bytes.

    Raises
    ------
    MeshFormatError
        The bytes are not a readable mesh of that format, or exceed ``limits``.
    """
    if not data:
        raise MeshFormatError("the file is empty")
    if len(data) > limits.max_bytes:
        raise MeshFormatError(
            f"the file has {len(data):,} bytes; the limit is {limits.max_bytes:,}", status=413
        )
    return READERS[fmt](data, limits)
