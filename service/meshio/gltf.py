"""glTF 2.0 (``.gltf`` with embedded ``data:`` buffers) and GLB, read from memory.

Rules (the API documentation repeats them):

* only the uploaded bytes are read: a buffer or image with any URI other than ``data:`` is
  refused, and so is any size the file declares that its bytes do not hold;
* triangles come primitive by primitive in document order: the nodes of the default scene
  depth first (children in order), each node's mesh's primitives in order, with the node's
  world transform applied to the positions (a mirroring transform also reverses the
  triangles' winding, as glTF prescribes); vertices come in the same order, each
  primitive's POSITION elements in turn; with no scene, root nodes in order; with no nodes,
  meshes in order;
* triangle lists, strips and fans are read; points and lines are refused, and so are files
  that require an extension (Draco or meshopt compression, for example);
* groups are mesh names and node names;
* a primitive's ``COLOR_0`` (white where a primitive has none), ``TEXCOORD_0`` and custom
  scalar attributes (``_FEATURE_ID_0``, ...; the first ``MAX_PROPERTIES``) are kept a
  vertex (:class:`mesh.Attributes`); other attributes are skipped.

Every value of the JSON is type-checked where it is read, and every count is checked against
the limits and against the bytes that hold it before anything is allocated for it.

Memory: the buffers are read in place (a GLB's binary chunk is a view of the upload), and the
(n, 3) float64 vertices and (m, 3) int64 faces are made once, from the declared counts, and
filled a block of elements at a time, so a read needs them plus a constant (a few MiB) and
the JSON document. They are at most 8 bytes a byte of the file except where the file says
little and means much: a strip or fan's index of 1 or 2 bytes is a 24-byte triangle (24 or
12 bytes a byte), and a mesh that many nodes use, or an accessor that many primitives share,
is read once for each, bounded only by the limits (``MESHFLAT_MAX_VERTICES`` and
``MESHFLAT_MAX_FACES``: 240 MB at most). ``json`` makes Python objects of the JSON: some 20
bytes a byte of JSON made of empty lists, a few of a usual document's.
"""

from __future__ import annotations

import base64
import binascii
import json
import struct
from dataclasses import dataclass

import numpy as np

from .attributes import kept_properties, unit_scale
from .mesh import (
    Attributes,
    Limits,
    Mesh,
    MeshFormatError,
    MeshTooLargeError,
    check_counts,
    checked_vertices,
)

_GLB_MAGIC = 0x46546C67  # "glTF"
_JSON_CHUNK = 0x4E4F534A
_BIN_CHUNK = 0x004E4942
_COMPONENTS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_COMPONENT_TYPES = {
    5120: np.dtype("<i1"),
    5121: np.dtype("<u1"),
    5122: np.dtype("<i2"),
    5123: np.dtype("<u2"),
    5125: np.dtype("<u4"),
    5126: np.dtype("<f4"),
}
_FLOAT, _INDEX_TYPES = (5126,), (5121, 5123, 5125)
_TRIANGLES, _STRIP, _FAN = 4, 5, 6
_NOT_TRIANGLES = {0: "points", 1: "lines", 2: "line loops", 3: "line strips"}
_MAX_DEPTH = 64


def read_glb(data: bytes | memoryview, limits: Limits) -> Mesh:
    """Parse a GLB container: header, JSON chunk, optional BIN chunk."""
    if len(data) < 12:
        raise MeshFormatError(f"the file has {len(data)} bytes; a GLB header alone has 12")
    magic, version, length = struct.unpack_from("<III", data, 0)
    if magic != _GLB_MAGIC:
        raise MeshFormatError("not a GLB file: it does not start with 'glTF'")
    if version != 2:
        raise MeshFormatError(f"GLB version {version}; only glTF 2.0 is read")
    if length != len(data):
        raise MeshFormatError(
            f"the GLB header declares {length:,} bytes but the file has {len(data):,}"
        )
    chunks, offset = [], 12
    while offset < len(data):
        if offset + 8 > len(data):
            raise MeshFormatError(f"GLB chunk header at byte {offset} is cut short")
        chunk_length, chunk_type = struct.unpack_from("<II", data, offset)
        start = offset + 8
        if start + chunk_length > len(data):
            raise MeshFormatError(
                f"GLB chunk at byte {offset} declares {chunk_length:,} bytes but only "
                f"{len(data) - start:,} follow"
            )
        chunks.append((chunk_type, memoryview(data)[start : start + chunk_length]))
        offset = start + chunk_length
    if not chunks or chunks[0][0] != _JSON_CHUNK:
        raise MeshFormatError("the first GLB chunk must be the JSON chunk")
    binary = chunks[1][1] if len(chunks) > 1 and chunks[1][0] == _BIN_CHUNK else None
    return _read_document(_parse_json(chunks[0][1]), binary, limits, "glb")


