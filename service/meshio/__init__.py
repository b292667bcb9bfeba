"""Reading uploaded mesh files from memory: OBJ, glTF, GLB, PLY, STL.

Only the uploaded bytes are read (never a file or URL they refer to), and the file's own
order is kept: vertex ``i`` and face ``i`` are the file's ``i``-th vertex and triangle.

:data:`READERS` is the one list of formats: the ``format`` parameter, the sample files'
media types and the documentation's rules for each format come from it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from .gltf import read_glb, read_gltf
from .mesh import Limits, Mesh, MeshFormatError, MeshTooLargeError
from .obj import read_obj
from .ply import read_ply
from .stl import read_stl


@dataclass(frozen=True)
class Reader:
    """One format: its name (and file extension), title, reader, media type and the rules by
    which its ids are the file's."""

    name: str
    title: str
    read: Callable[[bytes | memoryview, Limits], Mesh]
    media_type: str
    rules: str


_GLTF_RULES = (
    "glTF triangles come primitive by primitive in document order (the default scene's nodes "
    "depth first, children in order, each node's mesh's primitives in order) with node "
    "transforms applied; groups are mesh and node names; COLOR_0, TEXCOORD_0 and custom "
    "scalar attributes such as _FEATURE_ID_0 are kept."
)

READERS: dict[str, Reader] = {
    reader.name: reader
    for reader in (
        Reader(
            "obj",
            "OBJ",
            read_obj,
            "model/obj",
            "OBJ polygons are fan-triangulated in order, ``(a, b, c), (a, c, d), ...``; "
            "negative references count back; groups are ``g`` (each name), ``o`` and "
            "``usemtl`` names; ``v x y z r g b`` colours and ``vt`` texture coordinates (by "
            "the references' ``v/vt``) are kept.",
        ),
        Reader("gltf", "glTF (embedded buffers)", read_gltf, "model/gltf+json", _GLTF_RULES),
        Reader("glb", "GLB", read_glb, "model/gltf-binary", _GLTF_RULES),
        Reader(
            "ply",
            "PLY",
            read_ply,
            "application/octet-stream",
            "PLY polygons are fan-triangulated like OBJ's; triangle strips (``tristrips``, "
            "``-1`` ending a strip) give their triangles with the strip's winding, joins that "
            "repeat a vertex left out; faces and strips count in the header's order; vertex "
            "colours (red, green, blue, alpha), texture coordinates (u, v) and scalar vertex "
            "and face properties are kept, other elements and list properties skipped.",
        ),
        Reader(
            "stl",
            "STL",
            read_stl,
            "model/stl",
            "STL triangles keep their own corners (nothing is merged).",
        ),
    )
}
#: The format names, in the registry's order.
FORMATS = tuple(READERS)


def reading_rules() -> str:
    """How every format's bytes become vertex and face ids, in words (for the docs)."""
    rules = dict.fromkeys(reader.rules for reader in READERS.values())  # glTF's once
    return (
        "Mesh files are read from the uploaded bytes only: a glTF buffer or image that refers "
        "to a file or URL is refused. The file's order is kept: vertex ``i`` is the file's "
        "``i``-th vertex and face ``i`` its ``i``-th triangle. " + " ".join(rules)
    )


__all__ = [
    "FORMATS",
    "READERS",
    "Limits",
    "Mesh",
    "MeshFormatError",
    "MeshTooLargeError",
    "Reader",
    "format_of",
    "read_mesh",
    "reading_rules",
]


def format_of(filename: str | None, declared: str | None) -> str:
    """The format to read: ``declared`` when given, else the file name's extension.

    Raises
    ------
    MeshFormatError
        Neither names a supported format.
    """
    supported = ", ".join(FORMATS)
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


def read_mesh(data: bytes | memoryview, fmt: str, limits: Limits) -> Mesh:
    """Read a mesh of a known format from bytes (or a memoryview of them, which is read in
    place: no reader copies the whole of it).

    Raises
    ------
    MeshFormatError
        The bytes are not a readable mesh of that format.
    MeshTooLargeError
        They exceed ``limits``.
    """
    if not data:
        raise MeshFormatError("the file is empty")
    if len(data) > limits.max_bytes:
        raise MeshTooLargeError(
            f"the file has {len(data):,} bytes; the limit is {limits.max_bytes:,}"
        )
    return READERS[fmt].read(data, limits)
