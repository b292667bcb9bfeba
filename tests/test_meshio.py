"""The mesh readers: the file's own order, OBJ's and glTF's rules, and clear refusals."""

from __future__ import annotations

import base64
import io
import json
import re
import struct
import tracemalloc

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

from fixtures.hostile import obj_group_names
from service.meshio import Limits, MeshFormatError, MeshTooLargeError, read_mesh
from service.meshio.obj import MAX_GROUP_NAMES, read_obj
from service.meshio.ply import read_ply
from service.meshio.stl import read_stl
from service.samples import SAMPLES

from .corpus import glb as container

LIMITS = Limits()


def obj(text: str) -> bytes:
    return text.encode()


# -- OBJ ------------------------------------------------------------------------------------


def test_obj_fans_polygons_in_file_order_and_ignores_texture_and_normal_references():
    data = obj(
        "# a comment with / slashes and f 1 2 3\n"
        "v 0 0 0\nv 1 0 0\r\n  v 1 1 0 1.0\n\tv 0 1 0\nv 0 2 0\n"
        "vt 0.5 0.5\nvn 0 0 1\n"
        "f 1/1/1 2/1/1 3/1/1 4/1/1   # a quad\n"
        "f 1//1 3//1 5//1\n"
        "f 2/1 3/1 4/1 5/1 1/1\n"
        "f -5 -4 -3"  # no final newline, relative references
    )
    mesh = read_mesh(data, "obj", LIMITS)
    np.testing.assert_array_equal(
        mesh.vertices, [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 2, 0]]
    )
    np.testing.assert_array_equal(
        mesh.faces,
        [[0, 1, 2], [0, 2, 3], [0, 2, 4], [1, 2, 3], [1, 3, 4], [1, 4, 0], [0, 1, 2]],
    )


def test_obj_negative_references_count_back_from_the_vertices_defined_so_far():
    data = obj("v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\nv 5 5 5\nf -1 -3 -4\n")
    np.testing.assert_array_equal(read_mesh(data, "obj", LIMITS).faces, [[0, 1, 2], [3, 1, 0]])


def test_obj_groups_follow_g_o_and_usemtl():
    data = obj(
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\n"
        "f 1 2 3\n"
        "o head\ng scalp left\nusemtl skin/dark\nf 1 2 3 4\n"
        "g face\nf 2 3 4\n"
    )
    mesh = read_mesh(data, "obj", LIMITS)
    groups = {name: mesh.group_faces([name]).tolist() for name in mesh.groups}
    assert groups == {
        "head": [1, 2, 3],
        "scalp": [1, 2],
        "left": [1, 2],
        "skin/dark": [1, 2, 3],
        "face": [3],
    }
    assert mesh.group_faces(["face", "scalp"]).tolist() == [1, 2, 3]


def test_obj_many_names_on_one_line_cost_ranges_not_faces():
    names = " ".join(f"n{i}" for i in range(5000))
    data = obj("v 0 0 0\nv 1 0 0\nv 0 1 0\ng " + names + "\n" + "f 1 2 3\n" * 5000)
    mesh = read_mesh(data, "obj", LIMITS)
    assert len(mesh.groups) == 5000 and mesh.groups["n17"].tolist() == [[0, 5000]]
    assert mesh.group_faces(["n4999"]).tolist() == list(range(5000))


def test_obj_leading_blanks_are_one_pass():
    data = obj(" " * 200_000 + "v 0 0 0\n\t v 1 0 0\nv 0 1 0\n" + "   \n" * 1000 + "  f 1 2 3")
    np.testing.assert_array_equal(read_mesh(data, "obj", LIMITS).faces, [[0, 1, 2]])


@pytest.mark.parametrize(
    ("text", "says"),
    [
        ("f 1 2 3\n", "no vertex"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\n", "no face"),
        ("v 0 0 0\nv 1 0 0\nf 1 2\n", "line 3 has 2 corners"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", "refers to vertex 4, but the file has 3"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", "refers to vertex 0"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf -4 1 2\n", "refers to vertex -4"),
        ("v 0 0 0\nv 1 x 0\nv 0 1 0\nf 1 2 3\n", "unreadable vertex coordinates"),
        ("v 0 0 0\nv 1/2 0 0\nv 0 1 0\nf 1 2 3\n", "unreadable vertex coordinates"),
        ("v 0 0 0\nv 1 0\nv 0 1 0\nf 1 2 3\n", "line 2 has 2 numbers"),
        (
            "v 0 0 0\nv 1 0 0\nv 0 nan 0\nf 1 2 3\n",
            r"vertex 2 \(line 3\) has the position \[0.0, nan",
        ),
        ("v 0 0 0\nv 1 0 0\nv 0 1e101 0\nf 1 2 3\n", r"within \+-1e\+100"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3.5\n", "unreadable face references"),
    ],
)
def test_obj_errors_say_where(text, says):
    with pytest.raises(MeshFormatError, match=says):
        read_mesh(obj(text), "obj", LIMITS)


def test_obj_counts_are_checked_before_reading():
    data = obj("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3 4\n")
    with pytest.raises(MeshFormatError, match="2 triangles; the limit is 1") as caught:
        read_mesh(data, "obj", Limits(max_faces=1))
    assert isinstance(caught.value, MeshTooLargeError)  # a 413


@pytest.mark.parametrize("name", ["nefertiti-lowres.obj", "fsaverage-head.ply"])
def test_sample_matches_trimesh(name):
    sample = SAMPLES[name].path.read_bytes()
    fmt = name.rsplit(".", 1)[1]
    ours = read_mesh(sample, fmt, LIMITS)
    peer = trimesh.load(io.BytesIO(sample), file_type=fmt, process=False, force="mesh")
    np.testing.assert_array_equal(ours.vertices, peer.vertices)
    np.testing.assert_array_equal(ours.faces, peer.faces)


# -- PLY -------------------------------------------------------------------------------------

PENTAGON = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 2, 0]], dtype=np.float64)
POLYGONS = [[0, 1, 2], [0, 1, 2, 3], [1, 2, 3, 4, 0], [4, 3, 2]]
FANNED = [[0, 1, 2], [0, 1, 2], [0, 2, 3], [1, 2, 3], [1, 3, 4], [1, 4, 0], [4, 3, 2]]


