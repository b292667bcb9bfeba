"""Structural fuzz of the glTF/GLB reader: mutate a valid document, then a valid container.

Byte-level damage (``test_meshio``) mostly breaks the JSON syntax, so it rarely gets past
``json.loads``. Here the document stays valid JSON and the mutations go where the reader's
type checks live: any value at any depth is replaced by another JSON value (wrong types,
huge or negative integers, extreme floats, nested containers), deleted, or a glTF key the
document lacks is added. The GLB test also damages the container itself: header and chunk
lengths, chunk types, the binary payload, truncation.

The contract under test: every input either reads to a sound mesh (finite float64 (n, 3)
vertices, int (m, 3) faces within range) or raises ``MeshFormatError`` with a message and a
status of 422 or 413. Any other exception, including a numpy ``RuntimeWarning`` (an error
under the project's pytest configuration), fails the test.
"""

from __future__ import annotations

import base64
import json
import math
import struct

import numpy as np
import pytest
from hypothesis import example, given, note
from hypothesis import strategies as st

from service.meshio.gltf import read_glb, read_gltf
from service.meshio.mesh import Limits, Mesh, MeshFormatError, MeshTooLargeError
from transforms import MAX_ABS_COORDINATE

from .corpus import glb

#: Small enough that a mutated count or a repeated node reaches a limit, not the memory.
LIMITS = Limits(max_vertices=64, max_faces=64, max_bytes=4096)

# -- the valid document ---------------------------------------------------------------------

SQUARE = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype="<f4")
INDICES = np.array([0, 1, 2, 0, 2, 3], dtype="<u2")
#: Positions, then the indices padded to 4 bytes (bufferView offsets stay aligned).
BINARY = SQUARE.tobytes() + INDICES.tobytes() + b"\0" * (-INDICES.nbytes % 4)
HALF = math.sqrt(0.5)


def base_document(uri: str | None) -> dict:
    """Two triangles (the unit square) under two nodes: a root with a column-major
    ``matrix`` (translation (0, 0, 5)) and a child with translation, rotation (90 degrees
    about +Z) and scale; buffer 0 is ``uri``, or the GLB binary chunk when ``None``."""
    buffer: dict = {"byteLength": len(BINARY)}
    if uri is not None:
        buffer["uri"] = uri
    return {
        "asset": {"version": "2.0", "generator": "test_gltf_fuzz"},
        "scene": 0,
        "scenes": [{"name": "scene", "nodes": [0]}],
        "nodes": [
            {
                "name": "root",
                "matrix": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 5, 1],
                "children": [1],
            },
            {
                "name": "child",
                "mesh": 0,
                "translation": [1.0, 2.0, 3.0],
                "rotation": [0.0, 0.0, HALF, HALF],
                "scale": [2.0, 2.0, 2.0],
            },
        ],
        "meshes": [
            {
                "name": "square",
                "primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "mode": 4}],
            }
        ],
        "accessors": [
            {
                "bufferView": 0,
                "byteOffset": 0,
                "componentType": 5126,
                "count": 4,
                "type": "VEC3",
                "min": [0, 0, 0],
                "max": [1, 1, 0],
            },
            {"bufferView": 1, "componentType": 5123, "count": 6, "type": "SCALAR"},
        ],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": SQUARE.nbytes, "byteStride": 12},
            {"buffer": 0, "byteOffset": SQUARE.nbytes, "byteLength": INDICES.nbytes},
        ],
        "buffers": [buffer],
    }


GLTF_DOCUMENT = base_document(
    "data:application/octet-stream;base64," + base64.b64encode(BINARY).decode()
)
GLB_DOCUMENT = base_document(None)

#: R_z(90 degrees) (2 p) + (1, 2, 3), then + (0, 0, 5) from the root.
EXPECTED_VERTICES = np.stack([-2 * SQUARE[:, 1], 2 * SQUARE[:, 0], 2 * SQUARE[:, 2]], axis=1)
EXPECTED_VERTICES += np.array([1.0, 2.0, 8.0], dtype=np.float32)
EXPECTED_FACES = INDICES.reshape(-1, 3)


def glb_fields(data: bytes) -> dict[str, int]:
    """Byte offset of each u32 field of the header and chunk headers of an undamaged GLB
    (the BIN chunk header follows the JSON chunk, wherever the mutated JSON ends)."""
    json_length = struct.unpack_from("<I", data, 12)[0]
    bin_at = 20 + json_length
    return {
        "magic": 0,
        "version": 4,
        "length": 8,
        "json_length": 12,
        "json_type": 16,
        "bin_length": bin_at,
        "bin_type": bin_at + 4,
        "bin_data": bin_at + 8,
    }


