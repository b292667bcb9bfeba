"""The planning routes' hostile requests for ``make attack`` (benchmarks/attack.py): the
cases of a planning-route attack, each with the statuses it must answer.

Each is a small upload that once cost a worker gigabytes or minutes, or answered a wrong
200: a curve zig-zagging across the map, a zone of 400,000 points, a palette PNG mask that
decodes to 8192² pixels, 256 nested zones, a follow-up scaled by 1e40 or shrunk onto a
point, a zone whose corners lie 1e15 off the map, a truncated density map, and a form whose
Content-Type names a decoy boundary. Beside them, what the bounds still let through, the
largest of each: a curve crossing just under ``MESHFLAT_MAX_CURVE_CROSSINGS`` edges, a zone
just under ``MESHFLAT_MAX_DRAWN_POINTS``, a mask of ``MESHFLAT_MAX_IMAGE_PIXELS``, and two
1.13M-face heads registered. The rows measure the worker's growth as the others do,
against the charge the server's access line gives for the request (its ``charged_bytes``:
eight bytes per byte of the body, then what the job declared before allocating it).
"""

from __future__ import annotations

import json
import struct
import zlib
from collections.abc import Callable
from dataclasses import dataclass

import httpx

from fixtures.meshes import subdivided_ply
from service.samples import SAMPLES

SCALP = {"region": {"cone": {"axis": [0, 0, 1], "half_angle_deg": 70}}, "units": "mm"}
HEAD = "fsaverage-head.ply"


@dataclass(frozen=True)
class PlanningCase:
    """A request, the statuses it may answer, and what its answer must hold."""

    name: str
    expected: frozenset[int]
    send: Callable[[httpx.Client, dict], httpx.Response]
    holds: Callable[[httpx.Response], bool] = lambda response: True


def _head() -> bytes:
    return SAMPLES[HEAD].path.read_bytes()


def _post(route: str, params: dict, **parts):
    def send(client: httpx.Client, headers: dict) -> httpx.Response:
        files = {"mesh": (HEAD, _head()), **parts}
        return client.post(route, files=files, data={"params": json.dumps(params)},
                           headers=headers)  # fmt: skip

    return send


def _zig_zag(points: int) -> dict:
    """A curve across the map and back, ``points`` corners."""
    xs = [(-3.0 if k % 2 else 3.0) for k in range(points)]
    ys = [0.5 + 2.0 * k / points for k in range(points)]
    return {**SCALP, "curves": [{"name": "zig-zag", "x": xs, "y": ys}]}


def _many_points(points: int) -> dict:
    """One zone of ``points`` corners round a small circle on the map."""
    import math

    angles = [2 * math.pi * k / points for k in range(points)]
    zone = {"name": "ring", "outer": {"x": [0.3 * math.cos(a) for a in angles],
                                      "y": [1.5 + 0.3 * math.sin(a) for a in angles]}}  # fmt: skip
    return {**SCALP, "zones": [zone], "density_per_cm2": 1}


def _nested(count: int) -> dict:
    """``count`` nested 16-gons."""
    import math

    angles = [2 * math.pi * k / 16 for k in range(16)]
    zones = [
        {"name": f"z{i}", "outer": {"x": [(0.1 + 0.01 * i) * math.cos(a) for a in angles],
                                    "y": [1.5 + (0.1 + 0.01 * i) * math.sin(a) for a in angles]}}
        for i in range(count)
    ]  # fmt: skip
    return {**SCALP, "zones": zones}


def _far_corners() -> dict:
    """A rectangle with two corners 1e15 off the map."""
    zone = {"name": "far", "outer": {"x": [-1e15, 1e15, 1e15, -1e15], "y": [1.0, 1.0, 1.6, 1.6]}}
    return {**SCALP, "zones": [zone]}


def _png(width: int, height: int, colour: int, rows: bytes, extra: bytes = b"") -> bytes:
    def chunk(kind: bytes, data: bytes) -> bytes:
        body = kind + data
        return struct.pack(">I", len(data)) + body + struct.pack(">I", zlib.crc32(body))

    header = struct.pack(">IIBBBBB", width, height, 8, colour, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + extra
            + chunk(b"IDAT", zlib.compress(rows, 9)) + chunk(b"IEND", b""))  # fmt: skip


def _palette_bomb(side: int = 8192, opaque: bool = False) -> bytes:
    """A palette PNG with transparency that decodes to ``side``² pixels (8192²: in some
    70 KB), each of them black and transparent, or white and opaque."""
    colour, alpha = (b"\xff\xff\xff", b"\xff") if opaque else (b"\0\0\0", b"\0")
    palette = struct.pack(">I", 3) + b"PLTE" + colour
    palette += struct.pack(">I", zlib.crc32(b"PLTE" + colour))
    alpha = struct.pack(">I", 1) + b"tRNS" + alpha + struct.pack(">I", zlib.crc32(b"tRNS" + alpha))
    return _png(side, side, 3, bytes((1 + side) * side), palette + alpha)


def _truncated_map() -> bytes:
    """An 8-bit grey density map of the default framing (1200 x 800) whose image data holds
    10 of its 800 rows."""
    return _png(1200, 800, 0, bytes(1201 * 10))