def ply_header(fmt: str, extra_element: bool = False) -> bytes:
    lines = ["ply", f"format {fmt} 1.0", "comment made by hand", "element vertex 5"]
    lines += ["property float x", "property float y", "property double z", "property uchar red"]
    if extra_element:
        lines += ["element tag 2", "property list uchar short labels", "property int value"]
    lines += ["element face 4", "property int flags", "property list uchar int vertex_indices"]
    return ("\n".join([*lines, "end_header"]) + "\n").encode()


def ply_binary(order: str, extra_element: bool = False) -> bytes:
    body = b"".join(struct.pack(order + "ffdB", x, y, z, 7) for x, y, z in PENTAGON)
    if extra_element:
        body += struct.pack(order + "Bhhhi", 3, 1, 2, 3, 9) + struct.pack(order + "Bi", 0, 4)
    for polygon in POLYGONS:
        body += struct.pack(f"{order}iB{len(polygon)}i", 0, len(polygon), *polygon)
    fmt = {"<": "binary_little_endian", ">": "binary_big_endian"}[order]
    return ply_header(fmt, extra_element) + body


def ply_ascii(extra_element: bool = False) -> bytes:
    rows = [f"{x:g} {y:g} {z:g} 7" for x, y, z in PENTAGON]
    if extra_element:
        rows += ["3 1 2 3 9", "0 4"]
    rows += [f"0 {len(p)} " + " ".join(map(str, p)) for p in POLYGONS]
    return ply_header("ascii", extra_element) + "\n".join(rows).encode()  # no final newline


@pytest.mark.parametrize("extra_element", [False, True])
@pytest.mark.parametrize("make", [lambda e: ply_binary("<", e), lambda e: ply_binary(">", e),
                                  ply_ascii], ids=["little", "big", "ascii"])  # fmt: skip
def test_ply_keeps_file_order_and_fans_polygons(make, extra_element):
    mesh = read_mesh(make(extra_element), "ply", LIMITS)
    np.testing.assert_array_equal(mesh.vertices, PENTAGON)
    np.testing.assert_array_equal(mesh.faces, FANNED)


@pytest.mark.parametrize(
    ("data", "says"),
    [
        (b"ply\nformat ascii 1.0\nelement vertex 0\nend_header\n", "needs a 'vertex' and a"),
        (b"solid x", "does not start with 'ply'"),
        (ply_header("ascii").replace(b"format ascii 1.0", b"format weird 1.0"), "line 2"),
        (ply_header("binary_little_endian") + b"\0" * 20, "is cut short"),
        (ply_ascii().replace(b"0 3 4 3 2", b"0 3 4 3 9"), "refers to vertex 9"),
        (ply_ascii().replace(b"0 3 4 3 2", b"0 2 4 3"), "face 3 has 2 corners"),
        (ply_ascii().replace(b"0 3 4 3 2", b"0 3 4 3 x"), "not a number"),
        (ply_ascii().replace(b"0 3 4 3 2", b"0 3 4 3 2 5"), "more values"),
        (
            ply_ascii().replace(b"0 3 4 3 2", b"0 3 4 3.5 2"),
            "PLY face 3 lists 3.5, not a vertex index",
        ),
        (ply_ascii().replace(b"0 2 0 7", b"0 nan 0 7"), "vertex 4 has the position"),
        (ply_ascii()[:-12], "the file ends before them"),
        (ply_binary("<")[:-3], "is cut short"),
    ],
)
def test_ply_errors_say_where(data, says):
    with pytest.raises(MeshFormatError, match=re.escape(says)):
        read_mesh(data, "ply", LIMITS)


def test_ply_counts_are_checked_before_reading():
    data = ply_header("binary_little_endian").replace(b"vertex 5", b"vertex 4000000000")
    with pytest.raises(MeshFormatError, match="4,000,000,000 vertices") as caught:
        read_mesh(data, "ply", LIMITS)
    assert isinstance(caught.value, MeshTooLargeError)  # a 413


# -- glTF -----------------------------------------------------------------------------------


def gltf(nodes, meshes, accessors, binary: bytes, scenes=None) -> dict:
    document = {
        "asset": {"version": "2.0"},
        "nodes": nodes,
        "meshes": meshes,
        "accessors": accessors,
        "bufferViews": [{"buffer": 0, "byteLength": len(binary)}],
        "buffers": [
            {
                "byteLength": len(binary),
                "uri": "data:application/octet-stream;base64," + base64.b64encode(binary).decode(),
            }
        ],
    }
    if scenes is not None:
        document["scenes"] = scenes
    return document


def glb(document: dict, binary: bytes) -> bytes:
    """``document`` with its buffer in the GLB's BIN chunk."""
    return container(dict(document, buffers=[{"byteLength": len(binary)}]), binary)


SQUARE = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype="<f4")


