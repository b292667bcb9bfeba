"""The routes: thin handlers that parse, call the core off the event loop, and encode."""

from __future__ import annotations

import json
from functools import cache

import numpy as np
from fastapi import APIRouter, Request
from pydantic import ValidationError
from starlette.concurrency import run_in_threadpool
from starlette.responses import Response

from transforms import TransformInputError, angles_to_world, flatten_region, world_to_angles

from .encoding import Timings, json_response
from .meshio import Mesh, MeshFormatError, format_of, read_mesh
from .multipart import parse_form
from .params import (
    MESH_PARAMS_EXAMPLE,
    InverseRequest,
    MeshParams,
    PointsRequest,
    chart_of,
    checked,
    frame_of,
    region_faces,
    resolved,
)
from .problems import Problem, from_mesh_error, from_transform_error, validation_problem
from .samples import SAMPLES
from .schemas import (
    PROBLEMS,
    FlattenResponse,
    Health,
    InverseResponse,
    PointsResponse,
    SampleInfo,
    ValidateResponse,
)
from .settings import Settings

router = APIRouter()

MULTIPART_BODY = {
    "requestBody": {
        "required": True,
        "content": {
            "multipart/form-data": {
                "schema": {
                    "type": "object",
                    "required": ["mesh"],
                    "properties": {
                        "mesh": {
                            "type": "string",
                            "format": "binary",
                            "description": "The mesh file: OBJ, glTF (embedded buffers), GLB, "
                            "PLY or STL; the format comes from the file name's extension "
                            "or params.format.",
                        },
                        "params": {
                            "type": "string",
                            "contentMediaType": "application/json",
                            "contentSchema": {"$ref": "#/components/schemas/MeshParams"},
                            "description": "JSON, as the MeshParams schema; default {}.",
                            "example": json.dumps(MESH_PARAMS_EXAMPLE),
                        },
                    },
                },
                "encoding": {"params": {"contentType": "application/json"}},
            }
        },
    }
}

MESH_RULES = """
Mesh files are read from the uploaded bytes only: a glTF buffer or image that refers to a
file or URL is refused. The file's order is kept: vertex ``i`` is the file's ``i``-th vertex
and face ``i`` its ``i``-th triangle. OBJ polygons are fan-triangulated in order, ``(a, b, c),
(a, c, d), ...``; negative references count back; groups are ``g`` (each name), ``o`` and
``usemtl`` names. glTF triangles come primitive by primitive in document order (the default
scene's nodes depth first, children in order, each node's mesh's primitives in order) with
node transforms applied; groups are mesh and node names. STL triangles keep their own
corners (nothing is merged).
"""


def settings_of(request: Request) -> Settings:
    return request.app.state.settings


# -- health and samples ------------------------------------------------------------------


@router.get("/healthz", tags=["health"], summary="Liveness")
def healthz() -> Health:
    """Answers while the process serves requests."""
    return Health()


@router.get(
    "/readyz",
    tags=["health"],
    summary="Readiness",
    responses={503: PROBLEMS[422] | {"description": "The start-up self-check has not passed."}},
)
def readyz(request: Request) -> Health:
    """Answers 200 once the start-up self-check (a bundled scan flattened) has passed."""
    if not getattr(request.app.state, "ready", False):
        raise Problem(503, "the start-up self-check has not passed yet", "not-ready")
    return Health()


@cache
def _sample_info(name: str) -> SampleInfo:
    sample = SAMPLES[name]
    data = sample.path.read_bytes()
    mesh = read_mesh(data, format_of(name, None), Settings().limits)
    return SampleInfo(
        name=name,
        format=mesh.format,
        vertices=len(mesh.vertices),
        faces=len(mesh.faces),
        bytes=len(data),
        description=sample.description,
        credit=sample.credit,
        licence=sample.licence,
        url=f"/v1/samples/{name}",
    )


@router.get("/v1/samples", tags=["samples"], summary="The bundled sample meshes")
async def samples() -> list[SampleInfo]:
    """Real scans bundled with the service, with their face counts and credits."""
    return await run_in_threadpool(sample_infos)