def read_gltf(data: bytes | memoryview, limits: Limits) -> Mesh:
    """Parse a ``.gltf`` JSON document whose buffers are embedded ``data:`` URIs."""
    return _read_document(_parse_json(data), None, limits, "gltf")


def _parse_json(text: bytes | memoryview) -> dict:
    try:
        # As json.loads decodes bytes (UTF-8, or UTF-16/32 by their BOM), without first
        # copying a memoryview to bytes.
        document = json.loads(str(text, json.detect_encoding(bytes(text[:4])), "surrogatepass"))
    except RecursionError:
        raise MeshFormatError("the glTF JSON nests too deeply to be a glTF document") from None
    except (UnicodeDecodeError, ValueError) as exc:  # ValueError: also over-long integers
        raise MeshFormatError(f"the glTF JSON is not valid JSON: {exc}") from None
    if not isinstance(document, dict):
        raise MeshFormatError("the glTF JSON must be an object")
    asset = document.get("asset")
    version = asset.get("version") if isinstance(asset, dict) else None
    if not isinstance(version, str) or not version.startswith("2."):
        shown = "missing" if version is None else f"{version!r}"
        raise MeshFormatError(f"asset.version is {shown}; only glTF 2.0 is read")
    required = document.get("extensionsRequired", [])
    if required:
        names = ", ".join(map(str, required)) if isinstance(required, list) else repr(required)
        raise MeshFormatError(
            f"the file requires the extensions {names}; meshflat reads plain glTF 2.0 "
            "(export without compression or other required extensions)"
        )
    return document


# -- typed access to the JSON -------------------------------------------------------------


def _index(value, name: str) -> int:
    if not isinstance(value, int) or isinstance(value, bool) or value < 0:
        raise MeshFormatError(f"{name} must be a non-negative integer, got {_shown(value)}")
    return value


def _list(value, name: str) -> list:
    if not isinstance(value, list):
        raise MeshFormatError(f"{name} must be a list, got {_shown(value)}")
    return value


def _numbers(value, count: int, name: str) -> np.ndarray:
    if (
        not isinstance(value, list)
        or len(value) != count
        or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
    ):
        raise MeshFormatError(f"{name} must be a list of {count} numbers, got {_shown(value)}")
    try:
        array = np.asarray(value, dtype=np.float64)
    except OverflowError:  # JSON integers have no bound
        raise MeshFormatError(f"{name} holds a number beyond a 64-bit float") from None
    if not np.isfinite(array).all():
        raise MeshFormatError(f"{name} holds a NaN or Inf")
    return array


def _shown(value) -> str:
    text = json.dumps(value) if not isinstance(value, float) else repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


