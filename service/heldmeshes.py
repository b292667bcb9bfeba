"""``POST /v1/meshes``: a mesh sent once, kept by the worker (:mod:`service.meshcache`) and
named by the SHA-256 of its upload, which every mesh route then takes as
``params.mesh_sha256`` instead of the mesh part: a click on the map need not upload and
parse a 30 MB scan again.
"""

from __future__ import annotations

import hashlib
from typing import Literal

import orjson
from pydantic import BaseModel, ConfigDict, Field
from starlette.responses import Response

from .capabilities.context import JSON_BYTES_PER_BYTE, READER_BYTES_PER_BYTE, Context
from .capabilities.fields import Strict
from .capabilities.inputs import Upload, parse_params
from .capabilities.rows import MESH
from .encoding import JSON
from .errors import ErrorPlaces, InvalidInput
from .meshcache import MeshCache, TooLarge
from .meshio import FORMATS
from .problems import Problem, core_errors_as_problems
from .server.admission import Job
from .server.jobs import MiB
from .server.multipart import parse_form
from .timings import Timings

PATH = "/v1/meshes"
#: What parsing the body may take per byte beside the mesh, as for the mesh routes.
PARSE_BYTES_PER_BYTE = READER_BYTES_PER_BYTE


class HoldParams(Strict):
    """The JSON of the ``params`` field of POST /v1/meshes."""

    format: Literal[FORMATS] | None = Field(
        None, description="The file's format; default: from the file name's extension."
    )

    model_config = ConfigDict(json_schema_extra={"examples": [{"format": "obj"}]})


class HeldMesh(BaseModel):
    """A mesh the worker holds."""

    mesh_sha256: str = Field(
        description="The SHA-256 (hex) of the mesh part's bytes as sent: give it as "
        "params.mesh_sha256 to any mesh route instead of the mesh part."
    )
    vertices: int = Field(description="The mesh's vertex count.")
    faces: int = Field(description="The mesh's face count.")
    bytes: int = Field(
        description="What the mesh takes in the worker's cache (its arrays), of "
        "MESHFLAT_MESH_CACHE_BYTES; what is computed from it later takes more."
    )


#: Where a refusal's fields lie: the params, else the mesh part.
PLACES = ErrorPlaces("params.", frozenset(HoldParams.model_fields), "mesh")


def hold_mesh(meshes: MeshCache, body: bytes, content_type: str, job: Job) -> Response:
    """Read the form's mesh and keep it (CPU-bound: run off the event loop): 201 with its
    digest, or 200 when the worker held it already (it is not read again)."""
    timings = Timings(job.deadline)
    ctx = Context(job.settings, job.ticket)
    with core_errors_as_problems(PLACES), timings.measure("parse"):
        params, upload = _form(body, content_type, ctx)
        digest = hashlib.sha256(upload.data).hexdigest()
        held, status = meshes.get(digest), 200
        if held is None:
            mesh = MESH.read(upload, ctx, own=True, declared=params.format)
            try:
                held, status = meshes.put(digest, mesh), 201
            except TooLarge as error:
                raise _too_large(error) from None
            if held is None:
                raise Problem(
                    503,
                    "the service is busy: the memory budget of this process "
                    "(MESHFLAT_MEMORY_BUDGET) is taken by the jobs in flight, so the mesh "
                    "cannot be kept now; retry after 1 s",
                    "busy",
                    headers={"Retry-After": "1"},
                )
    mesh, size = held
    answer = HeldMesh(
        mesh_sha256=digest, vertices=len(mesh.vertices), faces=len(mesh.faces), bytes=size
    )
    return Response(
        orjson.dumps(answer.model_dump()),
        status_code=status,
        media_type=JSON,
        headers={"Server-Timing": timings.header()},
    )


def _form(body: bytes, content_type: str, ctx: Context) -> tuple[HoldParams, Upload]:
    """The params and the mesh part of the form."""
    form = parse_form(body, content_type)
    for name in form:
        if name not in ("params", MESH.name):
            raise InvalidInput(name, "this route reads no part of that name; it reads params, mesh")
    if MESH.name not in form:
        raise MESH.missing()
    text = form["params"].data if "params" in form else b"{}"
    ctx.charge(JSON_BYTES_PER_BYTE * len(text))  # its parse, as for the mesh routes
    part = form[MESH.name]
    return parse_params(HoldParams, bytes(text)), Upload(part.filename, part.data)


def _too_large(error: TooLarge) -> Problem:
    return Problem(
        413,
        f"mesh: it takes {error.size / MiB:,.1f} MiB in the cache, more than it holds "
        f"({error.capacity / MiB:,.1f} MiB, MESHFLAT_MESH_CACHE_BYTES): send it with each "
        "request instead",
        "mesh-too-large",
        "mesh",
    )


def request_body() -> dict:
    """The OpenAPI request body of POST /v1/meshes."""
    params = {
        "$ref": f"#/components/schemas/{HoldParams.__name__}",
        "description": "JSON, as the HoldParams schema; default {}.",
    }
    form = {
        "schema": {
            "type": "object",
            "required": [MESH.name],
            "properties": {
                "params": params,
                MESH.name: {"type": "string", "format": "binary", "description": MESH.documented},
            },
            "additionalProperties": False,
        },
        "encoding": {"params": {"contentType": "application/json"}},
    }
    return {"requestBody": {"required": True, "content": {"multipart/form-data": form}}}


#: The models the OpenAPI document adds for this route.
MODELS: tuple[type[BaseModel], ...] = (HoldParams,)
