"""Examples for the OpenAPI document, made by running the service's own code on the request
schemas' own examples (for meshes: the top of a unit icosahedron), so they show real answers.

Floats are rounded to six decimals, so the committed document does not depend on the last
bit of a platform's sine.
"""

from __future__ import annotations

import json

import orjson
import trimesh
from pydantic import ValidationError

from .api import answer_inverse, answer_points, flatten_answer, sample_infos, validate_answer
from .meshio import MeshFormatError, read_mesh
from .params import MESH_PARAMS_EXAMPLE, InverseRequest, PointsRequest
from .problems import Problem, from_mesh_error, problem_response, validation_problem
from .schemas import Health
from .settings import Settings

BOUNDARY = "example-boundary"
MULTIPART = f"multipart/form-data; boundary={BOUNDARY}"
JSON = "application/json"


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


def _dumped(example: dict, **changes) -> bytes:
    return json.dumps(dict(example, **changes)).encode()


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


def _problem(call) -> dict:
    try:
        call()
    except Problem as problem:
        return _json(problem_response(problem).body)
    except MeshFormatError as error:
        return _json(problem_response(from_mesh_error(error)).body)
    except ValidationError as error:
        return _json(problem_response(validation_problem(error.errors())).body)
    raise AssertionError("the example call did not fail")


def examples() -> dict[tuple[str, str], dict | list]:
    """(path, status) -> example answer body."""
    settings = Settings()
    mesh = icosahedron_obj()
    body = multipart_body(MESH_PARAMS_EXAMPLE, "icosahedron.obj", mesh)
    points = PointsRequest.model_config["json_schema_extra"]["examples"][0]
    inverse = InverseRequest.model_config["json_schema_extra"]["examples"][0]
    bad_region = dict(MESH_PARAMS_EXAMPLE, region={"faces": [3, 20]})
    tiny = Settings(max_faces=10).limits
    mesh_problems = {
        "422": _problem(
            lambda: flatten_answer(
                multipart_body(bad_region, "icosahedron.obj", mesh), MULTIPART, settings
            )
        ),
        "413": _problem(lambda: read_mesh(mesh, "obj", tiny)),
    }
    point_problem = _problem(lambda: answer_points(_dumped(points, sigma=-1.0), JSON, settings))
    return {
        ("/healthz", "200"): Health().model_dump(),
        ("/readyz", "200"): Health().model_dump(),
        ("/v1/samples", "200"): [info.model_dump() for info in sample_infos()],
        ("/v1/points", "200"): _json(answer_points(_dumped(points), JSON, settings).body),
        ("/v1/points", "422"): point_problem,
        ("/v1/points/inverse", "200"): _json(answer_inverse(_dumped(inverse), JSON, settings).body),
        ("/v1/points/inverse", "422"): _problem(
            lambda: answer_inverse(_dumped(inverse, pole_angle_deg=30.0), JSON, settings)
        ),
        ("/v1/flatten", "200"): _json(flatten_answer(body, MULTIPART, settings).body),
        ("/v1/validate", "200"): _json(validate_answer(body, MULTIPART, settings).body),
        **{("/v1/flatten", status): problem for status, problem in mesh_problems.items()},
        **{("/v1/validate", status): problem for status, problem in mesh_problems.items()},
    }


def add_examples(document: dict) -> dict:
    """Put the request examples and :func:`examples` into an OpenAPI document; returns it."""
    for path, model in (("/v1/points", PointsRequest), ("/v1/points/inverse", InverseRequest)):
        media = document["paths"][path]["post"]["requestBody"]["content"]["application/json"]
        media["example"] = model.model_config["json_schema_extra"]["examples"][0]
    for (path, status), example in examples().items():
        (operation,) = document["paths"][path].values()  # one method per path
        response = operation["responses"][status]
        for media in response.setdefault("content", {}).values():
            media["example"] = example
    return document
