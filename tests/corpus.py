"""The malformed-input corpus: files and parameter sets that scanners, exporters and callers
get wrong, each with the status the service must answer and words its problem ``detail`` must
contain (the cause, named). The big inputs are generated here, not committed.

``python -m tests.corpus DIR`` writes every case's files to ``DIR`` (for a look, or for other
tools); the tests build them in memory.
"""

from __future__ import annotations

import base64
import json
import struct
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from fixtures.hostile import HOSTILE
from service.samples import SAMPLES

#: The upload limit of the app the corpus is sent to (small, so the big cases stay small).
UPLOAD_LIMIT = 2_000_000
SCALP = {"region": {"cone": {"axis": [0, 0, 1], "half_angle_deg": 70}}}


@dataclass(frozen=True)
class Case:
    """One request: ``mesh`` (file name, bytes) in a multipart body with ``params``, or a raw
    ``body`` with ``content_type``; the expected status and words of the detail."""

    name: str
    status: int
    detail: tuple[str, ...]
    mesh: tuple[str, bytes] | None = None
    params: dict | str | None = None
    body: bytes | None = None
    content_type: str = "application/json"
    route: str = "/v1/flatten"
    headers: dict = field(default_factory=dict)


# -- building blocks -----------------------------------------------------------------------


def glb(document: dict, binary: bytes = b"", *, total=None, json_length=None, bin_length=None):
    """A GLB container of ``document`` and ``binary`` (no BIN chunk when it is empty), each
    chunk padded to 4 bytes as the spec lays it out; the lengths may be made to lie."""
    text = json.dumps(document, allow_nan=False).encode()
    text += b" " * (-len(text) % 4)
    binary += b"\0" * (-len(binary) % 4)
    chunks = struct.pack("<I4s", len(text) if json_length is None else json_length, b"JSON")
    chunks += text
    if binary:
        chunks += struct.pack("<I4s", len(binary) if bin_length is None else bin_length, b"BIN\0")
        chunks += binary
    length = 12 + len(chunks) if total is None else total
    return struct.pack("<4sII", b"glTF", 2, length) + chunks


def triangle_gltf(
    positions=((0, 0, 0), (1, 0, 0), (0, 1, 0)),
    indices=(0, 1, 2),
    *,
    uri: str | None = "data",
    mode: int = 4,
    count: int | None = None,
) -> dict:
    """A glTF document with one primitive; ``uri="data"`` embeds the buffer as a data URI,
    ``None`` leaves it for a GLB's BIN chunk; returns the document (and the binary in
    ``document["_binary"]`` when it is for a GLB)."""
    binary = struct.pack(f"<{3 * len(positions)}f", *[c for p in positions for c in p])
    index_offset = len(binary)
    binary += struct.pack(f"<{len(indices)}I", *indices)
    buffer = {"byteLength": len(binary)}
    if uri == "data":
        buffer["uri"] = "data:application/octet-stream;base64," + base64.b64encode(binary).decode()
    elif uri is not None:
        buffer["uri"] = uri
    document = {
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "mode": mode}]}],
        "buffers": [buffer],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": index_offset},
            {"buffer": 0, "byteOffset": index_offset, "byteLength": len(binary) - index_offset},
        ],
        "accessors": [
            {
                "bufferView": 0,
                "componentType": 5126,
                "count": len(positions) if count is None else count,
                "type": "VEC3",
                "min": [0, 0, 0],
                "max": [1, 1, 0],
            },
            {"bufferView": 1, "componentType": 5125, "count": len(indices), "type": "SCALAR"},
        ],
    }
    if uri is None:
        document["_binary"] = binary
    return document


def as_glb(document: dict, **lies) -> bytes:
    document = dict(document)
    binary = document.pop("_binary")
    return glb(document, binary, **lies)


def gltf_bytes(document: dict) -> bytes:
    return json.dumps(document).encode()


