"""The routes: thin handlers that parse, call the core off the event loop, and encode."""

from __future__ import annotations

import json
from functools import cache

import anyio
import numpy as np
from fastapi import APIRouter, Request
from pydantic import BaseModel, ValidationError
from starlette.concurrency import run_in_threadpool
from starlette.requests import ClientDisconnect
from starlette.responses import Response

from transforms import (
    Layout,
    TransformInputError,
    angles_to_world,
    fit_region,
    flatten_region,
    locate,
    world_to_angles,
)

from .encoding import Timings, json_response
from .meshio import Mesh, MeshFormatError, format_of, read_mesh
from .multipart import parse_form
from .params import (
    MESH_PARAMS_EXAMPLE,
    AutoPole,
    FitParams,
    InverseRequest,
    LocateParams,
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
    FitResponse,
    FlattenResponse,
    Health,
    InverseResponse,
    LocateResponse,
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
node transforms applied; groups are mesh and node names. PLY polygons are fan-triangulated
like OBJ's; other elements and properties are skipped. STL triangles keep their own corners
(nothing is merged).
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
    # A bundled file is trusted: read with the default limits, whatever the service's are.
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


# -- jobs --------------------------------------------------------------------------------


def json_body(model: type) -> dict:
    """The OpenAPI request body of a route that reads ``model`` as JSON itself."""
    schema = {"$ref": f"#/components/schemas/{model.__name__}"}
    return {"requestBody": {"required": True, "content": {"application/json": {"schema": schema}}}}


async def run_job(request: Request, work) -> Response:
    """Read the body (its size is bounded by the upload limit), then run
    ``work(body, content_type, settings)`` off the event loop, at most ``MESHFLAT_MAX_JOBS``
    at once: a slow upload does not hold a slot that a ready request could use."""
    settings = settings_of(request)
    try:
        body = await request.body()
    except ClientDisconnect:
        # Nobody is left to answer; nothing to log.
        return Response(status_code=400)
    content_type = request.headers.get("content-type", "")
    async with _job_slots(request.app, settings.max_jobs):
        return await run_in_threadpool(work, body, content_type, settings)


def _job_slots(app, total: int) -> anyio.CapacityLimiter:
    # Made on first use: a limiter belongs to the event loop that runs the app.
    if getattr(app.state, "job_slots", None) is None:
        app.state.job_slots = anyio.CapacityLimiter(total)
    return app.state.job_slots


def parse_json(model: type[BaseModel], body: bytes, content_type: str, prefix: str = ""):
    """``body`` validated as ``model`` (a 415 unless the content type is JSON, a 422 naming
    the fields otherwise)."""
    media_type = content_type.partition(";")[0].strip()
    if media_type.lower() != "application/json":
        raise Problem(
            415,
            f"send application/json, not {media_type or 'an untyped body'}",
            "unsupported-media-type",
        )
    try:
        return model.model_validate_json(body)
    except ValidationError as error:
        raise validation_problem(error.errors(), prefix) from None


# -- points --------------------------------------------------------------------------------


@router.post(
    "/v1/points",
    tags=["transforms"],
    summary="Points to (theta, phi, r)",
    response_model=PointsResponse,
    responses=PROBLEMS,
    openapi_extra=json_body(PointsRequest),
)
async def points(request: Request) -> Response:
    """World points to distorted-pole (or standard, or separable) coordinates, radians:
    ``theta`` the polar angle from local +Z, ``phi`` the azimuth from +X towards +Y.
    Body: JSON, as the PointsRequest schema."""
    return await run_job(request, answer_points)


def answer_points(body: bytes, content_type: str, settings: Settings) -> Response:
    """The /v1/points answer to a JSON body (CPU-bound: run it off the event loop)."""
    timings = Timings()
    with timings.measure("parse"):
        request = parse_json(PointsRequest, body, content_type)
        _check_count(len(request.points), settings.max_points, "points")
        points = np.asarray(request.points, dtype=np.float64)
    with timings.measure("compute"):
        chart, frame = _chart_and_frame(request)
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
    openapi_extra=json_body(InverseRequest),
)
async def points_inverse(request: Request) -> Response:
    """Coordinates back to world points, with the same parameters as /v1/points.
    Body: JSON, as the InverseRequest schema."""
    return await run_job(request, answer_inverse)


