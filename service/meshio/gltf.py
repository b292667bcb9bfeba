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
* triangle lists, strips and fans are read; points and lines are refused;
* groups are mesh names and node names.
"""

from __future__ import annotations

import base64
import binascii
import json
import struct

import numpy as np

from .mesh import Limits, Mesh, MeshFormatError, check_counts

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
_MODES = {0: "points", 1: "lines", 2: "line loops", 3: "line strips"}
_MAX_DEPTH = 64


def read_glb(data: bytes, limits: Limits) -> Mesh:
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
    return _read_document(_parse_json(bytes(chunks[0][1])), binary, limits, "glb")


def read_gltf(data: bytes, limits: Limits) -> Mesh:
    """Parse a ``.gltf`` JSON document whose buffers are embedded ``data:`` URIs."""
    return _read_document(_parse_json(data), None, limits, "gltf")


def _parse_json(text: bytes) -> dict:
    try:
        document = json.loads(text)
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise MeshFormatError(f"the glTF JSON is not valid JSON: {exc}") from None
    if not isinstance(document, dict):
        raise MeshFormatError("the glTF JSON must be an object")
    version = str(document.get("asset", {}).get("version", ""))
    if not version.startswith("2."):
        raise MeshFormatError(f"asset.version is {version!r}; only glTF 2.0 is read")
    return document


class _Document:
    """Typed access to a glTF JSON document with every reference checked."""

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
        value = self.json.get(key, [])
        if not isinstance(value, list):
            raise MeshFormatError(f"'{key}' must be a list")
        return value

    def item(self, key: str, index, where: str) -> dict:
        items = self.list(key)
        if not isinstance(index, int) or isinstance(index, bool) or not 0 <= index < len(items):
            raise MeshFormatError(f"{where} refers to {key}[{index}], which does not exist")
        item = items[index]
        if not isinstance(item, dict):
            raise MeshFormatError(f"{key}[{index}] must be an object")
        return item

    def buffer(self, index: int, where: str) -> memoryview:
        if index in self._buffers:
            return self._buffers[index]
        spec = self.item("buffers", index, where)
        declared = _count(spec.get("byteLength"), f"buffers[{index}].byteLength")
        uri = spec.get("uri")
        if uri is None:
            if self.binary is None or index != 0:
                raise MeshFormatError(f"buffers[{index}] has no uri and no GLB binary chunk")
            data = self.binary
        elif isinstance(uri, str) and uri.startswith("data:"):
            data = memoryview(self._decode_data_uri(uri, index))
        else:
            raise MeshFormatError(
                f"buffers[{index}] refers to the external file {uri!r}; upload a GLB, or a "
                "glTF whose buffers are embedded data: URIs"
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
            raise MeshFormatError(
                f"buffers[{index}] data: URI decodes to about {len(payload) * 3 // 4:,} bytes; "
                f"the limit is {self.limits.max_bytes:,} (MESHFLAT_MAX_UPLOAD_BYTES)",
                status=413,
            )
        try:
            return base64.b64decode(payload, validate=True)
        except (binascii.Error, ValueError):
            raise MeshFormatError(f"buffers[{index}] data: URI is not valid base64") from None

    def accessor(self, index, where: str, components: tuple[int, ...], types) -> np.ndarray:
        """Read an accessor as a (count, components) array, checking it fits its view."""
        spec = self.item("accessors", index, where)
        name = f"accessors[{index}]"
        if "sparse" in spec:
            raise MeshFormatError(f"{name} is sparse; sparse accessors are not read")
        kind = spec.get("type")
        if _COMPONENTS.get(kind) not in components:
            raise MeshFormatError(f"{name} has type {kind!r}, {where} needs {components}")
        dtype = _COMPONENT_TYPES.get(spec.get("componentType"))
        if dtype is None or spec.get("componentType") not in types:
            raise MeshFormatError(
                f"{name} has componentType {spec.get('componentType')!r}, not one {where} "
                f"accepts ({', '.join(map(str, types))})"
            )
        width = _COMPONENTS[kind]
        count = _count(spec.get("count"), f"{name}.count")
        if "bufferView" not in spec:
            return np.zeros((count, width), dtype=dtype)
        view_index = spec["bufferView"]
        view = self.item("bufferViews", view_index, name)
        view_name = f"bufferViews[{view_index}]"
        buffer = self.buffer(view.get("buffer"), view_name)
        view_offset = _count(view.get("byteOffset", 0), f"{view_name}.byteOffset")
        view_length = _count(view.get("byteLength"), f"{view_name}.byteLength")
        if view_offset + view_length > len(buffer):
            raise MeshFormatError(
                f"{view_name} spans bytes {view_offset:,} to {view_offset + view_length:,} "
                f"of a buffer of {len(buffer):,}"
            )
        element = width * dtype.itemsize
        stride = _count(view.get("byteStride", element), f"{view_name}.byteStride") or element
        if stride < element:
            raise MeshFormatError(f"{view_name}.byteStride {stride} is below the element size")
        offset = _count(spec.get("byteOffset", 0), f"{name}.byteOffset")
        needed = offset + (stride * (count - 1) + element if count else 0)
        if needed > view_length:
            raise MeshFormatError(
                f"{name} declares {count:,} elements ({needed:,} bytes) but {view_name} "
                f"holds {view_length:,} bytes"
            )
        if count == 0:
            return np.zeros((0, width), dtype=dtype)
        raw = np.frombuffer(buffer, dtype=np.uint8, count=view_length, offset=view_offset)
        array = np.ndarray(
            shape=(count, width),
            dtype=dtype,
            buffer=raw,
            offset=offset,
            strides=(stride, dtype.itemsize),
        )
        return array.copy()


def _count(value, name: str) -> int:
    if not isinstance(value, int) or isinstance(value, bool) or value < 0:
        raise MeshFormatError(f"{name} must be a non-negative integer, got {value!r}")
    return value


def _read_document(document: dict, binary, limits: Limits, fmt: str) -> Mesh:
    doc = _Document(document, binary, limits)
    instances = _mesh_instances(doc)
    if not instances:
        raise MeshFormatError("the glTF document has no meshes")
    # Read every primitive once and count before assembling (limits first).
    primitives = []
    for node_index, mesh_index, transform in instances:
        mesh = doc.item("meshes", mesh_index, f"nodes[{node_index}]" if node_index >= 0 else "")
        parts = mesh.get("primitives", [])
        if not isinstance(parts, list) or not parts:
            raise MeshFormatError(f"meshes[{mesh_index}] has no primitives")
        for p, primitive in enumerate(parts):
            primitives.append((node_index, mesh_index, p, primitive, transform))
    vertex_total, face_total, decoded = 0, 0, []
    for node_index, mesh_index, p, primitive, transform in primitives:
        where = f"meshes[{mesh_index}].primitives[{p}]"
        if not isinstance(primitive, dict):
            raise MeshFormatError(f"{where} must be an object")
        mode = primitive.get("mode", 4)
        if mode in _MODES:
            raise MeshFormatError(
                f"{where} draws {_MODES[mode]} (mode {mode}); only triangles can be flattened"
            )
        if mode not in (4, 5, 6):
            raise MeshFormatError(f"{where} has an unknown mode {mode!r}")
        attributes = primitive.get("attributes", {})
        if not isinstance(attributes, dict) or "POSITION" not in attributes:
            raise MeshFormatError(f"{where} has no POSITION attribute")
        positions = doc.accessor(attributes["POSITION"], f"{where} POSITION", (3,), (5126,))
        if "indices" in primitive:
            indices = (
                doc.accessor(primitive["indices"], f"{where} indices", (1,), (5121, 5123, 5125))
                .ravel()
                .astype(np.int64)
            )
        else:
            indices = np.arange(len(positions), dtype=np.int64)
        triangles = _triangles(indices, mode, where)
        if triangles.size and int(triangles.max()) >= len(positions):
            raise MeshFormatError(
                f"{where} indices refer to vertex {int(triangles.max())} but its POSITION "
                f"holds {len(positions)}"
            )
        vertex_total += len(positions)
        face_total += len(triangles)
        check_counts(vertex_total, face_total, limits)
        decoded.append((node_index, mesh_index, positions, triangles, transform))

    vertices, faces, groups, offset, face_offset = [], [], {}, 0, 0
    for node_index, mesh_index, positions, triangles, transform in decoded:
        points = positions.astype(np.float64) @ transform[:3, :3].T + transform[:3, 3]
        if np.linalg.det(transform[:3, :3]) < 0:
            triangles = triangles[:, ::-1]
        vertices.append(points)
        faces.append(triangles + offset)
        ids = np.arange(face_offset, face_offset + len(triangles))
        # A set: a node often shares its mesh's name. Primitives come in ascending id order,
        # so each group's ids stay ascending and distinct without sorting.
        names = {
            _name(document, "meshes", mesh_index),
            _name(document, "nodes", node_index) if node_index >= 0 else None,
        }
        for name in names - {None}:
            groups.setdefault(name, []).append(ids)
        offset += len(points)
        face_offset += len(triangles)
    vertices = np.ascontiguousarray(np.concatenate(vertices))
    finite = np.isfinite(vertices).all(axis=1)
    if not finite.all():
        raise MeshFormatError(f"vertex {int(np.flatnonzero(~finite)[0])} has a NaN or Inf position")
    return Mesh(
        vertices=vertices,
        faces=np.ascontiguousarray(np.concatenate(faces)),
        groups={name: np.concatenate(parts) for name, parts in groups.items()},
        format=fmt,
    )


def _triangles(indices: np.ndarray, mode: int, where: str) -> np.ndarray:
    """(t, 3) int triangles of a triangle list (4), strip (5) or fan (6)."""
    if mode == 4:
        if len(indices) % 3:
            raise MeshFormatError(f"{where} has {len(indices)} indices, not a multiple of 3")
        return indices.reshape(-1, 3)
    if len(indices) < 3:
        return np.zeros((0, 3), dtype=np.int64)
    k = np.arange(len(indices) - 2)
    if mode == 5:  # strip: every other triangle swaps its first two corners (glTF spec)
        odd = k % 2 == 1
        a = np.where(odd, indices[k + 1], indices[k])
        b = np.where(odd, indices[k], indices[k + 1])
        return np.stack([a, b, indices[k + 2]], axis=1)
    return np.stack([np.full_like(k, indices[0]), indices[k + 1], indices[k + 2]], axis=1)


def _name(document: dict, key: str, index: int) -> str | None:
    items = document.get(key, [])
    if 0 <= index < len(items) and isinstance(items[index], dict):
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
        roots = doc.item("scenes", scene_index, "scene").get("nodes", [])
    else:
        children = {c for node in nodes if isinstance(node, dict) for c in node.get("children", [])}
        roots = [i for i in range(len(nodes)) if i not in children]
        if not roots:
            raise MeshFormatError("the glTF has no scene and no root node (every node is a child)")
    instances: list[tuple[int, int, np.ndarray]] = []
    stack = [(index, np.eye(4), 0) for index in reversed(roots)]
    seen: set[int] = set()
    while stack:
        index, parent, depth = stack.pop()
        node = doc.item("nodes", index, "the scene graph")
        if index in seen or depth > _MAX_DEPTH:
            raise MeshFormatError(f"nodes[{index}] appears twice in the scene graph (a cycle?)")
        seen.add(index)
        world = parent @ _local_matrix(node, index)
        if "mesh" in node:
            instances.append((index, node["mesh"], world))
        children = node.get("children", [])
        if not isinstance(children, list):
            raise MeshFormatError(f"nodes[{index}].children must be a list")
        stack.extend((child, world, depth + 1) for child in reversed(children))
    return instances


def _local_matrix(node: dict, index: int) -> np.ndarray:
    """A node's local 4x4 transform from ``matrix`` (column-major) or T * R * S."""
    try:
        if "matrix" in node:
            matrix = np.asarray(node["matrix"], dtype=np.float64)
            if matrix.shape != (16,):
                raise ValueError
            result = matrix.reshape(4, 4).T
        else:
            t = np.asarray(node.get("translation", [0.0, 0.0, 0.0]), dtype=np.float64)
            x, y, z, w = np.asarray(node.get("rotation", [0.0, 0.0, 0.0, 1.0]), dtype=np.float64)
            s = np.asarray(node.get("scale", [1.0, 1.0, 1.0]), dtype=np.float64)
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
    except (TypeError, ValueError):
        raise MeshFormatError(f"nodes[{index}] has a malformed transform") from None
    if not np.isfinite(result).all():
        raise MeshFormatError(f"nodes[{index}] has a NaN or Inf in its transform")
    return result