def assert_sound(mesh: Mesh, fmt: str) -> None:
    """The reader's promise about a mesh it returns."""
    assert isinstance(mesh, Mesh)
    assert mesh.format == fmt
    vertices, faces = mesh.vertices, mesh.faces
    assert isinstance(vertices, np.ndarray) and vertices.dtype == np.float64
    assert vertices.ndim == 2 and vertices.shape[1] == 3
    assert np.isfinite(vertices).all()
    assert (np.abs(vertices) <= MAX_ABS_COORDINATE).all()
    assert isinstance(faces, np.ndarray) and faces.dtype.kind in "iu"
    assert faces.ndim == 2 and faces.shape[1] == 3
    assert ((faces >= 0) & (faces < len(vertices))).all()
    assert len(vertices) <= LIMITS.max_vertices and len(faces) <= LIMITS.max_faces
    for name, spans in mesh.groups.items():
        assert isinstance(name, str) and name
        assert spans.ndim == 2 and spans.shape[1] == 2 and spans.dtype.kind == "i"
        assert ((0 <= spans[:, 0]) & (spans[:, 0] <= spans[:, 1])).all()
        assert (spans[:, 1] <= len(faces)).all()


def read_or_refuse(reader, data: bytes, fmt: str) -> None:
    """Read ``data``: a sound mesh or a ``MeshFormatError``; anything else propagates."""
    try:
        mesh = reader(data, LIMITS)
    except MeshFormatError as exc:
        assert str(exc), "a refusal must say why"
        assert type(exc) in (MeshFormatError, MeshTooLargeError)  # a 422 or a 413
        return
    assert_sound(mesh, fmt)


# -- the plain reads the fuzz starts from ---------------------------------------------------