class _Document:
    """A glTF JSON document whose every reference is checked as it is followed."""

    def __init__(self, document: dict, binary, limits: Limits) -> None:
        self.json = document
        self.binary = binary
        self.limits = limits
        self._buffers: dict[int, memoryview] = {}
        for i, image in enumerate(self.list("images")):
            uri = image.get("uri") if isinstance(image, dict) else None
            if isinstance(uri, str) and not uri.startswith("data:"):
                raise MeshFormatError(
                    f"images[{i}] refers to the external file {uri!r}; meshflat reads only "
                    "the uploaded bytes"
                )

    def list(self, key: str) -> list:
        return _list(self.json.get(key, []), f"'{key}'")

    def item(self, key: str, index, where: str) -> dict:
        items = self.list(key)
        if not isinstance(index, int) or isinstance(index, bool) or not 0 <= index < len(items):
            raise MeshFormatError(f"{where} refers to {key}[{_shown(index)}], which does not exist")
        item = items[index]
        if not isinstance(item, dict):
            raise MeshFormatError(f"{key}[{index}] must be an object")
        return item

    def buffer(self, index, where: str) -> memoryview:
        spec = self.item("buffers", index, where)
        if index in self._buffers:
            return self._buffers[index]
        declared = _index(spec.get("byteLength"), f"buffers[{index}].byteLength")
        uri = spec.get("uri")
        if uri is None:
            if self.binary is None or index != 0:
                raise MeshFormatError(f"buffers[{index}] has no uri and no GLB binary chunk")
            data = self.binary
        elif isinstance(uri, str) and uri.startswith("data:"):
            data = memoryview(self._decode_data_uri(uri, index))
        else:
            raise MeshFormatError(
                f"buffers[{index}] refers to the external file {_shown(uri)}; upload a GLB, "
                "or a glTF whose buffers are embedded data: URIs"
            )
        if len(data) < declared:
            raise MeshFormatError(
                f"buffers[{index}] declares {declared:,} bytes but holds {len(data):,}"
            )
        self._buffers[index] = data
        return data

    def _decode_data_uri(self, uri: str, index: int) -> bytes:
        header, _, payload = uri.partition(",")
        if not header.endswith(";base64"):
            raise MeshFormatError(f"buffers[{index}] data: URI is not base64")
        if len(payload) * 3 // 4 > self.limits.max_bytes:
            raise MeshTooLargeError(
                f"buffers[{index}] data: URI decodes to about {len(payload) * 3 // 4:,} bytes; "
                f"the limit is {self.limits.max_bytes:,} (MESHFLAT_MAX_UPLOAD_BYTES)",
            )
        try:
            return base64.b64decode(payload, validate=True)
        except (binascii.Error, ValueError):
            raise MeshFormatError(f"buffers[{index}] data: URI is not valid base64") from None

    def accessor(self, index, where: str, widths: tuple[int, ...], types) -> _Accessor:
        """An accessor's layout, checked against its buffer view, without reading it."""
        spec = self.item("accessors", index, where)
        name = f"accessors[{index}]"
        if "sparse" in spec:
            raise MeshFormatError(f"{name} is sparse; sparse accessors are not read")
        kind = spec.get("type")
        width = _COMPONENTS.get(kind) if isinstance(kind, str) else None
        if width not in widths:
            raise MeshFormatError(f"{name} has type {_shown(kind)}, not one {where} accepts")
        component_type = spec.get("componentType")
        if not isinstance(component_type, int) or component_type not in types:
            raise MeshFormatError(
                f"{name} has componentType {_shown(component_type)}, not one {where} "
                f"accepts ({', '.join(map(str, types))})"
            )
        dtype = _COMPONENT_TYPES[component_type]
        count = _index(spec.get("count"), f"{name}.count")
        if "bufferView" not in spec:
            raise MeshFormatError(
                f"{name} has no bufferView (all its values would be zero); {where} needs data"
            )
        view_index = spec["bufferView"]
        view = self.item("bufferViews", view_index, name)
        view_name = f"bufferViews[{view_index}]"
        buffer = self.buffer(view.get("buffer"), view_name)
        view_offset = _index(view.get("byteOffset", 0), f"{view_name}.byteOffset")
        view_length = _index(view.get("byteLength"), f"{view_name}.byteLength")
        if view_offset + view_length > len(buffer):
            raise MeshFormatError(
                f"{view_name} spans bytes {view_offset:,} to {view_offset + view_length:,} "
                f"of a buffer of {len(buffer):,}"
            )
        element = width * dtype.itemsize
        stride = _index(view.get("byteStride", element), f"{view_name}.byteStride") or element
        if stride < element:
            raise MeshFormatError(f"{view_name}.byteStride {stride} is below the element size")
        offset = _index(spec.get("byteOffset", 0), f"{name}.byteOffset")
        needed = offset + (stride * (count - 1) + element if count else 0)
        if needed > view_length:
            raise MeshFormatError(
                f"{name} declares {count:,} elements ({needed:,} bytes) but {view_name} "
                f"holds {view_length:,} bytes"
            )
        return _Accessor(buffer, view_offset, view_length, offset, count, width, dtype, stride)


@dataclass(frozen=True)
class _Accessor:
    """Where an accessor's elements lie; :meth:`view` shows them."""

    buffer: memoryview
    view_offset: int
    view_length: int
    offset: int
    count: int
    width: int
    dtype: np.dtype
    stride: int

    def view(self) -> np.ndarray:
        """(count, width) array of the elements: a view of the buffer (no copy)."""
        if self.count == 0:
            return np.zeros((0, self.width), dtype=self.dtype)
        raw = np.frombuffer(
            self.buffer, dtype=np.uint8, count=self.view_length, offset=self.view_offset
        )
        return np.ndarray(
            shape=(self.count, self.width),
            dtype=self.dtype,
            buffer=raw,
            offset=self.offset,
            strides=(self.stride, self.dtype.itemsize),
        )


