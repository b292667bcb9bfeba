"""Examples for the OpenAPI document, made by running the service's own code on the request
schemas' own examples (for meshes: the top of a unit icosahedron), so they show real answers.

Floats are rounded to six decimals, so the committed document does not depend on the last
bit of a platform's sine.
"""

from __future__ import annotations

import json

import orjson
import trimesh

from .capabilities import JSON_CAPABILITIES, MESH_CAPABILITIES
from .capabilities.context import Context
from .capabilities.inputs import MeshPart, Upload, parse_params
from .capabilities.region.params import MESH_PARAMS_EXAMPLE
from .encoding import JSON
from .errors import JSON_BODY
from .forms import parse_json
from .meshio import read_mesh
from .outputs import Output
from .problems import PROBLEM_JSON, Problem, core_errors_as_problems, problem_response
from .samples import sample_infos
from .selfcheck import Health
from .settings import Settings
from .timings import Timings

BOUNDARY = "example-boundary"
MULTIPART = f"multipart/form-data; boundary={BOUNDARY}"


def icosahedron_obj() -> bytes:
    """A unit icosahedron as OBJ text (12 vertices, 20 triangles, wound outward)."""
    mesh = trimesh.creation.icosahedron()
    lines = [f"v {x:.9f} {y:.9f} {z:.9f}" for x, y, z in mesh.vertices.tolist()]
    lines += [f"f {a} {b} {c}" for a, b, c in (mesh.faces + 1).tolist()]
    return ("\n".join(lines) + "\n").encode()


def multipart_body(params: dict, filename: str, data: bytes) -> bytes:
    """A multipart/form-data body (boundary :data:`BOUNDARY`) with ``params`` and ``mesh``."""
    return b"".join(
        [
            f'--{BOUNDARY}\r\nContent-Disposition: form-data; name="params"\r\n\r\n'.encode(),
            json.dumps(params).encode(),
            f'\r\n--{BOUNDARY}\r\nContent-Disposition: form-data; name="mesh"; '
            f'filename="{filename}"\r\n\r\n'.encode(),
            data,
            f"\r\n--{BOUNDARY}--\r\n".encode(),
        ]
    )


def _rounded(value):
    if isinstance(value, float):
        return round(value, 6) + 0.0  # + 0.0: no "-0.0"
    if isinstance(value, list):
        return [_rounded(item) for item in value]
    if isinstance(value, dict):
        return {key: _rounded(item) for key, item in value.items()}
    return value


def _json(body: bytes) -> dict:
    return _rounded(orjson.loads(body))


def _problem(call, places) -> dict:
    """The problem answer ``call`` fails with (as the routes would answer it)."""
    try:
        with core_errors_as_problems(places):
            call()
    except Problem as problem:
        return _json(problem_response(problem).body)
    raise AssertionError("the example call did not fail")


def request_example(model) -> dict:
    """The first example of a request model's schema."""
    return model.model_config["json_schema_extra"]["examples"][0]


def mesh_answer(capability, params: dict, mesh: bytes, settings: Settings) -> bytes:
    """A mesh route's JSON answer to ``params`` on the OBJ ``mesh``."""
    parsed = parse_params(capability.params, json.dumps(params).encode())
    # A route of two meshes (/v1/register) gets the same one twice.
    upload = Upload("icosahedron.obj", mesh)
    files = {part.name: upload for part in capability.parts if isinstance(part, MeshPart)}
    ctx = Context(settings)
    given = capability.input_of(parsed, files, ctx)
    return capability.answer(given, ctx, Output.JSON, Timings())


def json_answer(capability, body: dict, settings: Settings) -> bytes:
    """A JSON route's answer to ``body``."""
    request = parse_json(capability.request, json.dumps(body).encode(), JSON)
    return capability.answer(request, Context(settings), Timings())


def examples() -> dict[tuple[str, str], dict | list]:
    """(path, status) -> example answer body: for every capability, its answer to its
    request example, and problems for a bad region, a mesh beyond a limit and bad points."""
    settings = Settings()
    mesh = icosahedron_obj()
    found: dict[tuple[str, str], dict | list] = {
        ("/healthz", "200"): Health().model_dump(),
        ("/readyz", "200"): Health().model_dump(),
        ("/v1/samples", "200"): [info.model_dump() for info in sample_infos()],
    }
    for capability in JSON_CAPABILITIES:
        example = request_example(capability.request)
        found[capability.path, "200"] = _json(json_answer(capability, example, settings))
    for capability in MESH_CAPABILITIES:
        example = request_example(capability.params)
        found[capability.path, "200"] = _json(mesh_answer(capability, example, mesh, settings))
    by_path = {c.path: c for c in (*JSON_CAPABILITIES, *MESH_CAPABILITIES)}
    points, inverse = by_path["/v1/points"], by_path["/v1/points/inverse"]
    bad_points = dict(request_example(points.request), sigma=-1.0)
    found[points.path, "422"] = _problem(
        lambda: json_answer(points, bad_points, settings), JSON_BODY
    )
    bad_inverse = dict(request_example(inverse.request), pole_angle_deg=30.0)
    found[inverse.path, "422"] = _problem(
        lambda: json_answer(inverse, bad_inverse, settings), JSON_BODY
    )
    bad_region = dict(MESH_PARAMS_EXAMPLE, region={"faces": [3, 20]})
    tiny = Settings(max_faces=10).limits
    for capability in (by_path["/v1/flatten"], by_path["/v1/validate"]):
        found[capability.path, "422"] = _problem(
            lambda c=capability: mesh_answer(c, bad_region, mesh, settings), capability.places
        )
        found[capability.path, "413"] = _problem(
            lambda: read_mesh(mesh, "obj", tiny), capability.places
        )
    return found


def add_examples(document: dict) -> dict:
    """Put the request examples and :func:`examples` into an OpenAPI document, each answer
    only under its own media type (JSON answers under application/json, problems under
    application/problem+json); returns the document."""
    for capability in JSON_CAPABILITIES:
        operation = document["paths"][capability.path]["post"]
        media = operation["requestBody"]["content"]["application/json"]
        media["example"] = request_example(capability.request)
    for (path, status), example in examples().items():
        (operation,) = document["paths"][path].values()  # one method per path
        content = operation["responses"][status].setdefault("content", {})
        media_type = PROBLEM_JSON if status.startswith(("4", "5")) else JSON
        content.setdefault(media_type, {})["example"] = example
    return document