def big_data_uri_gltf() -> bytes:
    """A glTF whose data URI decodes to more than the upload limit allows."""
    document = triangle_gltf()
    payload = base64.b64encode(b"\0" * (UPLOAD_LIMIT + 1)).decode()
    document["buffers"][0]["uri"] = "data:application/octet-stream;base64," + payload
    document["buffers"][0]["byteLength"] = UPLOAD_LIMIT + 1
    return gltf_bytes(document)


def oversized_points() -> bytes:
    """A /v1/points body just over the upload limit."""
    row = b"[1.0, 2.0, 3.0],"
    body = b'{"points": [' + row * (UPLOAD_LIMIT // len(row) + 1)
    return body[:-1] + b"]}"


OBJ_SQUARE = b"v 0 0 1\nv 1 0 1\nv 0 1 1\nv 1 1 1\nf 1 2 3\nf 2 4 3\n"


def binary_stl(triangles: list[tuple], count: int | None = None) -> bytes:
    body = b"".join(
        struct.pack("<12fH", 0, 0, 0, *[c for corner in t for c in corner], 0) for t in triangles
    )
    return b"\0" * 80 + struct.pack("<I", len(triangles) if count is None else count) + body


def junk(size: int, seed: int) -> bytes:
    """Deterministic bytes that are no format (a linear congruential sequence)."""
    out, state = bytearray(), seed
    for _ in range(size):
        state = (1103515245 * state + 12345) % 2**31
        out.append(state >> 16 & 0xFF)
    return bytes(out)


# -- the corpus ----------------------------------------------------------------------------


def cases() -> list[Case]:
    head_glb = SAMPLES["lee-perry-smith.glb"].path.read_bytes()
    head_ply = SAMPLES["fsaverage-head.ply"].path.read_bytes()
    tri_glb = as_glb(triangle_gltf(uri=None))
    json_length = struct.unpack_from("<I", tri_glb, 12)[0]
    m = "mesh"
    c = [
        # empty and junk files
        Case("empty OBJ", 422, (m, "empty"), mesh=("a.obj", b"")),
        Case("empty GLB", 422, (m, "empty"), mesh=("a.glb", b"")),
        Case("empty PLY", 422, (m, "empty"), mesh=("a.ply", b"")),
        Case("empty STL", 422, (m, "empty"), mesh=("a.stl", b"")),
        Case("empty glTF", 422, (m, "empty"), mesh=("a.gltf", b"")),
        Case("junk as OBJ", 422, (m,), mesh=("a.obj", junk(4096, 1))),
        Case("junk as GLB", 422, (m, "GLB"), mesh=("a.glb", junk(4096, 2))),
        Case("junk as PLY", 422, (m, "PLY"), mesh=("a.ply", junk(4096, 3))),
        Case("junk as glTF", 422, (m, "JSON"), mesh=("a.gltf", junk(4096, 4))),
        Case("unknown extension", 422, (m, "format"), mesh=("a.fbx", OBJ_SQUARE)),
        # GLB containers that lie
        Case("truncated GLB", 422, (m,), mesh=("a.glb", head_glb[: len(head_glb) // 2])),
        Case("GLB header only", 422, (m,), mesh=("a.glb", tri_glb[:12])),
        Case("GLB wrong magic", 422, (m, "GLB"), mesh=("a.glb", b"glTX" + tri_glb[4:])),
        Case(
            "GLB version 1",
            422,
            (m, "version"),
            mesh=("a.glb", tri_glb[:4] + struct.pack("<I", 1) + tri_glb[8:]),
        ),
        Case(
            "GLB total length beyond the file",
            422,
            (m, "declares 704 bytes"),
            mesh=("a.glb", as_glb(triangle_gltf(uri=None), total=len(tri_glb) + 100)),
        ),
        Case(
            "GLB JSON chunk length beyond the file",
            422,
            (m, "chunk"),
            mesh=("a.glb", as_glb(triangle_gltf(uri=None), json_length=10_000)),
        ),
        Case(
            "GLB BIN chunk length beyond the file",
            422,
            (m, "chunk"),
            mesh=("a.glb", as_glb(triangle_gltf(uri=None), bin_length=10_000)),
        ),
        Case(
            "GLB JSON chunk cut short",
            422,
            (m,),
            mesh=("a.glb", as_glb(triangle_gltf(uri=None), json_length=json_length - 8)),
        ),
        # glTF documents that lie or reach out
        Case(
            "accessor count larger than its buffer",
            422,
            (m, "accessor"),
            mesh=("a.gltf", gltf_bytes(triangle_gltf(count=1000))),
        ),
        Case(
            "indices past the vertices",
            422,
            (m, "3"),
            mesh=("a.gltf", gltf_bytes(triangle_gltf(indices=(0, 1, 3)))),
        ),
        Case(
            "external buffer URI",
            422,
            (m, "mesh.bin"),
            mesh=("a.gltf", gltf_bytes(triangle_gltf(uri="mesh.bin"))),
        ),
        Case(
            "file: URI",
            422,
            (m, "file:///etc/passwd"),
            mesh=("a.gltf", gltf_bytes(triangle_gltf(uri="file:///etc/passwd"))),
        ),
        Case(
            "https URI",
            422,
            (m, "https://example.com/b.bin"),
            mesh=("a.gltf", gltf_bytes(triangle_gltf(uri="https://example.com/b.bin"))),
        ),
        Case(
            "data: URI beyond the limit",
            413,
            ("2,000,000", "MESHFLAT_MAX_UPLOAD_BYTES"),
            mesh=("a.gltf", b""),
        ),
        Case(
            "data: URI shorter than its declared length",
            422,
            (m, "buffers[0] declares 3,000,000 bytes but holds 48"),
            mesh=(
                "a.gltf",
                gltf_bytes(
                    triangle_gltf()
                    | {"buffers": [triangle_gltf()["buffers"][0] | {"byteLength": 3_000_000}]}
                ),
            ),
        ),
        Case(
            "data: URI that is not base64",
            422,
            (m, "base64"),
            mesh=(
                "a.gltf",
                gltf_bytes(
                    triangle_gltf() | {"buffers": [{"byteLength": 48, "uri": "data:;base64,@@@@"}]}
                ),
            ),
        ),
        Case(
            "lines instead of triangles",
            422,
            (m, "mode"),
            mesh=("a.gltf", gltf_bytes(triangle_gltf(mode=1, indices=(0, 1, 1, 2)))),
        ),
        Case(
            "points instead of triangles",
            422,
            (m, "mode"),
            mesh=("a.gltf", gltf_bytes(triangle_gltf(mode=0))),
        ),
        Case(
            "NaN position in a glTF",
            422,
            (m, "vertex"),
            mesh=(
                "a.gltf",
                gltf_bytes(triangle_gltf(((0, 0, 0), (float("nan"), 0, 0), (0, 1, 0)))),
            ),
        ),
        # OBJ, PLY and STL faults
        Case(
            "OBJ face past the vertex list",
            422,
            (m, "9"),
            mesh=("a.obj", OBJ_SQUARE + b"f 1 2 9\n"),
        ),
        Case("OBJ face index 0", 422, (m, "0"), mesh=("a.obj", OBJ_SQUARE + b"f 0 1 2\n")),
        Case(
            "OBJ negative index too far back",
            422,
            (m, "-9"),
            mesh=("a.obj", OBJ_SQUARE + b"f -1 -2 -9\n"),
        ),
        Case("OBJ NaN vertex", 422, (m, "vertex"), mesh=("a.obj", b"v nan 0 1\n" + OBJ_SQUARE)),
        Case("OBJ Inf vertex", 422, (m, "vertex"), mesh=("a.obj", b"v 0 inf 1\n" + OBJ_SQUARE)),
        Case("OBJ vertex with two numbers", 422, (m,), mesh=("a.obj", b"v 0 1\n" + OBJ_SQUARE)),
        Case(
            "OBJ with lines only", 422, (m, "no face"), mesh=("a.obj", b"v 0 0 0\nv 1 0 0\nl 1 2\n")
        ),
        Case(
            "PLY with fewer vertices than its header says",
            422,
            (m,),
            mesh=("a.ply", head_ply[: len(head_ply) // 3]),
        ),
        Case(
            "STL that ends before its triangles",
            422,
            (m,),
            mesh=("a.stl", binary_stl([((0, 0, 0), (1, 0, 0), (0, 1, 0))], count=50)),
        ),
        Case(
            "STL NaN corner",
            422,
            (m, "vertex"),
            mesh=("a.stl", binary_stl([((0, 0, 0), (float("nan"), 0, 0), (0, 1, 0))])),
        ),
        # parameters
        Case(
            "a region of zero area",
            422,
            (m, "zero area"),
            mesh=("a.obj", b"v 0 0 1\nv 1 0 1\nv 2 0 1\nv 0 1 1\nf 1 2 3\nf 1 2 4\n"),
            params={"center": [1, 5, 1], "region": {"faces": [0]}},
        ),
        Case(
            "the centre on the surface",
            422,
            ("vertex 0", "at the centre", "choose a centre"),
            # Bent: flat, the square would be seen edge-on from its own vertex (below).
            mesh=("a.obj", OBJ_SQUARE.replace(b"v 1 1 1", b"v 1 1 2")),
            params={"center": [0, 0, 1]},
        ),
        Case(
            "the centre on a flat region's vertex",
            422,
            ("params.center", "in the plane of every face", "on vertex 0", "off that plane"),
            mesh=("a.obj", OBJ_SQUARE),
            params={"center": [0, 0, 1]},
        ),
        Case(
            "a flat region from its default centre, in its plane",
            422,
            ("params.center", "[0.5, 0.5, 1]", "in the plane of every face", "edge-on"),
            mesh=("a.obj", OBJ_SQUARE),
        ),
        Case(
            "region ids with a duplicate",
            422,
            ("params.region.faces", "1"),
            mesh=("a.obj", OBJ_SQUARE),
            params={"region": {"faces": [0, 1, 1]}},
        ),
        Case(
            "region ids with a negative",
            422,
            ("params.region.faces",),
            mesh=("a.obj", OBJ_SQUARE),
            params={"region": {"faces": [0, -1]}},
        ),
        Case(
            "region ids past the faces",
            422,
            ("params.region.faces", "2"),
            mesh=("a.obj", OBJ_SQUARE),
            params={"region": {"faces": [0, 2]}},
        ),
        Case(
            "sigma below its range",
            422,
            ("params.sigma",),
            mesh=("a.obj", OBJ_SQUARE),
            params={"sigma": -0.5},
        ),
        Case(
            "sigma and pole angle both",
            422,
            ("sigma", "pole_angle_deg"),
            mesh=("a.obj", OBJ_SQUARE),
            params={"sigma": 0.3, "pole_angle_deg": 30},
        ),
        Case(
            "a cone axis beyond the coordinate bound",
            422,
            ("params.region.cone.axis.0", "1000000000000000"),
            mesh=("a.obj", OBJ_SQUARE),
            params={"region": {"cone": {"axis": [-4.4e253, 0.2, 1.4e33], "half_angle_deg": 90}}},
        ),
        Case("params not JSON", 422, ("params",), mesh=("a.obj", OBJ_SQUARE), params="{sigma"),
        Case("params a JSON list", 422, ("params",), mesh=("a.obj", OBJ_SQUARE), params="[1]"),
        Case(
            "an unknown parameter",
            422,
            ("params.sigmaa",),
            mesh=("a.obj", OBJ_SQUARE),
            params={"sigmaa": 0.3},
        ),
        Case(
            "params repeating a key",
            422,
            ("params.sigma", "more than once"),
            mesh=("a.obj", OBJ_SQUARE),
            params='{"sigma": 0.3, "sigma": 0.5}',
        ),
        # bodies and content types
        Case("oversized JSON", 413, ("2,000,000",), route="/v1/points", body=b""),
        Case(
            "points as text/plain",
            415,
            ("application/json",),
            route="/v1/points",
            body=b'{"points": [[1, 0, 0]]}',
            content_type="text/plain",
        ),
        Case(
            "a mesh sent as JSON",
            415,
            ("multipart/form-data",),
            body=b'{"mesh": "v 0 0 0"}',
        ),
        Case(
            "multipart without the mesh part",
            422,
            ("mesh",),
            body=b'--b\r\nContent-Disposition: form-data; name="params"\r\n\r\n{}\r\n--b--\r\n',
            content_type="multipart/form-data; boundary=b",
        ),
        Case(
            "multipart with two mesh parts",
            422,
            ("mesh", "more than one 'mesh' part"),
            body=2
            * (
                b'--b\r\nContent-Disposition: form-data; name="mesh"; filename="a.obj"\r\n'
                b"\r\n" + OBJ_SQUARE + b"\r\n"
            )
            + b"--b--\r\n",
            content_type="multipart/form-data; boundary=b",
        ),
        Case(
            "points repeating a key",
            422,
            ("points", "more than once"),
            route="/v1/points",
            body=b'{"points": [[1, 0, 0]], "points": [[0, 1, 0]]}',
        ),
        Case(
            "multipart whose boundary never comes",
            400,
            ("multipart",),
            body=b"--x\r\nno boundary here",
            content_type="multipart/form-data; boundary=b",
        ),
        Case(
            "multipart naming its boundary twice",
            400,
            ("Content-Type", "boundary more than once"),
            body=b'--b\r\nContent-Disposition: form-data; name="params"\r\n\r\n{}\r\n--b--\r\n',
            content_type="multipart/form-data; boundary=evil; boundary=b",
        ),
        Case(
            "points with a NaN",
            422,
            ("points",),
            route="/v1/points",
            body=b'{"points": [[1, 0, NaN]]}',
        ),
        Case(
            "an answer nobody accepts",
            406,
            ("Accept",),
            mesh=("a.ply", head_ply),
            params=SCALP,
            headers={"Accept": "text/html"},
        ),
    ]
    generated: dict[str, Callable[[], bytes]] = {
        "data: URI beyond the limit": big_data_uri_gltf,
        "oversized JSON": oversized_points,
    }
    return [_with_generated(case, generated) for case in c] + hostile_cases()


#: What the service says of each of the readers' worst offenders (fixtures/hostile.py):
#: no vertices at all, or triangles that have no area (or none seen from the centre).
_HOSTILE_DETAILS = {
    "OBJ of newlines": ("mesh:", "no vertex"),
    "OBJ of comments": ("mesh:", "no vertex"),
    "OBJ of distinct group names": ("params.center", "plane"),
    "binary PLY, mixed polygon sizes": ("params.center", "plane"),
    "ASCII STL, `facet  normal`": ("params.center", "plane"),
    "binary STL": ("params.center", "plane"),
}


def hostile_cases(size: int = 200_000) -> list[Case]:
    """The uploads that cost the readers the most memory per byte (``make attack`` sends them
    at tens of MiB and measures it), small: each must still be read and answered right."""
    return [
        Case(
            f"hostile: {name}",
            422,
            _HOSTILE_DETAILS.get(name, ("mesh:", "zero area")),
            mesh=(file_name, build(size)),
            params={},
        )
        for name, (file_name, build) in HOSTILE.items()
    ]


def _with_generated(case: Case, generated: dict) -> Case:
    if case.name not in generated:
        return case
    data = generated[case.name]()
    if case.mesh is not None:
        return Case(**{**case.__dict__, "mesh": (case.mesh[0], data)})
    return Case(**{**case.__dict__, "body": data})


def write(directory: Path) -> None:
    directory.mkdir(parents=True, exist_ok=True)
    for number, case in enumerate(cases()):
        stem = f"{number:02d}-{case.name.replace(' ', '-').replace(':', '')}"
        if case.mesh is not None:
            (directory / f"{stem}-{case.mesh[0]}").write_bytes(case.mesh[1])
        if case.body is not None:
            (directory / f"{stem}.body").write_bytes(case.body)


if __name__ == "__main__":
    write(Path(sys.argv[1] if len(sys.argv) > 1 else "corpus"))