@dataclass(frozen=True)
class _Primitive:
    where: str
    node_index: int
    mesh_index: int
    mode: int
    positions: _Accessor
    indices: _Accessor | None
    transform: np.ndarray
    extras: dict[str, _Accessor]  # COLOR_0, TEXCOORD_0 and custom ("_" ...) attributes

    @property
    def triangle_count(self) -> int:
        count = self.indices.count if self.indices is not None else self.positions.count
        if self.mode == _TRIANGLES:
            if count % 3:
                raise MeshFormatError(f"{self.where} has {count} indices, not a multiple of 3")
            return count // 3
        return max(count - 2, 0)


def _read_document(document: dict, binary, limits: Limits, fmt: str) -> Mesh:
    doc = _Document(document, binary, limits)
    instances = _mesh_instances(doc)
    if not instances:
        raise MeshFormatError("the glTF document has no meshes")
    primitives = [
        primitive
        for node_index, mesh_index, transform in instances
        for primitive in _primitives(doc, node_index, mesh_index, transform)
    ]
    # The limits, from the declared counts, before any array is allocated.
    n_vertices = sum(p.positions.count for p in primitives)
    n_faces = sum(p.triangle_count for p in primitives)
    check_counts(n_vertices, n_faces, limits)
    vertices = np.empty((n_vertices, 3), dtype=np.float64)
    faces = np.empty((n_faces, 3), dtype=np.int64)
    groups: dict[str, list] = {}
    offset = face_offset = 0
    for primitive in primitives:
        count, triangles = primitive.positions.count, primitive.triangle_count
        _read_triangles(primitive, faces[face_offset : face_offset + triangles], offset)
        _read_positions(primitive, vertices[offset : offset + count])
        span = (face_offset, face_offset + triangles)
        names = {_name(document, "meshes", primitive.mesh_index)}
        if primitive.node_index >= 0:
            names.add(_name(document, "nodes", primitive.node_index))
        for name in names - {None}:  # a set: a node often shares its mesh's name
            groups.setdefault(name, []).append(span)
        offset += count
        face_offset += triangles
    if face_offset == 0:
        raise MeshFormatError("the glTF file holds no triangles")
    return Mesh(
        vertices=checked_vertices(vertices),
        faces=faces,
        groups={name: np.array(spans, dtype=np.int64) for name, spans in groups.items()},
        format=fmt,
        attributes=_read_extras(primitives, n_vertices, faces),
    )


#: Elements of an accessor converted at a time (the temporaries stay this small).
_BLOCK = 1 << 16


def _read_positions(primitive: _Primitive, out: np.ndarray) -> None:
    """Write a primitive's POSITION elements, world-transformed, into ``out`` ((n, 3)
    float), a block at a time."""
    transform = primitive.transform
    if not np.isfinite(transform).all():
        raise MeshFormatError(f"the world transform of {primitive.where} overflows")
    positions = primitive.positions.view()
    for start in range(0, len(positions), _BLOCK):
        block = out[start : start + _BLOCK]
        block[...] = positions[start : start + _BLOCK]
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            # checked_vertices refuses an overflow
            np.matmul(block, transform[:3, :3].T, out=block)
            block += transform[:3, 3]


def _read_triangles(primitive: _Primitive, out: np.ndarray, offset: int) -> None:
    """Write a primitive's (t, 3) triangles, as ids into the mesh's vertices from
    ``offset``, into ``out``, a block of triangles at a time."""
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        # slogdet: the sign, never overflowing; a mirroring transform reverses the winding
        mirrored = np.linalg.slogdet(primitive.transform[:3, :3])[0] < 0
    indices = primitive.indices.view()[:, 0] if primitive.indices is not None else None
    largest, count = -1, primitive.positions.count
    for start in range(0, len(out), _BLOCK):
        block = out[start : start + _BLOCK]
        block[...] = _triangles(indices, primitive.mode, start, len(block))
        largest = max(largest, int(block.max()))
        if mirrored:
            block[...] = block[:, ::-1]
        block += offset
    if largest >= count:
        raise MeshFormatError(
            f"{primitive.where} indices refer to vertex {largest} but its POSITION holds {count}"
        )