def answer_inverse(body: bytes, content_type: str, settings: Settings) -> Response:
    """The /v1/points/inverse answer to a JSON body (CPU-bound: run it off the event loop)."""
    timings = Timings()
    with timings.measure("parse"):
        request = parse_json(InverseRequest, body, content_type)
        _check_count(len(request.theta), settings.max_points, "theta")
    with timings.measure("compute"):
        chart, frame = _chart_and_frame(request)
        r = 1.0 if request.r is None else request.r
        world = checked(lambda: angles_to_world(request.theta, request.phi, r, frame, chart), "")
    return json_response({"points": world}, timings)


def _chart_and_frame(request: PointsRequest | InverseRequest):
    """The chart and the frame a points request names (a bad one: a 422 naming the field)."""
    return checked(lambda: (chart_of(request), frame_of(request, np.asarray(request.center))), "")


def _check_count(count: int, limit: int, field: str) -> None:
    if count > limit:
        raise Problem(
            413,
            f"{field}: {count:,} items; the limit is {limit:,} (MESHFLAT_MAX_POINTS)",
            "too-many-points",
            field,
        )


# -- meshes --------------------------------------------------------------------------------


def _mesh_route(path: str, summary: str, model: type[BaseModel], description: str):
    """A multipart mesh route: a ``mesh`` file and a ``params`` JSON field."""
    return router.post(
        path,
        tags=["meshes"],
        summary=summary,
        response_model=model,
        responses=PROBLEMS,
        openapi_extra=MULTIPART_BODY,
        description=f"{description}\n{MESH_RULES}",
    )


@_mesh_route(
    "/v1/flatten",
    "Flatten a region of a mesh",
    FlattenResponse,
    "Multipart: a `mesh` file and a `params` JSON field (MeshParams). Answers "
    "the resolved parameters, (theta, phi, r) of every vertex the region uses, the region's "
    "triangles, the validation report and the distortion metrics.",
)
async def flatten(request: Request) -> Response:
    return await run_job(request, flatten_answer)


@_mesh_route(
    "/v1/validate",
    "Validate a region of a mesh",
    ValidateResponse,
    "The same input as /v1/flatten; answers only the resolved parameters, the "
    "validation report and the distortion metrics.",
)
async def validate(request: Request) -> Response:
    return await run_job(request, validate_answer)


@_mesh_route(
    "/v1/fit",
    "Choose the centre, rotation and sigma for a region",
    FitResponse,
    "The same input as /v1/flatten, but centre, rotation and sigma not given are "
    'chosen ("auto"); any of them may be fixed. They are chosen together to minimise the '
    "region's area-weighted isometric energy, keeping the centre inside the region's kernel "
    "at a depth of at least min_kernel_depth of its inscribed radius and the margin to the "
    "seam and the singular points at least min_margin_deg. The search starts from the "
    "kernel's deepest point (a linear program), the middle of the largest cap free of region "
    "directions as the pole, the roll along the region's widest spread about the pole (or "
    "the up hint), and the best sigma with that cap; then refines the free ones together on "
    "an area-weighted sample of the triangles. Answers the resolved parameters, the "
    "validation and metrics they give on every triangle, and `explain`.",
)
async def fit(request: Request) -> Response:
    return await run_job(request, fit_answer)