@pytest.mark.parametrize(
    ("reader", "data", "fmt"),
    [
        (read_gltf, json.dumps(GLTF_DOCUMENT).encode(), "gltf"),
        (read_glb, glb(GLB_DOCUMENT, BINARY), "glb"),
    ],
)
def test_the_unmutated_document_reads_to_the_expected_mesh(reader, data, fmt):
    """The fuzz is only as good as its starting point: a document that reads, with every
    transform, the indices and both groups taking part."""
    mesh = reader(data, LIMITS)
    assert_sound(mesh, fmt)
    np.testing.assert_allclose(mesh.vertices, EXPECTED_VERTICES, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(mesh.faces, EXPECTED_FACES)
    assert {name: mesh.group_faces([name]).tolist() for name in mesh.groups} == {
        "square": [0, 1],
        "child": [0, 1],
    }


# -- mutations of the JSON ------------------------------------------------------------------


def json_paths(value, prefix: tuple = ()) -> list[tuple]:
    """Every path (dict keys and list indices) into ``value``, the root ``()`` included."""
    paths = [prefix]
    if isinstance(value, dict):
        for key, item in value.items():
            paths += json_paths(item, (*prefix, key))
    elif isinstance(value, list):
        for i, item in enumerate(value):
            paths += json_paths(item, (*prefix, i))
    return paths


def container_paths(document: dict) -> list[tuple]:
    """Paths to the document's objects: where an added key can go."""
    return [p for p in json_paths(document) if isinstance(get_path(document, p), dict)]


def get_path(document, path: tuple):
    for step in path:
        document = document[step]
    return document


def mutate(document: dict, mutations: list[tuple]) -> object:
    """``document`` (deep-copied) with each ``("set", path, value)`` or ``("delete", path)``
    applied in turn; a path an earlier mutation removed is skipped. Setting a missing key
    adds it; the root path replaces the whole document."""
    result: object = json.loads(json.dumps(document))
    for mutation in mutations:
        action, path = mutation[0], mutation[1]
        if not path:
            if action == "set":
                result = mutation[2]
            continue
        try:
            parent = get_path(result, path[:-1])
        except (KeyError, IndexError, TypeError):
            continue
        key = path[-1]
        if isinstance(parent, dict) and isinstance(key, str):
            pass
        elif isinstance(parent, list) and isinstance(key, int) and key < len(parent):
            pass
        else:
            continue
        if action == "set":
            parent[key] = mutation[2]
        elif isinstance(parent, list) or key in parent:
            del parent[key]
    return result


#: Keys the reader looks for (or must ignore) that the base document lacks or could move.
GLTF_KEYS = [
    "asset", "version", "scene", "scenes", "nodes", "children", "mesh", "matrix",
    "translation", "rotation", "scale", "meshes", "primitives", "attributes", "POSITION",
    "indices", "mode", "accessors", "bufferView", "byteOffset", "componentType", "count",
    "type", "sparse", "bufferViews", "buffer", "byteLength", "byteStride", "buffers", "uri",
    "images", "extensionsRequired", "extensionsUsed", "extensions", "extras", "name",
]  # fmt: skip

# Integers where the reader's arithmetic and numpy conversions have edges: glTF enums,
# sizes around the buffer's, 32- and 64-bit limits, and far beyond any float.
SPECIAL_INTS = [
    -1, 0, 1, 2, 3, 4, 5, 6, 7, 11, 12, 16, 48, 60, 64, 65, 5120, 5121, 5123, 5125, 5126,
    2**31 - 1, 2**31, 2**32 - 1, 2**32, 2**53 + 1, 2**63 - 1, 2**63, 2**64, -(2**63),
    10**30, 10**400, -(10**400),
]  # fmt: skip
SPECIAL_FLOATS = [0.0, -0.0, 0.5, 1.5, 1e-300, 5e-324, 1e38, 3.5e38, 1e200, 1e308, -1e308]
SPECIAL_STRINGS = [
    "", "2.0", "1.0", "2.", "VEC3", "VEC2", "SCALAR", "MAT4", "POSITION", "KHR_x",
    "data:application/octet-stream;base64,", "data:,", "data:;base64,AAAA", "file.bin",
    "data:application/octet-stream;base64,\u00e9\u00e9\u00e9\u00e9", "\x00", "\ud7ff\U0001f600",
]  # fmt: skip

# Finite only: the document must stay strict JSON (json.dumps(allow_nan=False)).
json_numbers = st.one_of(
    st.sampled_from(SPECIAL_INTS),
    st.integers(),
    st.sampled_from(SPECIAL_FLOATS),
    st.floats(allow_nan=False, allow_infinity=False),
)
#: Numbers at the ends of float64 (and past them, as integers), drawn often on purpose:
#: uniform draws almost never reach them, and they are where conversions and products fail.
extreme_numbers = st.sampled_from([10**400, -(10**400), 2**1024, 1e308, -1e308, 1e200, 5e-324])
json_scalars = st.one_of(
    st.none(),
    st.booleans(),
    json_numbers,
    st.sampled_from(SPECIAL_STRINGS),
    st.text(max_size=8),
)
json_values = st.one_of(
    json_scalars,
    extreme_numbers,
    st.recursive(
        json_scalars,
        lambda children: st.one_of(
            st.lists(children, max_size=4),
            st.dictionaries(st.sampled_from(GLTF_KEYS) | st.text(max_size=4), children, max_size=4),
        ),
        max_leaves=8,
    ),
    # Lists the shape of a translation, rotation, scale or matrix, so numbers reach the maths.
    st.sampled_from([1, 2, 3, 4, 16]).flatmap(
        lambda n: st.lists(extreme_numbers | json_numbers, min_size=n, max_size=n)
    ),
)


def mutations(document: dict) -> st.SearchStrategy[list[tuple]]:
    """One to three mutations of ``document``: replace the value at any path, delete it, or
    add a glTF key to any object. Half the paths drawn lead to a number of the document
    (counts, offsets, transforms), where most of the reader's arithmetic starts."""
    every = json_paths(document)
    numeric = [p for p in every if isinstance(get_path(document, p), (int, float))]
    paths = st.sampled_from(every) | st.sampled_from(numeric)
    added = st.tuples(st.sampled_from(container_paths(document)), st.sampled_from(GLTF_KEYS)).map(
        lambda pair: (*pair[0], pair[1])
    )
    one = st.one_of(
        st.tuples(st.just("set"), paths, json_values),
        st.tuples(st.just("delete"), paths),
        st.tuples(st.just("set"), added, json_values),
    )
    return st.lists(one, min_size=1, max_size=3)


@given(changes=mutations(GLTF_DOCUMENT))
def test_mutated_gltf_is_read_or_refused(changes):
    """Any value anywhere in a .gltf replaced, deleted or added: a sound mesh or a refusal."""
    note(f"changes={changes!r}")  # this hypothesis prints explicit examples' arguments blank
    document = mutate(GLTF_DOCUMENT, changes)
    read_or_refuse(read_gltf, json.dumps(document, allow_nan=False).encode(), "gltf")


#: The numbers of the node transforms (matrix, translation, rotation, scale).
TRANSFORM_PATHS = [
    p
    for p in json_paths(GLTF_DOCUMENT)
    if len(p) == 4 and p[0] == "nodes" and p[2] in ("matrix", "translation", "rotation", "scale")
]


# Found by this fuzz, now fixed in the reader; kept so they stay fixed:
# 1. an integer too large for a float64 in a transform (JSON allows any integer) raised
#    OverflowError;
@example(changes=[("set", ("nodes", 1, "translation", 0), 10**400)])
# 2. a scale whose 3x3 determinant overflows or underflows (the vertices stay finite)
#    raised numpy RuntimeWarnings from the mirror test.
@example(changes=[("set", ("nodes", 1, "scale", 2), 1e308)])
@example(changes=[("set", ("nodes", 1, "scale", 0), 5e-324)])
@given(
    changes=st.lists(
        st.tuples(st.just("set"), st.sampled_from(TRANSFORM_PATHS), extreme_numbers | json_numbers),
        min_size=1,
        max_size=3,
    )
)
def test_extreme_transform_numbers_are_read_or_refused(changes):
    """The general mutation above reaches a transform's number with an extreme value only
    now and then; this draws only those, so the float conversion, the matrix products and
    the mirroring test meet huge integers, 1e308 and denormals on every run."""
    note(f"changes={changes!r}")
    document = mutate(GLTF_DOCUMENT, changes)
    read_or_refuse(read_gltf, json.dumps(document, allow_nan=False).encode(), "gltf")


# -- mutations of the GLB container ---------------------------------------------------------

u32s = st.one_of(st.integers(0, 2**32 - 1), st.sampled_from([0, 1, 2, 4, 8, 12, 2**31, 2**32 - 1]))
f32s = st.floats(width=32) | st.sampled_from([math.nan, math.inf, -math.inf, 3.4e38, -0.0])
FIELDS = ["magic", "version", "length", "json_length", "json_type", "bin_length", "bin_type"]

#: Damage to the container, located by name so a pinned example stays readable:
#: a header field set or nudged, a float written into the binary chunk (NaN, Inf, huge),
#: any byte overwritten (offset taken modulo the length), the file cut or extended.
byte_damage = st.one_of(
    st.tuples(st.just("u32"), st.sampled_from(FIELDS), u32s),
    st.tuples(st.just("nudge"), st.sampled_from(FIELDS), st.integers(-9, 9)),
    st.tuples(st.just("f32"), st.integers(0, len(BINARY) // 4 - 1), f32s),
    st.tuples(st.just("byte"), st.integers(0, 2**16), st.integers(0, 255)),
    st.tuples(st.just("cut"), st.integers(0, 2**16)),
    st.tuples(st.just("append"), st.binary(max_size=24)),
)


def damage(data: bytes, changes: list[tuple]) -> bytes:
    """``data`` with each of ``byte_damage``'s changes applied in turn; field offsets are
    those of the undamaged container, and a change past the (possibly cut) end is skipped."""
    fields = glb_fields(data)
    out = bytearray(data)
    for change in changes:
        kind = change[0]
        if kind in ("u32", "nudge", "f32"):
            if kind == "f32":
                at, packed = fields["bin_data"] + 4 * change[1], struct.pack("<f", change[2])
            else:
                at = fields[change[1]]
                old = struct.unpack_from("<I", out, at)[0] if at + 4 <= len(out) else 0
                new = change[2] if kind == "u32" else (old + change[2]) % 2**32
                packed = struct.pack("<I", new)
            if at + 4 <= len(out):
                out[at : at + 4] = packed
        elif kind == "byte" and out:
            out[change[1] % len(out)] = change[2]
        elif kind == "cut":
            del out[change[1] % (len(out) + 1) :]
        elif kind == "append":
            out += change[1]
    return bytes(out)


# Bug 1 above, through a GLB's column-major matrix.
@example(changes=[("set", ("nodes", 0, "matrix", 0), -(10**400))], damages=[])
@given(
    changes=st.just([]) | mutations(GLB_DOCUMENT),
    damages=st.lists(byte_damage, max_size=3),
)
def test_mutated_glb_is_read_or_refused(changes, damages):
    """A GLB whose JSON chunk is mutated as above (or not) and whose container is then
    damaged (or not): a sound mesh or a refusal."""
    note(f"changes={changes!r}, damages={damages!r}")
    document = mutate(GLB_DOCUMENT, changes)
    data = glb(document, BINARY)
    read_or_refuse(read_glb, damage(data, damages), "glb")
