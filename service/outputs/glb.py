"""The flattened region as a binary glTF (GLB) that three.js and other viewers load: the
file's vertex positions, ``TEXCOORD_0`` from the layout, and the file's vertex and face ids.

Layout of the one mesh primitive (triangles):

* ``POSITION``: the region's vertices, in the file's coordinates (float32), in ascending id
  order: the order of ``vertices.ids`` in the JSON answer;
* ``TEXCOORD_0``: the layout scaled into ``[0, 1]`` by one factor (so the map keeps its
  aspect), ``u = (x - x_min) * scale`` and ``v = (s - s_min) * scale`` with ``s`` the layout's
  coordinate that grows with theta (``y`` for theta_phi, ``-y`` for mercator): ``v`` runs
  down an image, as glTF's does, from the region's smallest theta. ``asset.extras.meshflat.uv``
  holds ``scale``, ``x_min``, ``s_min`` and ``s_sign`` (``s = s_sign * y``), so that
  ``x = u / scale + x_min`` and ``y = s_sign * (v / scale + s_min)``;
* ``_VERTEX_ID``: each vertex's id in the file (float32, exact below 2^24; the service reads
  at most ``MESHFLAT_MAX_VERTICES``, 5M by default);
* the indices list the region's triangles in the order of ``faces.ids``: triangle ``k``
  (indices ``3k .. 3k + 2``) is file face ``faces.ids[k]``. The ids themselves are also in
  the accessor ``asset.extras.meshflat.face_ids_accessor`` (unsigned 32-bit integers).

``asset.extras.meshflat`` also holds the resolved ``params`` and the validation summary.
"""

from __future__ import annotations

import io
import struct
from functools import cache

import numpy as np
import orjson
from PIL import Image

#: glTF constants.
_FLOAT, _UNSIGNED_INT = 5126, 5125
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963
_POINTS, _LINES, _TRIANGLES = 0, 1, 4
_GLB_MAGIC, _GLB_VERSION = 0x46546C67, 2
_JSON_CHUNK, _BIN_CHUNK = 0x4E4F534A, 0x004E4942


def layout_uv(x: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, dict]:
    """``TEXCOORD_0`` (k, 2) float32 from the layout ``x`` and ``s`` (growing with theta),
    and the affine map's numbers (see the module docstring)."""
    x_min, s_min = float(x.min()), float(s.min())
    span = max(float(x.max()) - x_min, float(s.max()) - s_min)
    scale = 1.0 / span if span > 0 else 1.0
    uv = np.empty((len(x), 2), dtype=np.float32)
    uv[:, 0] = (x - x_min) * scale
    uv[:, 1] = (s - s_min) * scale
    np.clip(uv, 0.0, 1.0, out=uv)  # float32 rounding must not step outside [0, 1]
    return uv, {"scale": scale, "x_min": x_min, "s_min": s_min}


def region_glb(
    positions: np.ndarray,
    uv: np.ndarray,
    vertex_ids: np.ndarray,
    triangles: np.ndarray,
    face_ids: np.ndarray,
    extras: dict,
    sites: tuple[np.ndarray, np.ndarray] | None = None,
    colours: np.ndarray | None = None,
    lines: tuple[np.ndarray, np.ndarray] | None = None,
    lines_name: str = "growth",
) -> bytes:
    """A GLB of one triangle mesh, of sites on it as a POINTS primitive, and of line
    segments over it as a LINES primitive.

    Parameters
    ----------
    positions : (k, 3) float, the region's vertices
    uv : (k, 2) float32, ``TEXCOORD_0``
    vertex_ids : (k,) int, the file's id of each vertex
    triangles : (m, 3) int, indices into ``positions``
    face_ids : (m,) int, the file's id of each triangle
    extras : dict, JSON-ready, written as ``asset.extras.meshflat`` (with
        ``face_ids_accessor`` added)
    sites : ((n, 3), (n, 3)) float or None: points and their unit normals, a second mesh
        (``sites``: ``POSITION`` and ``NORMAL``, mode POINTS) of a second node
    colours : (k, 3) float or None, ``COLOR_0`` of the region's vertices
    lines : ((2 s, 3), (2 s, 3)) float or None: segments' ends (each pair one segment) and
        their colours in [0, 1], a third mesh (``lines_name``: ``POSITION`` and ``COLOR_0``,
        mode LINES) of a third node

    Returns
    -------
    bytes
    """
    blobs = [
        ("POSITION", np.ascontiguousarray(positions, dtype=np.float32), _ARRAY_BUFFER),
        ("TEXCOORD_0", np.ascontiguousarray(uv, dtype=np.float32), _ARRAY_BUFFER),
        ("_VERTEX_ID", vertex_ids.astype(np.float32), _ARRAY_BUFFER),
        ("indices", triangles.astype(np.uint32).ravel(), _ELEMENT_ARRAY_BUFFER),
        ("face_ids", face_ids.astype(np.uint32), None),
        ("checker", np.frombuffer(_checker_png(), dtype=np.uint8), None),
    ]
    if sites is not None:
        points, normals = (np.ascontiguousarray(a, dtype=np.float32) for a in sites)
        blobs += [("SITE_POSITION", points, _ARRAY_BUFFER), ("NORMAL", normals, _ARRAY_BUFFER)]
    if colours is not None:
        blobs.append(("COLOR_0", np.ascontiguousarray(colours, dtype=np.float32), _ARRAY_BUFFER))
    if lines is not None:
        ends, tints = (np.ascontiguousarray(a, dtype=np.float32) for a in lines)
        blobs += [("LINE_POSITION", ends, _ARRAY_BUFFER), ("LINE_COLOR", tints, _ARRAY_BUFFER)]
    buffer_views, accessors, chunks, offset = _packed(blobs)
    accessor_of = {accessor["name"]: i for i, accessor in enumerate(accessors)}
    attributes = {name: i for i, (name, _, _) in enumerate(blobs[:3])}
    if colours is not None:
        attributes["COLOR_0"] = accessor_of["COLOR_0"]
    document = {
        "asset": {
            "version": "2.0",
            "generator": "meshflat",
            "extras": {"meshflat": extras | {"face_ids_accessor": 4}},
        },
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "name": "region"}],
        "meshes": [
            {
                "name": "region",
                "primitives": [
                    {"attributes": attributes, "indices": 3, "material": 0, "mode": _TRIANGLES}
                ],
            }
        ],
        "materials": [
            {
                "name": "checker",
                "pbrMetallicRoughness": {
                    "baseColorTexture": {"index": 0},
                    "metallicFactor": 0.0,
                    "roughnessFactor": 1.0,
                },
                "doubleSided": True,
            }
        ],
        "textures": [{"source": 0, "sampler": 0}],
        "samplers": [{"magFilter": 9728, "minFilter": 9728, "wrapS": 33071, "wrapT": 33071}],
        "images": [{"bufferView": 5, "mimeType": "image/png", "name": "checker"}],
        "accessors": accessors,
        "bufferViews": buffer_views,
        "buffers": [{"byteLength": offset}],
    }
    for name, mode, attributes in _OVERLAYS:
        if attributes["POSITION"] in accessor_of:
            found = {key: accessor_of[blob] for key, blob in attributes.items()}
            shown = lines_name if mode == _LINES else name
            _add_node(document, shown, {"attributes": found, "mode": mode})
    json_chunk = orjson.dumps(document, option=orjson.OPT_SERIALIZE_NUMPY)
    json_chunk += b" " * (-len(json_chunk) % 4)
    binary = b"".join(chunks)
    total = 12 + 8 + len(json_chunk) + 8 + len(binary)
    return b"".join(
        [
            struct.pack("<III", _GLB_MAGIC, _GLB_VERSION, total),
            struct.pack("<II", len(json_chunk), _JSON_CHUNK),
            json_chunk,
            struct.pack("<II", len(binary), _BIN_CHUNK),
            binary,
        ]
    )