def _primitives(doc: _Document, node_index: int, mesh_index, transform) -> list[_Primitive]:
    """The primitives of one mesh instance, their layouts checked."""
    mesh = doc.item("meshes", mesh_index, f"nodes[{node_index}]" if node_index >= 0 else "")
    parts = _list(mesh.get("primitives", []), f"meshes[{mesh_index}].primitives")
    if not parts:
        raise MeshFormatError(f"meshes[{mesh_index}] has no primitives")
    primitives = []
    for p, primitive in enumerate(parts):
        where = f"meshes[{mesh_index}].primitives[{p}]"
        if not isinstance(primitive, dict):
            raise MeshFormatError(f"{where} must be an object")
        mode = primitive.get("mode", _TRIANGLES)
        if isinstance(mode, int) and mode in _NOT_TRIANGLES:
            raise MeshFormatError(
                f"{where} draws {_NOT_TRIANGLES[mode]} (mode {mode}); only triangles can be "
                "flattened"
            )
        if not isinstance(mode, int) or isinstance(mode, bool) or mode not in (4, 5, 6):
            raise MeshFormatError(f"{where} has an unknown mode {_shown(mode)}")
        attributes = primitive.get("attributes")
        if not isinstance(attributes, dict) or "POSITION" not in attributes:
            raise MeshFormatError(f"{where} has no POSITION attribute")
        positions = doc.accessor(attributes["POSITION"], f"{where} POSITION", (3,), _FLOAT)
        indices = None
        if "indices" in primitive:
            indices = doc.accessor(primitive["indices"], f"{where} indices", (1,), _INDEX_TYPES)
        extras = _extra_accessors(doc, attributes, where, positions.count)
        primitives.append(
            _Primitive(where, node_index, mesh_index, mode, positions, indices, transform, extras)
        )
    return primitives


#: The attributes read besides POSITION: name -> (accepted widths, component types).
_COLOR_TYPES = (5126, 5121, 5123)
_EXTRAS = {"COLOR_0": ((3, 4), _COLOR_TYPES), "TEXCOORD_0": ((2,), _COLOR_TYPES)}


def _extra_accessors(doc: _Document, attributes: dict, where: str, count: int) -> dict:
    """The primitive's COLOR_0, TEXCOORD_0 and custom (``_FEATURE_ID_0``, ...) scalar
    attributes, checked to hold one element a vertex."""
    found = {}
    for name, index in attributes.items():
        if name in _EXTRAS:
            widths, types = _EXTRAS[name]
        elif isinstance(name, str) and name.startswith("_"):
            widths, types = (1,), tuple(_COMPONENT_TYPES)
        else:
            continue
        accessor = doc.accessor(index, f"{where} {name}", widths, types)
        if accessor.count != count:
            raise MeshFormatError(
                f"{where} {name} holds {accessor.count:,} elements but POSITION {count:,}"
            )
        normalized = doc.item("accessors", index, where).get("normalized") is True
        found[name] = (accessor, normalized or accessor.dtype.kind == "f")
    return found


def _read_extras(primitives: list[_Primitive], n_vertices: int, faces: np.ndarray):
    """The vertices' colours, texture coordinates and custom attributes, primitive by
    primitive (a primitive without one: white, no texture coordinates, NaN)."""
    names = sorted({name for p in primitives for name in p.extras})
    if not names:
        return Attributes()
    colors = np.ones((n_vertices, 4), dtype=np.float32) if "COLOR_0" in names else None
    uv = np.full((n_vertices, 2), np.nan) if "TEXCOORD_0" in names else None
    custom = kept_properties([name for name in names if name.startswith("_")])
    values = {name: np.full(n_vertices, np.nan) for name in custom}
    offset = 0
    for primitive in primitives:
        count = primitive.positions.count
        for name, (accessor, unit) in primitive.extras.items():
            if name.startswith("_") and name not in values:
                continue
            view = accessor.view()
            scale = unit_scale(accessor.dtype) if unit else 1.0
            for start in range(0, count, _BLOCK):
                block = slice(offset + start, offset + min(start + _BLOCK, count))
                part = view[start : start + _BLOCK].astype(np.float64) * scale
                if name == "COLOR_0":
                    colors[block, : part.shape[1]] = np.clip(np.nan_to_num(part), 0.0, 1.0)
                elif name == "TEXCOORD_0":
                    uv[block] = part
                else:
                    values[name][block] = part[:, 0]
        offset += count
    uv_faces = None
    if uv is not None:
        missing = np.isnan(uv[:, 0])
        uv_faces = np.where(missing[faces], -1, faces) if missing.any() else faces
    return Attributes(colors=colors, uv=uv, uv_faces=uv_faces, vertex=values)