def sample_infos() -> list[SampleInfo]:
    return [_sample_info(name) for name in SAMPLES]


_MEDIA_TYPES = {
    "obj": "model/obj",
    "glb": "model/gltf-binary",
    "gltf": "model/gltf+json",
    "ply": "application/octet-stream",
    "stl": "model/stl",
}


@router.get(
    "/v1/samples/{name}",
    tags=["samples"],
    summary="Download a sample mesh",
    response_class=Response,
    responses={
        200: {"content": {t: {} for t in set(_MEDIA_TYPES.values())}, "description": "The file."},
        404: PROBLEMS[422] | {"description": "No such sample."},
        422: PROBLEMS[422],
    },
)
def sample_file(name: str) -> Response:
    """The file itself, as bundled."""
    if name not in SAMPLES:
        raise Problem(404, f"no sample named {name!r}; see /v1/samples", "not-found", "name")
    return Response(
        SAMPLES[name].path.read_bytes(),
        media_type=_MEDIA_TYPES[format_of(name, None)],
        headers={"Content-Disposition": f'attachment; filename="{name}"'},
    )


# -- points --------------------------------------------------------------------------------


@router.post(
    "/v1/points",
    tags=["transforms"],
    summary="Points to (theta, phi, r)",
    response_model=PointsResponse,
    responses=PROBLEMS,
)
async def points(body: PointsRequest, request: Request) -> Response:
    """World points to distorted-pole (or standard, or separable) coordinates, radians:
    ``theta`` the polar angle from local +Z, ``phi`` the azimuth from +X towards +Y."""
    settings = settings_of(request)
    _check_count(len(body.points), settings.max_points, "points")
    return await run_in_threadpool(answer_points, body, settings)


def answer_points(body: PointsRequest, settings: Settings) -> Response:
    """The /v1/points answer (CPU-bound: run it off the event loop)."""
    timings = Timings()
    with timings.measure("parse"):
        points = np.asarray(body.points, dtype=np.float64)
    with timings.measure("compute"):
        chart, frame = _chart_and_frame(body)
        theta, phi, r = checked(
            lambda: world_to_angles(points, frame, chart, threads=settings.threads), ""
        )
    return json_response({"theta": theta, "phi": phi, "r": r}, timings)


@router.post(
    "/v1/points/inverse",
    tags=["transforms"],
    summary="(theta, phi, r) to points",
    response_model=InverseResponse,
    responses=PROBLEMS,
)
async def points_inverse(body: InverseRequest, request: Request) -> Response:
    """Coordinates back to world points, with the same parameters as /v1/points."""
    settings = settings_of(request)
    _check_count(len(body.theta), settings.max_points, "theta")
    return await run_in_threadpool(answer_inverse, body, settings)


def answer_inverse(body: InverseRequest, settings: Settings) -> Response:
    """The /v1/points/inverse answer (CPU-bound: run it off the event loop)."""
    timings = Timings()
    with timings.measure("compute"):
        chart, frame = _chart_and_frame(body)
        r = 1.0 if body.r is None else body.r
        world = checked(lambda: angles_to_world(body.theta, body.phi, r, frame, chart), "")
    return json_response({"points": world}, timings)


def _chart_and_frame(body: PointsRequest | InverseRequest):
    """The chart and the frame a points request names (a bad one: a 422 naming the field)."""
    return checked(lambda: (chart_of(body), frame_of(body, np.asarray(body.center))), "")


def _check_count(count: int, limit: int, field: str) -> None:
    if count > limit:
        raise Problem(
            413,
            f"{field}: {count:,} items; the limit is {limit:,} (MESHFLAT_MAX_POINTS)",
            "too-many-points",
            field,
        )


# -- meshes --------------------------------------------------------------------------------