def _textured_head() -> bytes:
    """The head as an OBJ with texture coordinates (from its x and y): a mask applies."""
    from service.meshio import read_mesh
    from service.settings import Settings

    mesh = read_mesh(_head(), "ply", Settings().limits)
    v = mesh.vertices
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in v.tolist()]
    lines += [f"vt {x / 260 + 0.5!r} {y / 260 + 0.5!r}" for x, y in v[:, :2].tolist()]
    lines += [f"f {a}/{a} {b}/{b} {c}/{c}" for a, b, c in (mesh.faces + 1).tolist()]
    return ("\n".join(lines) + "\n").encode()


def _decoy_boundary(client: httpx.Client, headers: dict) -> httpx.Response:
    """A form whose Content-Type names ``xboundary=EVIL`` before ``boundary=REAL``, with a
    part hidden behind EVIL that asks for a thousand times the sites."""
    visible = json.dumps({**SCALP, "density_per_cm2": 1})
    hidden = json.dumps({**SCALP, "density_per_cm2": 1000})
    head = _head()
    body = (
        b"--REAL\r\nContent-Disposition: form-data; name=\"mesh\"; filename=\"h.ply\"\r\n\r\n"
        + head + b"\r\n--REAL\r\nContent-Disposition: form-data; name=\"params\"\r\n\r\n"
        + visible.encode() + b"\r\n--EVIL\r\nContent-Disposition: form-data; name=\"params\""
        b"\r\n\r\n" + hidden.encode() + b"\r\n--EVIL--\r\n--REAL--\r\n"
    )  # fmt: skip
    content_type = "multipart/form-data; xboundary=EVIL; boundary=REAL"
    return client.post("/v1/sites", content=body,
                       headers=headers | {"Content-Type": content_type})  # fmt: skip


def _visible_sites_only(response: httpx.Response) -> bool:
    """The visible params ask for about 580 sites, the hidden ones a thousand times that (as
    any standard parser reads the form, the params field ends in the decoy's text: a 422)."""
    return response.status_code != 200 or response.json()["count"] < 5_000


def _register(scale: float, cone_deg: float | None = None):
    def send(client: httpx.Client, headers: dict) -> httpx.Response:
        from service.meshio import read_mesh
        from service.settings import Settings

        mesh = read_mesh(_head(), "ply", Settings().limits)
        lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in (mesh.vertices * scale).tolist()]
        lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in mesh.faces.tolist()]
        follow = ("\n".join(lines) + "\n").encode()
        params = {"mode": "similarity", "units": "mm"}
        if cone_deg is not None:
            params["region"] = {"cone": {"axis": [0, 0, 1], "half_angle_deg": cone_deg}}
        files = {"baseline": (HEAD, _head()), "follow_up": ("f.obj", follow)}
        return client.post("/v1/register", files=files, data={"params": json.dumps(params)},
                           headers=headers)  # fmt: skip

    return send


def _large_registration(client: httpx.Client, headers: dict) -> httpx.Response:
    """The 1.13M-face head (Lee Perry-Smith split three times) registered to itself."""
    head = subdivided_ply("lee-perry-smith.glb", 3)
    files = {"baseline": ("b.ply", head), "follow_up": ("f.ply", head)}
    return client.post("/v1/register", files=files, data={"params": "{}"}, headers=headers)


def _mask(side: int):
    def send(client: httpx.Client, headers: dict) -> httpx.Response:
        files = {
            "mesh": ("h.obj", _textured_head()),
            "mask": ("m.png", _palette_bomb(side, side <= 4096)),
        }
        params = {"region": {"texture_mask": {}}}
        return client.post("/v1/flatten", files=files, data={"params": json.dumps(params)},
                           headers=headers)  # fmt: skip

    return send


def planning_cases() -> list[PlanningCase]:
    """The cases, each with the statuses it must answer (issue 32's list)."""
    return [
        PlanningCase("curve zig-zagging 30,000 times (/v1/measure)", frozenset({413}),
                     _post("/v1/measure", _zig_zag(30_000))),
        PlanningCase("zone of 400,000 points (/v1/sites)", frozenset({413}),
                     _post("/v1/sites", _many_points(400_000))),
        PlanningCase("palette PNG mask of 8192² pixels (/v1/flatten)", frozenset({422}),
                     _mask(8192)),
        PlanningCase("curve crossing some 246,000 edges, under the bound (/v1/measure)",
                     frozenset({200}), _post("/v1/measure", _zig_zag(2_900))),
        PlanningCase("zone of 99,000 points, under the bound (/v1/sites)", frozenset({200}),
                     _post("/v1/sites", _many_points(99_000))),
        PlanningCase("opaque PNG mask of 4096² pixels, the bound (/v1/flatten)",
                     frozenset({200}), _mask(4096)),
        PlanningCase("two 1.13M-face heads registered (/v1/register)", frozenset({200}),
                     _large_registration),
        PlanningCase("256 nested 16-gons (/v1/measure)", frozenset({200}),
                     _post("/v1/measure", _nested(256))),
        PlanningCase("zone corners 1e15 off the map (/v1/measure)", frozenset({200}),
                     _post("/v1/measure", _far_corners())),
        PlanningCase("truncated density map (/v1/sites)", frozenset({422}),
                     _post("/v1/sites", {**SCALP, "density_range": [0, 10]},
                           density_map=("d.png", _truncated_map()))),
        PlanningCase("follow-up scaled by 1e40 (/v1/register)", frozenset({422}),
                     _register(1e40)),
        PlanningCase("follow-up scaled by 1e-90 (/v1/register)", frozenset({422}),
                     _register(1e-90)),
        PlanningCase("decoy boundary before the real one (/v1/sites)", frozenset({200, 400, 422}),
                     _decoy_boundary, _visible_sites_only),
    ]  # fmt: skip