@_mesh_route(
    "/v1/locate",
    "Find the surface points of directions on the map",
    LocateResponse,
    "Multipart like /v1/flatten; `params` also holds the queries, `theta` and "
    "`phi` (radians, in the frame the other params resolve to). Answers, per query, the "
    "region triangle the ray from the centre in that direction meets first, the barycentric "
    "weights of the hit (of the triangle's vertices in file order) and the hit point (world "
    "coordinates), or null where the ray misses the region.",
)
async def locate_points(request: Request) -> Response:
    return await run_job(request, locate_answer)


def locate_answer(body: bytes, content_type: str, settings: Settings) -> Response:
    """The /v1/locate answer to a multipart body (CPU-bound: run it off the event loop)."""
    timings = Timings()
    with timings.measure("parse"):
        params, mesh = _mesh_request(body, content_type, settings, LocateParams)
        _check_count(len(params.theta), settings.max_points, "params.theta")
    with timings.measure("compute"):
        faces, center = region_faces(mesh, params)
        chart, frame, _ = _chart_frame_fit(mesh, faces, center, params, settings)
        directions = checked(lambda: chart.inverse(params.theta, params.phi, 1.0))
        try:  # every vertex given, so that an error names the file's vertex ids
            hits = locate(frame.to_local(mesh.vertices), mesh.faces[faces], directions)
        except TransformInputError as error:
            raise _mesh_error(error) from None
        found = hits.faces >= 0
        world = frame.to_world(np.where(found[:, None], hits.points, 0.0))
        ids = np.where(found, faces[np.maximum(hits.faces, 0)], -1).tolist()
        weights = np.where(found[:, None], hits.barycentric, 0.0).tolist()
        answer = [
            {"face": face, "barycentric": weight, "point": point} if face >= 0 else None
            for face, weight, point in zip(ids, weights, world.tolist(), strict=True)
        ]
    return json_response({"params": resolved(chart, frame), "hits": answer}, timings)


def flatten_answer(body: bytes, content_type: str, settings: Settings) -> Response:
    """The /v1/flatten answer to a multipart body (CPU-bound: run it off the event loop)."""
    return _mesh_answer(body, content_type, settings, full=True)


def validate_answer(body: bytes, content_type: str, settings: Settings) -> Response:
    """The /v1/validate answer to a multipart body (CPU-bound: run it off the event loop)."""
    return _mesh_answer(body, content_type, settings, full=False)


def fit_answer(body: bytes, content_type: str, settings: Settings) -> Response:
    """The /v1/fit answer to a multipart body (CPU-bound: run it off the event loop)."""
    return _mesh_answer(body, content_type, settings, full=False, model=FitParams)


def _mesh_answer(
    body: bytes,
    content_type: str,
    settings: Settings,
    full: bool,
    model: type[MeshParams] = MeshParams,
) -> Response:
    timings = Timings()
    with timings.measure("parse"):
        params, mesh = _mesh_request(body, content_type, settings, model)
    with timings.measure("compute"):
        payload = _flatten_payload(mesh, params, settings, full)
    return json_response(payload, timings)


def _mesh_request(body: bytes, content_type: str, settings: Settings, model: type[MeshParams]):
    """The params and the mesh of a multipart mesh request."""
    form = parse_form(body, content_type)
    params = _mesh_params(form, model)
    if "mesh" not in form:
        raise Problem(422, "mesh: the form has no 'mesh' file field", "invalid-request", "mesh")
    part = form["mesh"]
    try:
        fmt = format_of(part.filename, params.format)
        mesh = read_mesh(bytes(part.data), fmt, settings.limits)
    except MeshFormatError as error:
        raise from_mesh_error(error) from None
    return params, mesh


def _mesh_params(form, model: type[MeshParams]) -> MeshParams:
    data = bytes(form["params"].data) if "params" in form else b"{}"  # no params: defaults
    return parse_json(model, data, "application/json", "params")


#: Core errors about these inputs are the parameters' fault; any other is the file's.
_PARAMETER_FIELDS = {
    "center",
    "up",
    "pole",
    "rotation",
    "sigma",
    "min_kernel_depth",
    "min_margin_deg",
}