@router.post(
    "/v1/flatten",
    tags=["meshes"],
    summary="Flatten a region of a mesh",
    response_model=FlattenResponse,
    responses=PROBLEMS,
    openapi_extra=MULTIPART_BODY,
    description="Multipart: a `mesh` file and a `params` JSON field (MeshParams). Answers "
    "the resolved parameters, (theta, phi, r) of every vertex the region uses, the region's "
    "triangles, the validation report and the distortion metrics.\n" + MESH_RULES,
)
async def flatten(request: Request) -> Response:
    return await _mesh_job(request, full=True)


@router.post(
    "/v1/validate",
    tags=["meshes"],
    summary="Validate a region of a mesh",
    response_model=ValidateResponse,
    responses=PROBLEMS,
    openapi_extra=MULTIPART_BODY,
    description="The same input as /v1/flatten; answers only the resolved parameters, the "
    "validation report and the distortion metrics.\n" + MESH_RULES,
)
async def validate(request: Request) -> Response:
    return await _mesh_job(request, full=False)


async def _mesh_job(request: Request, full: bool) -> Response:
    settings = settings_of(request)
    body = await request.body()
    content_type = request.headers.get("content-type", "")
    return await run_in_threadpool(run_mesh_job, body, content_type, settings, full)


def run_mesh_job(body: bytes, content_type: str, settings: Settings, full: bool) -> Response:
    """The /v1/flatten (``full``) or /v1/validate answer to a multipart body (CPU-bound: run
    it off the event loop)."""
    timings = Timings()
    with timings.measure("parse"):
        form = parse_form(body, content_type)
        params = _mesh_params(form)
        if "mesh" not in form:
            raise Problem(422, "mesh: the form has no 'mesh' file field", "invalid-request", "mesh")
        part = form["mesh"]
        try:
            fmt = format_of(part.filename, params.format)
            mesh = read_mesh(bytes(part.data), fmt, settings.limits)
        except MeshFormatError as error:
            raise from_mesh_error(error) from None
    with timings.measure("compute"):
        payload = _flatten_payload(mesh, params, settings, full)
    return json_response(payload, timings)


def _mesh_params(form) -> MeshParams:
    if "params" not in form:
        return MeshParams()
    try:
        return MeshParams.model_validate_json(bytes(form["params"].data))
    except ValidationError as error:
        raise validation_problem(error.errors(), "params") from None


def _flatten_payload(mesh: Mesh, params: MeshParams, settings: Settings, full: bool) -> dict:
    chart = checked(lambda: chart_of(params))
    faces, center = region_faces(mesh, params)
    frame = checked(lambda: frame_of(params, center))
    try:
        flat = flatten_region(
            mesh.vertices, mesh.faces[faces], frame, chart, threads=settings.threads
        )
    except TransformInputError as error:
        raise from_transform_error(error, "mesh: " if error.field == "vertices" else "") from None
    v = flat.validation
    face_ids = lambda positions: faces[positions]  # noqa: E731 - positions -> file ids
    d = flat.distortion
    payload = {
        "params": resolved(chart, frame),
        "validation": {
            "seam_free": v.seam_free,
            "star_shaped": v.star_shaped,
            "singular_point_faces": face_ids(v.singular_point_faces),
            "seam_faces": face_ids(v.seam_faces),
            "folded_faces": face_ids(v.folded_faces),
            "backfacing_faces": face_ids(v.backfacing_faces),
            "degenerate_faces": face_ids(v.degenerate_faces),
            "margin_deg": {
                "seam": v.margin_deg_seam,
                "north": v.margin_deg_north,
                "south": v.margin_deg_south,
            },
            "boundary_loops": v.boundary_loops,
            "winding": "outward" if v.winding == 1 else "inward",
        },
        "metrics": {
            name: {"mean": s.mean, "p95": s.p95, "max": s.max}
            for name, s in (
                ("conformal", d.conformal),
                ("area", d.area),
                ("isometric", d.isometric),
            )
        },
    }
    if full:
        payload["vertices"] = {
            "ids": flat.vertex_ids,
            "theta": flat.theta,
            "phi": flat.phi,
            "r": flat.r,
        }
        payload["faces"] = {"ids": faces, "vertices": mesh.faces[faces]}
    return payload