def _triangles(indices: np.ndarray | None, mode: int, first: int, count: int) -> np.ndarray:
    """(count, 3) int: triangles ``first`` to ``first + count`` of a triangle list, strip or
    fan (counts already checked) of ``indices`` (None: the vertices in order)."""
    if mode == _TRIANGLES:
        corners = np.arange(3 * first, 3 * (first + count))
    else:
        corners = np.arange(first, first + count + 2)
    ids = corners if indices is None else indices[corners].astype(np.int64)
    if mode == _TRIANGLES:
        return ids.reshape(-1, 3)
    k = np.arange(count)
    if mode == _STRIP:  # every other triangle swaps two corners to keep the winding
        odd = (first + k) % 2 == 1
        a = np.where(odd, ids[k + 1], ids[k])
        b = np.where(odd, ids[k], ids[k + 1])
        return np.stack([a, b, ids[k + 2]], axis=1)
    lead = int(indices[0]) if indices is not None else 0
    return np.stack([np.full(count, lead), ids[k + 1], ids[k + 2]], axis=1)


def _name(document: dict, key: str, index: int) -> str | None:
    items = document.get(key, [])
    if isinstance(items, list) and 0 <= index < len(items) and isinstance(items[index], dict):
        name = items[index].get("name")
        return name if isinstance(name, str) and name else None
    return None


def _mesh_instances(doc: _Document) -> list[tuple[int, int, np.ndarray]]:
    """(node index or -1, mesh index, 4x4 world transform) in document order."""
    nodes = doc.list("nodes")
    if not nodes:
        return [(-1, m, np.eye(4)) for m in range(len(doc.list("meshes")))]
    scenes = doc.list("scenes")
    if scenes:
        scene_index = doc.json.get("scene", 0)
        roots = _list(doc.item("scenes", scene_index, "scene").get("nodes", []), "scene nodes")
    else:
        children = set()
        for i, node in enumerate(nodes):
            if isinstance(node, dict):
                listed = _list(node.get("children", []), f"nodes[{i}].children")
                children.update(c for c in listed if isinstance(c, int))
        roots = [i for i in range(len(nodes)) if i not in children]
        if not roots:
            raise MeshFormatError("the glTF has no scene and no root node (every node is a child)")
    instances: list[tuple[int, int, np.ndarray]] = []
    stack = [(index, np.eye(4), 0) for index in reversed(roots)]
    seen: set[int] = set()
    while stack:
        index, parent, depth = stack.pop()
        node = doc.item("nodes", index, "the scene graph")
        if index in seen:
            raise MeshFormatError(f"nodes[{index}] appears twice in the scene graph (a cycle?)")
        if depth > _MAX_DEPTH:
            raise MeshFormatError(f"nodes[{index}] lies deeper than {_MAX_DEPTH} levels")
        seen.add(index)
        with np.errstate(over="ignore", invalid="ignore"):  # an overflow is refused later
            world = parent @ _local_matrix(node, index)
        if "mesh" in node:
            instances.append((index, node["mesh"], world))
        children = _list(node.get("children", []), f"nodes[{index}].children")
        stack.extend((child, world, depth + 1) for child in reversed(children))
    return instances


def _local_matrix(node: dict, index: int) -> np.ndarray:
    """A node's local 4x4 transform from ``matrix`` (column-major) or T * R * S."""
    name = f"nodes[{index}]"
    if "matrix" in node:
        return _numbers(node["matrix"], 16, f"{name}.matrix").reshape(4, 4).T
    t = _numbers(node.get("translation", [0.0, 0.0, 0.0]), 3, f"{name}.translation")
    x, y, z, w = _numbers(node.get("rotation", [0.0, 0.0, 0.0, 1.0]), 4, f"{name}.rotation")
    s = _numbers(node.get("scale", [1.0, 1.0, 1.0]), 3, f"{name}.scale")
    rotation = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )
    result = np.eye(4)
    result[:3, :3] = rotation * s
    result[:3, 3] = t
    return result