def square_document(indices, mode=4, nodes=None, scenes=None):
    """One mesh of the unit square with ``indices`` (uint16) drawn in ``mode``."""
    index_bytes = np.asarray(indices, dtype="<u2").tobytes()
    index_bytes += b"\0" * (-len(index_bytes) % 4)
    binary = SQUARE.tobytes() + index_bytes
    accessors = [
        {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3"},
        {
            "bufferView": 0,
            "byteOffset": SQUARE.nbytes,
            "componentType": 5123,
            "count": len(indices),
            "type": "SCALAR",
        },
    ]
    meshes = [{"name": "square", "primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}]
    meshes[0]["primitives"][0]["mode"] = mode
    nodes = nodes if nodes is not None else [{"mesh": 0, "name": "node"}]
    return gltf(nodes, meshes, accessors, binary, scenes), binary


@pytest.mark.parametrize(
    ("mode", "indices", "faces"),
    [
        (4, [0, 1, 2, 0, 2, 3], [[0, 1, 2], [0, 2, 3]]),
        (5, [0, 1, 3, 2], [[0, 1, 3], [3, 1, 2]]),  # strip: every other triangle swaps
        (6, [0, 1, 2, 3], [[0, 1, 2], [0, 2, 3]]),  # fan
    ],
)
def test_gltf_triangle_lists_strips_and_fans(mode, indices, faces):
    document, binary = square_document(indices, mode)
    for data, fmt in ((json.dumps(document).encode(), "gltf"), (glb(document, binary), "glb")):
        mesh = read_mesh(data, fmt, LIMITS)
        np.testing.assert_array_equal(mesh.faces, faces)
        np.testing.assert_array_equal(mesh.vertices, SQUARE)


def test_gltf_node_transforms_and_order():
    nodes = [
        {"name": "parent", "translation": [10, 0, 0], "children": [1]},
        {"name": "child", "mesh": 0, "scale": [2, 2, 2]},
        {"name": "mirror", "mesh": 0, "matrix": [-1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 5, 1]},
    ]
    document, _ = square_document([0, 1, 2, 0, 2, 3], nodes=nodes, scenes=[{"nodes": [2, 0]}])
    mesh = read_mesh(json.dumps(document).encode(), "gltf", LIMITS)
    mirrored = SQUARE * [-1, 1, 1] + [0, 0, 5]
    np.testing.assert_allclose(mesh.vertices, np.concatenate([mirrored, SQUARE * 2 + [10, 0, 0]]))
    # The mirrored instance comes first (scene order) with its winding reversed.
    np.testing.assert_array_equal(mesh.faces, [[2, 1, 0], [3, 2, 0], [4, 5, 6], [4, 6, 7]])
    groups = {name: mesh.group_faces([name]).tolist() for name in mesh.groups}
    assert groups == {"square": [0, 1, 2, 3], "mirror": [0, 1], "child": [2, 3]}


@pytest.mark.parametrize(
    ("change", "says"),
    [
        (lambda d: d["accessors"][0].update(count=6), "declares 6 elements"),
        (lambda d: d["accessors"][1].update(componentType=5126), "componentType 5126"),
        (lambda d: d["meshes"][0]["primitives"][0].update(mode=1), "draws lines"),
        (lambda d: d["meshes"][0]["primitives"][0].update(indices=7), "accessors\\[7\\]"),
        (lambda d: d["buffers"][0].update(byteLength=10**6), "declares 1,000,000 bytes"),
        (
            lambda d: d.update(scenes=[{"nodes": [0]}]) or d["nodes"][0].update(children=[0]),
            "appears twice",
        ),
        (lambda d: d["nodes"][0].update(children=[0]), "no root node"),
        (lambda d: d["asset"].update(version="1.0"), "only glTF 2.0"),
    ],
)
def test_gltf_refusals_name_the_item(change, says):
    document, _ = square_document([0, 1, 2, 0, 2, 3])
    change(document)
    with pytest.raises(MeshFormatError, match=says):
        read_mesh(json.dumps(document).encode(), "gltf", LIMITS)


def test_gltf_index_past_the_positions_is_refused():
    document, _ = square_document([0, 1, 4])
    with pytest.raises(MeshFormatError, match="refer to vertex 4 but its POSITION holds 4"):
        read_mesh(json.dumps(document).encode(), "gltf", LIMITS)


def test_glb_cut_short_is_refused():
    document, binary = square_document([0, 1, 2])
    data = glb(document, binary)
    with pytest.raises(MeshFormatError, match="declares"):
        read_mesh(data[:-8], "glb", LIMITS)


def test_glb_sample_matches_trimesh():
    sample = SAMPLES["lee-perry-smith.glb"].path.read_bytes()
    ours = read_mesh(sample, "glb", LIMITS)
    peer = trimesh.load(io.BytesIO(sample), file_type="glb", process=False, force="mesh")
    np.testing.assert_allclose(ours.vertices, peer.vertices, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(ours.faces, peer.faces)


# -- anything else is a MeshFormatError ------------------------------------------------------


def _small_files() -> dict[str, bytes]:
    document, binary = square_document([0, 1, 2, 0, 2, 3])
    square = trimesh.Trimesh(SQUARE[:3], [[0, 1, 2]], process=False)
    return {
        "obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\ng a\nf 1/1 2/1 3/1 4/1\nf -1 -2 -3\n",
        "gltf": json.dumps(document).encode(),
        "glb": glb(document, binary),
        "ply": square.export(file_type="ply"),
        "ply-ascii": ply_ascii(extra_element=True),
        "ply-binary": ply_binary(">", extra_element=True),
        "stl": square.export(file_type="stl"),
    }


SMALL_FILES = _small_files()


@pytest.mark.parametrize("fmt", sorted(SMALL_FILES))
@settings(max_examples=150, deadline=None)
@given(data=st.data())
def test_damaged_files_are_read_or_refused_never_crash(fmt, data):
    original = SMALL_FILES[fmt]
    cut = data.draw(st.integers(0, len(original)), label="cut")
    damaged = bytearray(original[:cut])
    for _ in range(data.draw(st.integers(0, 3), label="flips")):
        if damaged:
            at = data.draw(st.integers(0, len(damaged) - 1), label="at")
            damaged[at] = data.draw(st.integers(0, 255), label="byte")
    try:
        reader = fmt.split("-")[0]
        mesh = read_mesh(bytes(damaged), reader, Limits(max_vertices=1000, max_faces=1000))
    except MeshFormatError:
        return
    assert np.isfinite(mesh.vertices).all()
    assert mesh.faces.ndim == 2 and mesh.faces.shape[1] == 3
    assert ((mesh.faces >= 0) & (mesh.faces < len(mesh.vertices))).all()


def ply_text(header: str, body: str) -> bytes:
    return f"ply\nformat ascii 1.0\n{header}end_header\n{body}".encode()


VERTS = "element vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
TRIANGLE_ROWS = "0 0 0\n1 0 0\n0 1 0\n"


@pytest.mark.parametrize(
    ("data", "faces"),
    [
        # An element with no rows (MeshLab writes `element edge 0`).
        (
            ply_text(
                VERTS + "element face 1\nproperty list uchar int vertex_indices\n"
                "element edge 0\nproperty int vertex1\n",
                TRIANGLE_ROWS + "3 0 1 2\n",
            ),
            [[0, 1, 2]],
        ),
        # A float list that is not the face indices (texture coordinates) is skipped.
        (
            ply_text(
                VERTS + "element face 1\nproperty list uchar int vertex_indices\n"
                "property list uchar float texcoord\n",
                TRIANGLE_ROWS + "3 0 1 2 6 0.5 0.5 0.25 0 1 1\n",
            ),
            [[0, 1, 2]],
        ),
        # 'end_header' inside a comment does not end the header.
        (
            ply_text(
                "comment made by end_header_writer\n"
                + VERTS
                + "element face 1\nproperty list uchar int vertex_indices\n",
                TRIANGLE_ROWS + "3 0 1 2\n",
            ),
            [[0, 1, 2]],
        ),
    ],
)
def test_ply_reads_what_real_writers_write(data, faces):
    assert read_mesh(data, "ply", LIMITS).faces.tolist() == faces


@pytest.mark.parametrize(
    ("data", "says", "status"),
    [
        (
            b"ply\nformat binary_little_endian 1.0\n" + VERTS.encode() + b"element face 1\n"
            b"property list uchar int vertex_indices\nelement junk 10000000000000\n"
            b"property list uchar uchar a\nend_header\n" + b"\0" * 40,
            "junk element declares 10,000,000,000,000 rows",
            413,
        ),
        (
            ply_text(VERTS + "property float x\nelement face 0\n", ""),
            "a second 'x' property",
            422,
        ),
        (
            ply_text(
                "element vertex 1\nproperty list uchar float x\nproperty float y\n"
                "property float z\nelement face 0\nproperty list uchar int vertex_indices\n",
                "",
            ),
            "needs scalar x, y and z",
            422,
        ),
        (
            ply_text(VERTS + "element face 1\nproperty int vertex_indices\n", TRIANGLE_ROWS),
            "needs a list property",
            422,
        ),
    ],
)
def test_ply_header_mistakes_are_named(data, says, status):
    with pytest.raises(MeshFormatError, match=re.escape(says)) as caught:
        read_mesh(data, "ply", LIMITS)
    assert isinstance(caught.value, MeshTooLargeError) == (status == 413)


def test_a_gltf_without_triangles_is_refused():
    twelve = base64.b64encode(bytes(12)).decode()
    document = {
        "asset": {"version": "2.0"},
        "buffers": [{"byteLength": 12, "uri": f"data:application/octet-stream;base64,{twelve}"}],
        "bufferViews": [{"buffer": 0, "byteLength": 12}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 0, "type": "VEC3"}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
        "nodes": [{"mesh": 0}],
    }
    with pytest.raises(MeshFormatError, match="no triangles"):
        read_mesh(json.dumps(document).encode(), "gltf", LIMITS)


# -- PLY triangle strips (range scanners and the Igea scan write them) ----------------------

#: A 2 x 4 grid of vertices (x across, y up) as one strip: 0 4 1 5 2 6 3 7, every triangle
#: counter-clockwise seen from +Z once the strip's alternation is undone.
GRID = np.array([[x, y, 0.0] for y in (0, 1) for x in range(4)])
STRIP = [4, 0, 5, 1, 6, 2, 7, 3]
STRIP_TRIANGLES = [[4, 0, 5], [5, 0, 1], [5, 1, 6], [6, 1, 2], [6, 2, 7], [7, 2, 3]]


def strips_ply(fmt: str, rows: list[list[int]], count: str = "int", index="vertex_indices"):
    """A PLY of the grid with a ``tristrips`` element (colours and a confidence per vertex,
    a material element in the way), in ``fmt``."""
    header = [
        "ply",
        f"format {fmt} 1.0",
        "element vertex 8",
        "property float x",
        "property float y",
        "property float z",
        "property uchar red",
        "property uchar green",
        "property uchar blue",
        "property float confidence",
        "element material 1",
        "property uchar ambient_red",
        "element tristrips " + str(len(rows)),
        f"property list {count} int {index}",
        "end_header",
    ]
    head = ("\n".join(header) + "\n").encode()
    if fmt == "ascii":
        lines = [f"{x:g} {y:g} {z:g} 10 20 30 0.5" for x, y, z in GRID] + ["7"]
        lines += [f"{len(row)} " + " ".join(map(str, row)) for row in rows]
        return head + ("\n".join(lines) + "\n").encode()
    order = {"binary_little_endian": "<", "binary_big_endian": ">"}[fmt]
    code = {"uchar": "B", "ushort": "H", "int": "i", "uint": "I"}[count]
    body = b"".join(struct.pack(order + "fffBBBf", x, y, z, 10, 20, 30, 0.5) for x, y, z in GRID)
    body += struct.pack(order + "B", 7)
    for row in rows:
        body += struct.pack(f"{order}{code}{len(row)}i", len(row), *row)
    return head + body


def normals_z(mesh) -> np.ndarray:
    a, b, c = (mesh.vertices[mesh.faces[:, k]] for k in range(3))
    return np.cross(b - a, c - a)[:, 2]


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian", "binary_big_endian"])
@pytest.mark.parametrize("count", ["uchar", "ushort", "uint"])
def test_ply_triangle_strips_keep_the_strips_winding(fmt, count):
    mesh = read_mesh(strips_ply(fmt, [STRIP], count), "ply", LIMITS)
    assert mesh.faces.tolist() == STRIP_TRIANGLES
    assert (normals_z(mesh) > 0).all()  # one orientation: the alternation is undone
    np.testing.assert_array_equal(mesh.vertices, GRID)


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian"])
def test_ply_strips_restart_at_minus_one_and_skip_the_joins(fmt):
    # Two strips in one row, split by -1; then a row whose strips are joined by repeating
    # vertices (the old way): the repeating triangles are no triangles.
    rows = [[4, 0, 5, 1, -1, 6, 2, 7, 3], [4, 0, 5, 1, 1, 6, 6, 2, 7, 3]]
    mesh = read_mesh(strips_ply(fmt, rows, index="vertex_index"), "ply", LIMITS)
    first = [[4, 0, 5], [5, 0, 1], [6, 2, 7], [7, 2, 3]]
    assert mesh.faces.tolist()[:4] == first
    assert all(len(set(face)) == 3 for face in mesh.faces.tolist())
    assert (normals_z(mesh) > 0).all()


def test_ply_faces_and_strips_come_in_the_headers_order():
    header = VERTS.replace("vertex 3", "vertex 4")
    body = "0 0 0\n1 0 0\n0 1 0\n1 1 0\n"
    text = (
        header
        + "element face 1\nproperty list uchar int vertex_indices\n"
        + "element tristrips 1\nproperty list int int vertex_indices\n"
    )
    mesh = read_mesh(ply_text(text, body + "3 0 1 2\n4 1 3 2 -1\n"), "ply", LIMITS)
    assert mesh.faces.tolist() == [[0, 1, 2], [1, 3, 2]]


def test_a_strip_that_names_a_missing_vertex_is_refused():
    with pytest.raises(MeshFormatError, match=r"PLY tristrips row 0 refers to vertex 8"):
        read_mesh(strips_ply("ascii", [[4, 0, 8]]), "ply", LIMITS)


def test_a_file_without_triangle_elements_names_what_it_has():
    text = VERTS + "element edge 1\nproperty int vertex1\nproperty int vertex2\n"
    with pytest.raises(MeshFormatError, match="it has 'vertex', 'edge'"):
        read_mesh(ply_text(text, TRIANGLE_ROWS + "0 1\n"), "ply", LIMITS)


def test_a_real_scan_written_as_strips_reads_back_its_triangles():
    """Lee Perry-Smith's scan as one tristrips row: each triangle a strip of its own, ended by
    -1 (binary, as scanners write it; the zoo's writer)."""
    from fixtures.zoo import strips_ply

    mesh = read_mesh(SAMPLES["lee-perry-smith.obj"].path.read_bytes(), "obj", LIMITS)
    strips = read_mesh(strips_ply(mesh), "ply", LIMITS)
    np.testing.assert_array_equal(strips.faces, mesh.faces)
    np.testing.assert_array_equal(strips.vertices, mesh.vertices)


def test_an_unsigned_strip_list_ends_its_strips_with_its_largest_value():
    """A strip list of uint items writes -1 as 4294967295."""
    header = (
        b"ply\nformat binary_little_endian 1.0\nelement vertex 8\nproperty float x\n"
        b"property float y\nproperty float z\nelement tristrips 1\n"
        b"property list uchar uint vertex_indices\nend_header\n"
    )
    body = b"".join(struct.pack("<fff", *p) for p in GRID)
    items = [4, 0, 5, 1, 0xFFFFFFFF, 6, 2, 7, 3]
    body += struct.pack(f"<B{len(items)}I", len(items), *items)
    mesh = read_mesh(header + body, "ply", LIMITS)
    assert mesh.faces.tolist() == [[4, 0, 5], [5, 0, 1], [6, 2, 7], [7, 2, 3]]


# -- memory: a reader needs at most 8 bytes a byte of the file, plus a constant --------------

#: The constant: a few chunks' worth of temporaries (text.CHUNK_BYTES) and small arrays.
MEMORY_CONSTANT = 16 * 2**20
SIZE = 4 * 2**20
TRIANGLE = b"v 0 0 0\nv 1 0 0\nv 0 1 0\n"


def repeated(unit: bytes, head: bytes = b"", tail: bytes = b"", size: int = SIZE) -> bytes:
    return head + unit * ((size - len(head) - len(tail)) // len(unit)) + tail


def ply_head(fmt: str, vertices: int, rows: int, item: str = "int", element="face") -> bytes:
    return (
        f"ply\nformat {fmt} 1.0\nelement vertex {vertices}\nproperty float x\n"
        f"property float y\nproperty float z\nelement {element} {rows}\n"
        f"property list uchar {item} vertex_indices\nend_header\n"
    ).encode()


def binary_ply_of_mixed_polygons(size: int = SIZE) -> bytes:
    """Triangles and quads in turn: rows of two shapes, walked."""
    pair = struct.pack("<B3i", 3, 0, 1, 2) + struct.pack("<B4i", 4, 0, 1, 2, 3)
    pairs = size // len(pair)
    square = SQUARE.astype("<f4").tobytes()
    return ply_head("binary_little_endian", 4, 2 * pairs) + square + pair * pairs


def ascii_stl(space: bytes = b" ", size: int = SIZE) -> bytes:
    facet = (
        b"facet" + space + b"normal 0 0 1\n outer loop\n  vertex 0 0 0\n  vertex 1 0 0\n"
        b"  vertex 0 1 0\n endloop\nendfacet\n"
    )
    return repeated(facet, b"solid x\n", b"endsolid x\n", size)


def binary_stl(size: int) -> bytes:
    return b"\0" * 80 + struct.pack("<I", size // 50) + bytes(size // 50 * 50)


def ascii_ply_of_triangles(size: int) -> bytes:
    head = ply_head("ascii", 3, size // 8)
    return head + b"0 0 0\n1 0 0\n0 1 0\n" + b"3 0 1 2\n" * (size // 8)


def ascii_ply_of_vertices(size: int) -> bytes:
    return ply_head("ascii", size // 6, 1) + b"0 0 0\n" * (size // 6) + b"3 0 1 2\n"


def binary_ply_of_one_long_strip(size: int) -> bytes:
    return (
        ply_head("binary_little_endian", 3, 1, element="tristrips").replace(b"uchar", b"int")
        + SQUARE[:3].astype("<f4").tobytes()
        + struct.pack("<i", size // 4)
        + (np.arange(size // 4) % 3).astype("<i4").tobytes()
    )


def binary_ply_of_byte_properties(size: int) -> bytes:
    """Vertices with a colour and ten more one-byte properties (eight of them kept)."""
    names = ["red", "green", "blue", "alpha", *(f"p{k}" for k in range(10))]
    count = size // (12 + len(names))
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        f"element vertex {count}\nproperty float x\nproperty float y\nproperty float z\n"
        + "".join(f"property uchar {name}\n" for name in names)
        + "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
    ).encode()
    rows = bytes(count * (12 + len(names)))
    return header + rows + struct.pack("<B3i", 3, 0, 1, 2)


def obj_of(unit: bytes, head: bytes = b"", tail: bytes = b""):
    return lambda size: repeated(unit, head, tail, size)


#: Each case's format and its file of about a given size.
ADVERSARIAL = {
    "obj of line feeds": ("obj", obj_of(b"\n", TRIANGLE + b"f 1 2 3\n")),
    "obj of comments": ("obj", obj_of(b"#\n", TRIANGLE + b"f 1 2 3\n")),
    "obj of comments with words": ("obj", obj_of(b"# f 1 2 3 / v\n", TRIANGLE + b"f 1 2 3\n")),
    "obj of v lines": ("obj", obj_of(b"v 0 0 0\n", tail=b"f 1 2 3\n")),
    "obj of f lines": ("obj", obj_of(b"f 1 1 1\n", TRIANGLE)),
    "obj of f lines with tails": ("obj", obj_of(b"f 1/1/1 1/1/1 1/1/1\n", TRIANGLE)),
    "obj of relative f lines": ("obj", obj_of(b"f -1 -1 -1\n", TRIANGLE)),
    "obj of g lines": ("obj", obj_of(b"g a\n", TRIANGLE, b"f 1 2 3\n")),
    "obj of vt lines": ("obj", obj_of(b"vt 0 0\n", TRIANGLE, b"f 1/1 2/1 3/1\n")),
    "obj of f lines with texture references": (
        "obj",
        obj_of(b"f 1/1 1/1 1/1\n", TRIANGLE + b"vt 0 0\n"),
    ),
    "obj of coloured v lines": ("obj", obj_of(b"v 0 0 0 1 1 1\n", tail=b"f 1 2 3\n")),
    "obj of one long face": ("obj", obj_of(b" -1", TRIANGLE + b"f", b"\n")),
    "obj of one long vertex": ("obj", obj_of(b" 0", b"v", b"\n" + TRIANGLE + b"f 1 2 3\n")),
    "obj of one long comment": ("obj", obj_of(b"x", TRIANGLE + b"f 1 2 3\n#", b"\n")),
    "ascii stl": ("stl", lambda size: ascii_stl(size=size)),
    "ascii stl with 'facet  normal'": ("stl", lambda size: ascii_stl(b"  ", size)),
    "binary stl": ("stl", binary_stl),
    "ascii ply of triangles": ("ply", ascii_ply_of_triangles),
    "ascii ply of vertices": ("ply", ascii_ply_of_vertices),
    "binary ply of mixed polygons": ("ply", binary_ply_of_mixed_polygons),
    "binary ply of one long strip": ("ply", binary_ply_of_one_long_strip),
    "binary ply of vertices with byte properties": ("ply", binary_ply_of_byte_properties),
}


def peak_of_reading(data: bytes, fmt: str) -> tuple[int, int]:
    """The peak of memory allocations (numpy's too) while reading ``data``, and the bytes of
    the mesh's arrays."""
    tracemalloc.start()
    try:
        mesh = read_mesh(data, fmt, Limits(max_vertices=10**8, max_faces=10**8))
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    return peak, mesh.vertices.nbytes + mesh.faces.nbytes


@pytest.mark.parametrize("name", sorted(ADVERSARIAL))
def test_reading_needs_at_most_8_bytes_a_byte_plus_a_constant(name):
    """Bounded at one size, and by its slope: the peak grows by at most 8 bytes for each
    byte a file twice as large adds, so the constant hides no cost per byte."""
    fmt, build = ADVERSARIAL[name]
    small, large = build(SIZE), build(2 * SIZE)
    (peak_small, _), (peak_large, _) = peak_of_reading(small, fmt), peak_of_reading(large, fmt)
    assert peak_small <= 8 * len(small) + MEMORY_CONSTANT, f"{peak_small / len(small):.1f} B/B"
    slope = (peak_large - peak_small) / (len(large) - len(small))
    assert slope <= 8, f"{slope:.1f} bytes a byte added"


@pytest.mark.parametrize(
    "data",
    [repeated(b"f" + b" 1" * 1000 + b"\n", TRIANGLE), repeated(b" 1", TRIANGLE + b"f", b"\n")],
    ids=["many long polygons", "one polygon"],
)
def test_polygons_of_one_digit_corners_need_their_triangles_plus_a_constant(data):
    """The one case beyond 8 bytes a byte (obj.py's docstring): each 2-byte corner past the
    second is a 24-byte triangle; the read needs those and a constant, nothing in between."""
    peak, arrays = peak_of_reading(data, "obj")
    assert arrays > 8 * len(data)
    assert peak <= arrays + MEMORY_CONSTANT


def test_an_ascii_stl_beyond_the_limits_is_refused_by_its_count_whatever_its_spacing():
    """The count is of 'vertex' lines, not of a spelling of 'facet normal'; it comes before
    any number is parsed (the file's last number is no number, and that is not what is
    said)."""
    data = ascii_stl(b"  ", size=20_000).replace(b"endsolid", b"facet normal 0 0 1\nvertex 0 x 0\n")
    facets = data.count(b"endfacet")
    with pytest.raises(MeshTooLargeError, match=f"{facets:,} triangles; the limit is 10"):
        read_mesh(data, "stl", Limits(max_faces=10))
    with pytest.raises(MeshTooLargeError, match="vertices; the limit is 10"):
        read_mesh(data, "stl", Limits(max_vertices=10))


def test_counts_are_checked_before_anything_is_made_for_them():
    """A file whose counts pass the limits only by a little and whose arrays would cost far
    more than the file is refused before they are made."""
    many = repeated(b"f" + b" 1" * 1000 + b"\n", TRIANGLE, size=300_000)
    tracemalloc.start()
    try:
        with pytest.raises(MeshTooLargeError):
            read_mesh(many, "obj", Limits(max_faces=1000))
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < MEMORY_CONSTANT  # its 150,000 triangles would take 3.6 MB


# -- chunks: what a reader reads does not depend on where the chunks end ---------------------


def read_in_chunks(data, fmt: str, chunk: int, rows: int = 3):
    """``data`` read with chunks of ``chunk`` bytes (and PLY batches of ``rows`` rows)."""
    if fmt == "ply":
        return read_ply(data, LIMITS, chunk_bytes=chunk, batch_rows=rows, strip_items=rows + 2)
    return {"obj": read_obj, "stl": read_stl}[fmt](data, LIMITS, chunk_bytes=chunk)


def assert_same_mesh(mesh, other):
    np.testing.assert_array_equal(mesh.vertices, other.vertices)
    np.testing.assert_array_equal(mesh.faces, other.faces)
    assert mesh.faces.dtype == np.int64 and mesh.vertices.dtype == np.float64
    assert {name: mesh.group_faces([name]).tolist() for name in mesh.groups} == {
        name: other.group_faces([name]).tolist() for name in other.groups
    }


#: Lines that cross chunk edges however small the chunks: comments, tails, relative
#: references, groups, a long polygon, blank and indented lines, CRLF.
EDGY_OBJ = (
    b"# a comment: v 9 9 9 / f 1 2 3\r\n"
    b"v 0 0 0 # trailing\nv 1 0 0\r\n  v 1 1 0 1.0\n\tv 0 1 0\nv 0 2 0\n\n\n"
    b"vt 0.5 0.5\nvn 0 0 1\ng  scalp   left # not a group\n"
    b"f 1/1/1 2/1/1 3/1/1 4/1/1   # a quad\n"
    b"o   the head  \nusemtl skin/dark\n"
    b"f 1//1 3//1 5//1\n   \nf 2/1 3/1 4/1 5/1 1/1\ng face\n"
    b"f " + b" ".join(b"-%d" % (1 + k % 5) for k in range(40)) + b"\n"
    b"v 5 5 5\nf -1 -3 -4#c\ng\nf 1 2 3"
)


@pytest.mark.parametrize("chunk", [1, 2, 3, 5, 8, 13, 64, 4096])
def test_obj_reads_the_same_however_its_text_is_cut_into_chunks(chunk):
    whole = read_mesh(EDGY_OBJ, "obj", LIMITS)
    assert whole.faces.tolist()[:7] == [
        [0, 1, 2], [0, 2, 3], [0, 2, 4], [1, 2, 3], [1, 3, 4], [1, 4, 0], [4, 3, 2]
    ]  # fmt: skip
    assert whole.groups["the head"].tolist() == [[2, len(whole.faces)]]
    assert whole.group_faces(["scalp"]).tolist() == [0, 1, 2, 3, 4, 5]
    assert "not" not in whole.groups and whole.faces.tolist()[-2:] == [[5, 3, 2], [0, 1, 2]]
    assert whole.groups["face"].tolist() == [[6, len(whole.faces) - 1]]  # "g" ends it
    assert_same_mesh(read_in_chunks(EDGY_OBJ, "obj", chunk), whole)


@pytest.mark.parametrize("chunk", [1, 4, 16, 1000])
@pytest.mark.parametrize(
    ("text", "says"),
    [
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n", "face on line 4 has 2 corners"),
        ("v 0 0 0\nv 1 0 0\n\nv 0 1 0 # x\nf 1 2 4\n", "line 5 refers to vertex 4"),
        ("v 0 0 0\nv 1 0\nv 0 1 0\nf 1 2 3\n", "vertex on line 2 has 2 numbers"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\n\n\nf 1 2 3.5\n", "unreadable face references on line 6"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 /2 3\n", "unreadable face references on line 4"),
        ("v 0 0 0\n# v\nv 1 x 0\nv 0 1 0\nf 1 2 3\n", "unreadable vertex coordinates on line 3"),
        ("v 0 0 0\nv 1 0 0\nv 0 inf 0\nf 1 2 3\n", r"vertex 2 \(line 3\)"),
    ],
)
def test_obj_errors_name_the_line_however_the_text_is_cut(chunk, text, says):
    with pytest.raises(MeshFormatError, match=says):
        read_obj(obj(text), LIMITS, chunk_bytes=chunk)


def _random_obj(rng: np.random.Generator) -> bytes:
    lines = ["v 0 0 0", "v 1 0 0", "v 0 1 0"]
    for _ in range(int(rng.integers(5, 60))):
        kind = rng.choice(["v", "f", "g", "o", "#", "vt", ""])
        if kind == "v":
            lines.append(" v " + " ".join(map(str, rng.integers(-9, 9, int(rng.integers(3, 6))))))
        elif kind == "f":
            refs = [str(int(rng.integers(1, 4))) + rng.choice(["", "/1", "//1"])
                    for _ in range(int(rng.integers(3, 12)))]  # fmt: skip
            lines.append("f\t" + "  ".join(refs) + rng.choice(["", " # c", "\r"]))
        elif kind in ("g", "o"):
            lines.append(
                f"{kind} " + " ".join(rng.choice(["a", "b", "c d"], int(rng.integers(0, 3))))
            )
        else:
            lines.append(f"{kind} 0 1")
    return "\n".join([*lines, "f 1 2 3"]).encode()


@pytest.mark.parametrize("seed", range(20))
def test_random_obj_files_read_the_same_in_any_chunks(seed):
    rng = np.random.default_rng(seed)
    data = _random_obj(rng)
    whole = read_mesh(data, "obj", LIMITS)
    for chunk in rng.integers(1, 40, 3).tolist():
        assert_same_mesh(read_in_chunks(data, "obj", chunk), whole)


PLY_FILES = {
    "ascii": ply_ascii(extra_element=True),
    "little": ply_binary("<", extra_element=True),
    "big": ply_binary(">", extra_element=True),
    "strips": strips_ply("binary_little_endian", [STRIP, [4, 0, 5, 1, -1, 6, 2, 7, 3]]),
    "ascii strips": strips_ply("ascii", [STRIP, [4, 0, 5, 1, 1, 6, 6, 2, 7, 3]]),
    "mixed": binary_ply_of_mixed_polygons(2000),
}


@pytest.mark.parametrize("name", sorted(PLY_FILES))
@pytest.mark.parametrize(("chunk", "rows"), [(1, 1), (7, 2), (64, 5)])
def test_ply_reads_the_same_in_any_chunks_and_batches(name, chunk, rows):
    data = PLY_FILES[name]
    assert_same_mesh(read_in_chunks(data, "ply", chunk, rows), read_mesh(data, "ply", LIMITS))


def test_binary_ply_of_mixed_sizes_keeps_every_polygon_in_order():
    """Runs of one shape and rows walked one by one, with a property after the list."""
    rng = np.random.default_rng(1)
    sizes = np.concatenate([rng.integers(3, 7, 50), np.full(40, 3), rng.integers(3, 5, 30)])
    polygons = [rng.integers(0, 5, size).tolist() for size in sizes]
    header = ply_header("binary_big_endian").replace(b"face 4", b"face %d" % len(polygons))
    header = header.replace(b"vertex_indices\n", b"vertex_indices\nproperty uchar tag\n")
    body = b"".join(struct.pack(">ffdB", x, y, z, 7) for x, y, z in PENTAGON)
    body += b"".join(struct.pack(f">iB{len(p)}iB", 0, len(p), *p, 9) for p in polygons)
    fanned = [[p[0], p[k], p[k + 1]] for p in polygons for k in range(1, len(p) - 1)]
    assert read_mesh(header + body, "ply", LIMITS).faces.tolist() == fanned
    assert read_in_chunks(header + body, "ply", 16, 7).faces.tolist() == fanned


@pytest.mark.parametrize("chunk", [1, 9, 100])
def test_ascii_stl_reads_the_same_in_any_chunks(chunk):
    data = trimesh.Trimesh(PENTAGON, FANNED, process=False).export(file_type="stl_ascii").encode()
    data = data.replace(b"facet normal", b"facet  normal").replace(b"vertex", b"VERTEX")
    mesh = read_in_chunks(data, "stl", chunk)
    np.testing.assert_array_equal(mesh.vertices, PENTAGON[np.ravel(FANNED)])
    np.testing.assert_array_equal(mesh.faces, np.arange(3 * len(FANNED)).reshape(-1, 3))


# -- STL without trimesh ---------------------------------------------------------------------


@pytest.mark.parametrize("file_type", ["stl", "stl_ascii"])
def test_stl_keeps_every_corner_of_every_triangle_as_trimesh_does(file_type):
    sample = read_mesh(SAMPLES["lee-perry-smith.glb"].path.read_bytes(), "glb", LIMITS)
    data = trimesh.Trimesh(sample.vertices, sample.faces, process=False).export(file_type=file_type)
    data = data.encode() if isinstance(data, str) else data
    ours = read_mesh(data, "stl", LIMITS)
    peer = trimesh.load(io.BytesIO(data), file_type="stl", process=False, force="mesh")
    np.testing.assert_array_equal(ours.vertices, peer.vertices)
    np.testing.assert_array_equal(ours.faces, peer.faces)
    np.testing.assert_allclose(ours.vertices, sample.vertices[sample.faces.ravel()], rtol=1e-6)


def test_binary_stl_ignores_normals_and_attributes():
    corners = [((0, 0, 0), (1, 0, 0), (0, 1, 0)), ((5, 5, 5), (6, 5, 5), (5, 6, 5))]
    body = b"".join(struct.pack("<12fH", 9, 9, 9, *np.ravel(t), 77) for t in corners)
    mesh = read_mesh(b"solid-looking header".ljust(80) + struct.pack("<I", 2) + body, "stl", LIMITS)
    np.testing.assert_array_equal(mesh.vertices, np.reshape(corners, (-1, 3)))
    assert mesh.faces.tolist() == [[0, 1, 2], [3, 4, 5]]


@pytest.mark.parametrize(
    ("body", "says"),
    [
        ("facet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nendloop\n", "2 'vertex'"),
        ("outer loop\nvertex 0 0 0\nvertex 1 0\nvertex 0 1 0\n", "line 4 of the STL file has 2"),
        (
            "outer loop\nvertex 0 0 0\nvertex 1 0 0 0\nvertex 0 1 0\n",
            "line 4 of the STL file has 4",
        ),
        ("outer loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 one 0\n", "numbers on line 5"),
        ("facet normal 0 0 1\nendfacet\n", "holds no triangles"),
    ],
)
@pytest.mark.parametrize("chunk", [3, 1 << 18])
def test_ascii_stl_mistakes_name_the_line(body, says, chunk):
    with pytest.raises(MeshFormatError, match=says):  # chunk 3: every line read in pieces
        read_stl(f"solid x\n{body}endsolid x\n".encode(), LIMITS, chunk_bytes=chunk)


def test_an_ascii_stl_cut_short_is_refused():
    data = ascii_stl(size=2000)
    cut = data[: data.rindex(b"endfacet")]
    with pytest.raises(MeshFormatError, match="no 'endsolid' line after its last 'vertex'"):
        read_mesh(cut, "stl", LIMITS)


# -- memoryview: every reader reads in place -------------------------------------------------


@pytest.mark.parametrize("name", sorted(SMALL_FILES))
def test_every_reader_reads_a_memoryview_inside_a_larger_buffer(name):
    """The caller passes a view into the request body: what follows the file (here digits,
    which a number running past the end would take in) is not read."""
    data = SMALL_FILES[name]
    if name == "obj":
        data = data.rstrip(b"\n")  # the file ends in a number
    body = b"123" + data + b"456789"
    view = memoryview(body)[3 : 3 + len(data)]
    fmt = name.split("-")[0]
    assert_same_mesh(read_mesh(view, fmt, LIMITS), read_mesh(data, fmt, LIMITS))


def test_a_memoryview_of_an_ascii_ply_ending_in_a_number_is_read_to_its_end():
    data = ply_ascii()  # no final line feed: the last index ends the file
    view = memoryview(data + b"7777")[: len(data)]
    assert read_mesh(view, "ply", LIMITS).faces.tolist() == FANNED


# -- groups ----------------------------------------------------------------------------------


def test_obj_group_ranges_are_merged_and_names_without_faces_kept():
    data = obj("v 0 0 0\nv 1 0 0\nv 0 1 0\ng a\ng a\nf 1 2 3\ng a b\nf 1 2 3\ng c\ng a\n")
    mesh = read_mesh(data, "obj", LIMITS)
    assert mesh.groups["a"].tolist() == [[0, 2]]  # two touching ranges, one range
    assert mesh.groups["b"].tolist() == [[1, 2]]
    assert mesh.groups["c"].shape == (0, 2) and mesh.group_faces(["c"]).tolist() == []


def test_an_obj_naming_too_many_groups_is_refused_by_the_count():
    """Each distinct name is a dictionary entry: without a bound, a file of short names
    would cost over 100 bytes per byte."""
    data = obj_group_names((MAX_GROUP_NAMES + 10) * 12)
    with pytest.raises(MeshTooLargeError, match="65,536 distinct group names"):
        read_mesh(data, "obj", Limits())
    below = read_mesh(obj_group_names(1000 * 12), "obj", Limits())
    assert len(below.groups) == 1000