#: The meshes drawn over the region, when their blobs are there: name, mode, attributes.
_OVERLAYS = (
    ("sites", _POINTS, {"POSITION": "SITE_POSITION", "NORMAL": "NORMAL"}),
    ("growth", _LINES, {"POSITION": "LINE_POSITION", "COLOR_0": "LINE_COLOR"}),
)


def _packed(blobs) -> tuple[list, list, list, int]:
    """The buffer views, accessors and 4-byte aligned chunks of ``blobs`` ((name, array,
    target) each; the ``checker`` image gets a view and no accessor), and the bytes in all."""
    buffer_views, accessors, chunks, offset = [], [], [], 0
    for name, array, target in blobs:
        data = array.tobytes()
        view = {"buffer": 0, "byteOffset": offset, "byteLength": len(data)}
        if target is not None:
            view["target"] = target
        buffer_views.append(view)
        chunks.append(data + b"\0" * (-len(data) % 4))  # views start 4-byte aligned
        offset += len(chunks[-1])
        if name == "checker":  # an image, not an accessor
            continue
        columns = array.shape[1] if array.ndim == 2 else 1
        accessor = {
            "bufferView": len(buffer_views) - 1,
            "componentType": _FLOAT if array.dtype == np.float32 else _UNSIGNED_INT,
            "count": len(array),
            "type": {1: "SCALAR", 2: "VEC2", 3: "VEC3"}[columns],
            "name": name,
        }
        if name in ("POSITION", "TEXCOORD_0", "_VERTEX_ID", "SITE_POSITION", "LINE_POSITION"):
            low, high = array.min(axis=0), array.max(axis=0)
            accessor["min"] = np.atleast_1d(low).tolist()
            accessor["max"] = np.atleast_1d(high).tolist()
        accessors.append(accessor)
    return buffer_views, accessors, chunks, offset


def _add_node(document: dict, name: str, primitive: dict) -> None:
    """A node of its own mesh of one ``primitive``, in the scene."""
    document["scenes"][0]["nodes"].append(len(document["nodes"]))
    document["nodes"].append({"mesh": len(document["meshes"]), "name": name})
    document["meshes"].append({"name": name, "primitives": [primitive]})


@cache
def _checker_png() -> bytes:
    """A 256 x 256 checker of 16 x 16 squares with a coloured cross at the middle, as PNG:
    what the region shows through its UVs (squares stay squares where the map is conformal;
    the colours tell the two axes apart)."""
    index = np.arange(256) // 16
    squares = (index[:, None] + index[None, :]) % 2
    image = np.where(squares[..., None] == 1, 200, 245).astype(np.uint8).repeat(3, axis=2)
    image[:, 126:130] = (213, 94, 0)  # u = 0.5: vertical
    image[126:130, :] = (0, 114, 178)  # v = 0.5: horizontal
    out = io.BytesIO()
    Image.fromarray(image, "RGB").save(out, format="PNG")
    return out.getvalue()