def _mesh_error(error: TransformInputError) -> Problem:
    if error.field in _PARAMETER_FIELDS:
        return from_transform_error(error, "params.")
    return Problem(422, f"mesh: {error.message}", "invalid-input", "mesh", error.indices)


def _chart_frame_fit(mesh: Mesh, faces: np.ndarray, center, params: MeshParams, settings):
    """The chart and frame the parameters name, fitted (with the fit) where any is "auto"."""
    if not params.auto:
        chart = checked(lambda: chart_of(params))
        return chart, checked(lambda: frame_of(params, center)), None
    try:
        fit = fit_region(
            mesh.vertices,
            mesh.faces[faces],
            threads=settings.threads,
            **_fit_arguments(params, center),
        )
    except TransformInputError as error:
        raise _mesh_error(error) from None
    return fit.chart, fit.frame, fit


def _flatten_payload(mesh: Mesh, params: MeshParams, settings: Settings, full: bool) -> dict:
    faces, center = region_faces(mesh, params)
    chart, frame, fit = _chart_frame_fit(mesh, faces, center, params, settings)
    explain = None
    if fit is not None:
        flat = fit.region
        explain = _explain(fit.explanation, faces) if isinstance(params, FitParams) else None
    else:
        try:
            flat = flatten_region(
                mesh.vertices,
                mesh.faces[faces],
                frame,
                chart,
                threads=settings.threads,
                layout=params.layout,
            )
        except TransformInputError as error:
            # The parameters were checked above: what is left is about the file's vertices.
            raise _mesh_error(error) from None
    v = flat.validation
    face_ids = lambda positions: faces[positions]  # noqa: E731 - positions -> file ids
    d = flat.distortion
    payload = {
        "params": {**resolved(chart, frame), "layout": flat.layout.value},
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
    if explain is not None:
        payload["explain"] = explain
    if full:
        payload["vertices"] = {
            "ids": flat.vertex_ids,
            "theta": flat.theta,
            "phi": flat.phi,
            "r": flat.r,
        }
        if flat.layout is not Layout.THETA_PHI:
            payload["vertices"] |= {"x": flat.x, "y": flat.y}
        payload["faces"] = {"ids": faces, "vertices": mesh.faces[faces]}
    return payload


def _fit_arguments(params: MeshParams, center) -> dict:
    """What :func:`transforms.fit_region` is given: the fixed parameters, None for the
    chosen ones."""
    rotation, up = params.rotation, None
    if rotation == "auto":
        rotation = None
    elif isinstance(rotation, AutoPole):
        rotation, up = None, rotation.up
    else:
        rotation = checked(lambda: frame_of(params, np.zeros(3)))
    sigma = None
    if params.sigma != "auto" and params.method != "standard":
        sigma = checked(lambda: chart_of(params)).cap.sigma  # given, or the default
    return {
        "method": params.method,
        "center": None if params.center == "auto" else center,
        "rotation": rotation,
        "up": up,
        "sigma": sigma,
        "min_kernel_depth": params.min_kernel_depth,
        "min_margin_deg": params.min_margin_deg,
        "layout": params.layout,
    }


def _explain(explanation, faces: np.ndarray) -> dict:
    """The ``explain`` block of /v1/fit."""
    e = explanation
    return {
        "energy_start": e.energy_start,
        "energy_end": e.energy_end,
        "kernel_inscribed_radius": e.kernel_inscribed_radius,
        "kernel_empty": e.kernel_empty,
        "center_depth": e.center_depth,
        "empty_cap_deg": e.empty_cap_deg,
        "margin_deg": e.margin_deg,
        "energy_at_sigma": [
            {"sigma": sigma, "energy": energy} for sigma, energy in e.energy_at_sigma.items()
        ],
        "backfacing_faces": faces[e.backfacing_faces],
        "notes": list(e.notes),
    }
