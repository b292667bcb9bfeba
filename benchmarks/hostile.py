"""Hostile uploads, built to a size: the inputs that cost the readers the most memory per byte
(``make attack`` sends them big; tests/corpus.py keeps them small as corpus entries).

Each builder returns the file's bytes, about ``size`` long.
"""

from __future__ import annotations

import struct
from collections.abc import Callable

import numpy as np

TRIANGLE = b"v 0 0 0\nv 1 0 0\nv 0 1 0\n"


def _repeat(unit: bytes, size: int, head: bytes = b"", tail: bytes = b"") -> bytes:
    return head + unit * max(1, (size - len(head) - len(tail)) // len(unit)) + tail


def obj_newlines(size: int) -> bytes:
    return b"\n" * size


def obj_comments(size: int) -> bytes:
    return _repeat(b"#\n", size)


def obj_vertices(size: int) -> bytes:
    return _repeat(b"v 1 1 1\n", size, tail=b"f 1 2 3\n")


def obj_faces(size: int) -> bytes:
    return _repeat(b"f 1 1 1\n", size, head=TRIANGLE)


def obj_many_corners(size: int) -> bytes:
    """One polygon of small references: 2 bytes a triangle after fan triangulation."""
    return _repeat(b" 1", size, head=TRIANGLE + b"f", tail=b"\n")


def obj_group_names(size: int) -> bytes:
    """A distinct group name a line, each a dictionary entry however short."""
    count = max(1, size // 12)
    names = b"".join(b"g n%d\n" % i for i in range(count))
    return TRIANGLE + names + b"f 1 2 3\n"


def ply_ascii(size: int) -> bytes:
    rows = max(1, size // 14)
    header = (
        f"ply\nformat ascii 1.0\nelement vertex {rows}\nproperty float x\nproperty float y\n"
        f"property float z\nelement face {rows}\nproperty list uchar int vertex_indices\n"
        "end_header\n"
    ).encode()
    return header + b"1 1 1\n" * rows + b"3 0 0 0\n" * rows


def ply_binary_mixed(size: int) -> bytes:
    """Polygons of 3 and 4 corners, alternately, with uchar indices: 4.5 bytes a polygon."""
    rows = max(2, size // 5) // 2 * 2
    header = (
        "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n"
        "property float y\nproperty float z\n"
        f"element face {rows}\nproperty list uchar uchar vertex_indices\nend_header\n"
    ).encode()
    vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], "<f4").tobytes()
    pair = bytes([3, 0, 1, 2, 4, 0, 1, 2, 1])
    return header + vertices + pair * (rows // 2)


def stl_ascii(size: int) -> bytes:
    """ASCII STL written with two spaces in ``facet  normal``."""
    facet = (
        b"facet  normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\n"
        b"endloop\nendfacet\n"
    )
    return _repeat(facet, size, head=b"solid x\n", tail=b"endsolid x\n")


def stl_binary(size: int) -> bytes:
    count = max(1, (size - 84) // 50)
    facet = struct.pack("<12fH", 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0)
    return b"\0" * 80 + struct.pack("<I", count) + facet * count


#: name -> (file name, builder); the file name's extension chooses the reader.
HOSTILE: dict[str, tuple[str, Callable[[int], bytes]]] = {
    "OBJ of newlines": ("a.obj", obj_newlines),
    "OBJ of comments": ("a.obj", obj_comments),
    "OBJ of `v` lines": ("a.obj", obj_vertices),
    "OBJ of `f 1 1 1` lines": ("a.obj", obj_faces),
    "OBJ polygon of 2-byte corners": ("a.obj", obj_many_corners),
    "OBJ of distinct group names": ("a.obj", obj_group_names),
    "ASCII PLY": ("a.ply", ply_ascii),
    "binary PLY, mixed polygon sizes": ("a.ply", ply_binary_mixed),
    "ASCII STL, `facet  normal`": ("a.stl", stl_ascii),
    "binary STL": ("a.stl", stl_binary),
}


def points_of_objects(size: int) -> bytes:
    """A /v1/points body whose every point is an empty object."""
    return b'{"points": [' + b",".join([b"{}"] * max(1, size // 3)) + b"]}"


def points_honest(size: int) -> bytes:
    """A /v1/points body of real points (for comparison)."""
    return b'{"points": [' + b",".join([b"[0.25, -1.5, 3.125]"] * max(1, size // 20)) + b"]}"


#: name -> builder of a /v1/points body.
HOSTILE_JSON: dict[str, Callable[[int], bytes]] = {
    "/v1/points of empty objects": points_of_objects,
    "/v1/points of real points": points_honest,
}
