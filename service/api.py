"""The routes: thin handlers that parse, call the core off the event loop, and encode."""

from __future__ import annotations

import gc
from dataclasses import dataclass
from functools import cache, partial
from typing import Annotated

import anyio
import anyio.to_thread
import numpy as np
from fastapi import APIRouter, Path, Request
from pydantic import BaseModel, ValidationError
from starlette.concurrency import run_in_threadpool
from starlette.requests import ClientDisconnect
from starlette.responses import Response

from transforms import (
    Chart,
    FlatRegion,
    Frame,
    Layout,
    TransformInputError,
    angles_to_world,
    fit_region,
    flatten_region,
    locate,
    world_to_angles,
)

from .allocator import release_free_memory
from .encoding import Timings, encode, json_response
from .jobs import Deadline, JobGate, TimeLimit
from .meshio import Mesh, MeshFormatError, format_of, read_mesh
from .multipart import parse_form
from .observability import metrics_response, observe_mesh
from .outputs import Output, choose_output
from .outputs.draw import to_png, to_svg
from .outputs.glb import layout_uv, region_glb
from .outputs.picture import describe
from .params import (
    AutoPole,
    FitParams,
    FlattenParams,
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


def multipart_body(model: type[BaseModel]) -> dict:
    """The OpenAPI request body of a mesh route whose ``params`` field is ``model``."""
    name = model.__name__
    example = model.model_config["json_schema_extra"]["examples"][0]
    mesh = {
        "type": "string",
        "format": "binary",
        "description": "The mesh file: OBJ, glTF (embedded buffers), GLB, PLY or STL; the "
        "format comes from the file name's extension or params.format.",
    }
    # An object part sent as JSON (the encoding below): clients and generators that read the
    # document build it from the schema itself.
    params = {
        "$ref": f"#/components/schemas/{name}",
        "description": f"JSON, as the {name} schema; default {{}}.",
        "example": example,
    }
    form = {
        "schema": {
            "type": "object",
            "required": ["mesh"],
            "properties": {"mesh": mesh, "params": params},
        },
        "encoding": {"params": {"contentType": "application/json"}},
    }
    return {"requestBody": {"required": True, "content": {"multipart/form-data": form}}}


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


GLB_RULES = """
The GLB holds one triangle mesh: `POSITION`, the file's coordinates of the region's vertices
in the order of `vertices.ids`; `TEXCOORD_0`, the layout scaled into [0, 1] by one factor
(`u = (x - x_min) * scale`, `v = (s - s_min) * scale`, with `s = s_sign * y` growing with
theta: +1 for theta_phi, -1 for mercator; the numbers are in `asset.extras.meshflat.uv`);
`_VERTEX_ID`, each vertex's file id (float32, exact below 2^24); and a material that shows a
checker through the UVs. Triangle `k` (indices `3k .. 3k+2`) is file face `faces.ids[k]`;
the ids are also the accessor named by `asset.extras.meshflat.face_ids_accessor`.
`asset.extras.meshflat` also holds the resolved `params`, the validation summary (counts of
flagged faces) and the metrics.
"""

_BINARY = {"schema": {"type": "string", "format": "binary"}}
FLATTEN_FORMS = {
    200: {
        "content": {
            "model/gltf-binary": _BINARY,
            "image/svg+xml": {"schema": {"type": "string"}},
            "image/png": _BINARY,
        },
        "description": "The flattened region, in the form asked for.",
    },
    406: PROBLEMS[422] | {"description": "Accept allows none of the forms /v1/flatten answers."},
}


def settings_of(request: Request) -> Settings:
    return request.app.state.settings


# -- health and samples ------------------------------------------------------------------


@router.get("/healthz", tags=["health"], summary="Liveness")
async def healthz() -> Health:
    """Answers while the process serves requests (on the event loop: never queued behind the
    jobs' threads)."""
    return Health()


@router.get(
    "/readyz",
    tags=["health"],
    summary="Readiness",
    responses={503: PROBLEMS[422] | {"description": "The start-up self-check has not passed."}},
)
async def readyz(request: Request) -> Health:
    """Answers 200 once the start-up self-check (a bundled scan flattened) has passed."""
    if not getattr(request.app.state, "ready", False):
        raise Problem(503, "the start-up self-check has not passed yet", "not-ready")
    return Health()


@router.get(
    "/metrics",
    tags=["health"],
    summary="Prometheus metrics",
    response_class=Response,
    responses={
        200: {
            "content": {"text/plain": {"schema": {"type": "string"}}},
            "description": "The Prometheus text exposition format, version 0.0.4.",
        }
    },
)
async def metrics() -> Response:
    """Requests by route, method and status (counts and latency histograms), the sizes of the
    meshes read, jobs in flight and computing, and refusals by reason; with several worker
    processes, summed over all of them."""
    return metrics_response()


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


@router.get(
    "/v1/samples",
    tags=["samples"],
    summary="The bundled sample meshes",
    responses={401: PROBLEMS[401]},
)
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
        401: PROBLEMS[401],
        404: PROBLEMS[422] | {"description": "No such sample."},
        422: PROBLEMS[422],
    },
)
def sample_file(
    name: Annotated[
        str,
        Path(description="A bundled sample's name.", json_schema_extra={"enum": list(SAMPLES)}),
    ],
) -> Response:
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
    """Admit the job (a 503 at once when this process has no room, see :mod:`service.jobs`),
    read the body (bounded by the upload limit), then run ``work(body, content_type,
    settings)`` off the event loop in a compute slot, all within the time limit. A slow upload
    holds an admission but no compute slot."""
    settings = settings_of(request)
    ticket = job_gate(request.app).admit()
    deadline = Deadline.after(settings.request_timeout)
    try:
        try:
            with anyio.fail_after(settings.request_timeout):
                body = await request.body()
        except ClientDisconnect:
            # Nobody is left to answer; 499 (as nginx says) marks it in the log and metrics.
            return Response(status_code=499)
        except TimeoutError:
            raise TimeLimit(settings.request_timeout, while_reading=True) from None
        content_type = request.headers.get("content-type", "")
        job = partial(ticket.run, work, deadline, body, content_type, settings)
        try:
            with anyio.fail_after(max(0.0, deadline.remaining())):
                return await anyio.to_thread.run_sync(job, abandon_on_cancel=True)
        except TimeoutError:
            raise TimeLimit(settings.request_timeout, while_reading=False) from None
    finally:
        # A computation that started ends the admission itself, even one that runs on after
        # its client had the 504; this ends it for one that never started.
        ticket.release()


def job_gate(app) -> JobGate:
    """The process's :class:`JobGate` (one per app: a worker process has one app)."""
    if getattr(app.state, "job_gate", None) is None:
        settings = app.state.settings
        app.state.job_gate = JobGate(settings.max_jobs, settings.max_waiting, on_idle=_shrink)
    return app.state.job_gate


def _shrink() -> None:
    """An idle worker gives its free heap back (see service.allocator), after freeing what
    only reference cycles kept (arrays held by a traceback's frames, say)."""
    gc.collect()
    release_free_memory()


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


def _mesh_route(
    path: str,
    summary: str,
    model: type[BaseModel],
    params: type[MeshParams],
    description: str,
    responses: dict | None = None,
):
    """A multipart mesh route: a ``mesh`` file and a ``params`` JSON field (``params``)."""
    return router.post(
        path,
        tags=["meshes"],
        summary=summary,
        response_model=model,
        responses=PROBLEMS | (responses or {}),
        openapi_extra=multipart_body(params),
        description=f"{description}\n{MESH_RULES}",
    )


@_mesh_route(
    "/v1/flatten",
    "Flatten a region of a mesh",
    FlattenResponse,
    FlattenParams,
    "Multipart: a `mesh` file and a `params` JSON field (FlattenParams). Answers "
    "the resolved parameters, (theta, phi, r) of every vertex the region uses, the region's "
    "triangles, the validation report and the distortion metrics; or, by the Accept header "
    "or params.output, the region as a GLB (model/gltf-binary) whose TEXCOORD_0 is the "
    "layout, or a picture of the map (image/svg+xml, image/png).\n" + GLB_RULES,
    responses=FLATTEN_FORMS,
)
async def flatten(request: Request) -> Response:
    accept = request.headers.get("accept")
    return await run_job(request, partial(flatten_answer, accept=accept))


@_mesh_route(
    "/v1/validate",
    "Validate a region of a mesh",
    ValidateResponse,
    MeshParams,
    "The same input as /v1/flatten; answers only the resolved parameters, the "
    "validation report and the distortion metrics.",
)
async def validate(request: Request) -> Response:
    return await run_job(request, validate_answer)


@_mesh_route(
    "/v1/fit",
    "Choose the centre, rotation and sigma for a region",
    FitResponse,
    FitParams,
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
    LocateParams,
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


def flatten_answer(
    body: bytes, content_type: str, settings: Settings, accept: str | None = None
) -> Response:
    """The /v1/flatten answer to a multipart body, in the form ``Accept`` or
    ``params.output`` asks for (CPU-bound: run it off the event loop)."""
    timings = Timings()
    with timings.measure("parse"):
        params, mesh = _mesh_request(body, content_type, settings, FlattenParams)
        output = choose_output(accept, params.output)
    data = flatten_output(mesh, params, settings, output, timings)
    headers = {"Server-Timing": timings.header(), "Vary": "Accept"}
    if output is not Output.JSON:
        headers["Content-Disposition"] = f'inline; filename="region.{output.value}"'
    return Response(data, media_type=output.media_type, headers=headers)


def flatten_output(
    mesh: Mesh, params: FlattenParams, settings: Settings, output: Output, timings: Timings
) -> bytes:
    """What /v1/flatten (and ``meshflat flatten``) answers, as bytes of ``output``."""
    with timings.measure("compute"):
        region = _flattened(mesh, params, settings)
    with timings.measure("encode"):
        if output is Output.JSON:
            return encode(_payload(region, mesh, full=True))
        if output is Output.GLB:
            return _glb(region, mesh)
        picture = describe(
            region.flat,
            region.payload_params(),
            len(region.faces),
            params.image_width,
            params.image_height,
        )
        return to_svg(picture) if output is Output.SVG else to_png(picture)


def validate_answer(body: bytes, content_type: str, settings: Settings) -> Response:
    """The /v1/validate answer to a multipart body (CPU-bound: run it off the event loop)."""
    return _mesh_answer(body, content_type, settings, MeshParams)


def fit_answer(body: bytes, content_type: str, settings: Settings) -> Response:
    """The /v1/fit answer to a multipart body (CPU-bound: run it off the event loop)."""
    return _mesh_answer(body, content_type, settings, FitParams)


def _mesh_answer(
    body: bytes, content_type: str, settings: Settings, model: type[MeshParams]
) -> Response:
    timings = Timings()
    with timings.measure("parse"):
        params, mesh = _mesh_request(body, content_type, settings, model)
    return json_response(report(mesh, params, settings, timings), timings)


def report(mesh: Mesh, params: MeshParams, settings: Settings, timings: Timings) -> dict:
    """What /v1/validate and /v1/fit (and ``meshflat validate``, ``fit``) answer: params,
    validation, metrics, and for the fit its ``explain``; no per-vertex arrays."""
    with timings.measure("compute"):
        return _payload(_flattened(mesh, params, settings), mesh, full=False)


def _mesh_request(body: bytes, content_type: str, settings: Settings, model: type[MeshParams]):
    """The params and the mesh of a multipart mesh request."""
    form = parse_form(body, content_type)
    params = _mesh_params(form, model)
    if "mesh" not in form:
        raise Problem(422, "mesh: the form has no 'mesh' file field", "invalid-request", "mesh")
    part = form["mesh"]
    return params, load_mesh(bytes(part.data), part.filename, params, settings)


def load_mesh(data: bytes, filename: str | None, params: MeshParams, settings: Settings) -> Mesh:
    """The mesh in ``data`` (its format from ``params.format`` or the file name), read within
    the settings' limits; a problem naming the cause otherwise."""
    try:
        mesh = read_mesh(data, format_of(filename, params.format), settings.limits)
    except MeshFormatError as error:
        raise from_mesh_error(error) from None
    observe_mesh(mesh.format, len(mesh.vertices), len(mesh.faces))
    return mesh


def mesh_params(model: type[MeshParams], text: bytes) -> MeshParams:
    """The ``params`` JSON validated as ``model`` (a 422 naming the field otherwise)."""
    return parse_json(model, text, "application/json", "params")


def _mesh_params(form, model: type[MeshParams]) -> MeshParams:
    data = bytes(form["params"].data) if "params" in form else b"{}"  # no params: defaults
    return mesh_params(model, data)


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


@dataclass(frozen=True)
class _Flattened:
    """A region flattened for a mesh request: its file face ids, the chart and frame used,
    the result, and the fit's ``explain`` block (for /v1/fit)."""

    faces: np.ndarray
    chart: Chart
    frame: Frame
    flat: FlatRegion
    explain: dict | None

    def payload_params(self) -> dict:
        return {**resolved(self.chart, self.frame), "layout": self.flat.layout.value}


def _flattened(mesh: Mesh, params: MeshParams, settings: Settings) -> _Flattened:
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
    return _Flattened(faces, chart, frame, flat, explain)


def _validation_summary(region: _Flattened) -> dict:
    """The validation block with file face ids."""
    v, faces = region.flat.validation, region.faces
    return {
        "seam_free": v.seam_free,
        "star_shaped": v.star_shaped,
        "singular_point_faces": faces[v.singular_point_faces],
        "seam_faces": faces[v.seam_faces],
        "folded_faces": faces[v.folded_faces],
        "backfacing_faces": faces[v.backfacing_faces],
        "degenerate_faces": faces[v.degenerate_faces],
        "margin_deg": {
            "seam": v.margin_deg_seam,
            "north": v.margin_deg_north,
            "south": v.margin_deg_south,
        },
        "boundary_loops": v.boundary_loops,
        "winding": "outward" if v.winding == 1 else "inward",
    }


def _metrics(region: _Flattened) -> dict:
    d = region.flat.distortion
    return {
        name: {"mean": s.mean, "p95": s.p95, "max": s.max}
        for name, s in (("conformal", d.conformal), ("area", d.area), ("isometric", d.isometric))
    }


def _payload(region: _Flattened, mesh: Mesh, full: bool) -> dict:
    """The JSON answer: params, validation, metrics (and explain for /v1/fit); with
    ``full``, the vertices' coordinates and the region's faces too."""
    flat = region.flat
    payload = {
        "params": region.payload_params(),
        "validation": _validation_summary(region),
        "metrics": _metrics(region),
    }
    if region.explain is not None:
        payload["explain"] = region.explain
    if full:
        payload["vertices"] = {
            "ids": flat.vertex_ids,
            "theta": flat.theta,
            "phi": flat.phi,
            "r": flat.r,
        }
        if flat.layout is not Layout.THETA_PHI:
            payload["vertices"] |= {"x": flat.x, "y": flat.y}
        payload["faces"] = {"ids": region.faces, "vertices": mesh.faces[region.faces]}
    return payload


#: Vertex ids travel in the GLB as float32 (glTF allows no 32-bit integer attributes).
_FLOAT32_EXACT = 2**24


def _glb(region: _Flattened, mesh: Mesh) -> bytes:
    """The region as a GLB (:mod:`.outputs.glb`)."""
    flat = region.flat
    largest = int(flat.vertex_ids[-1])
    if largest >= _FLOAT32_EXACT:
        raise Problem(
            422,
            f"params.output: a GLB carries vertex ids as float32, exact below "
            f"{_FLOAT32_EXACT:,}; this region uses vertex {largest:,}. Ask for JSON instead.",
            "invalid-request",
            "params.output",
            [largest],
        )
    s_sign = 1.0 if flat.layout is Layout.THETA_PHI else -1.0  # s grows with theta
    uv, affine = layout_uv(flat.x, s_sign * flat.y)
    validation = _validation_summary(region)
    summary = {
        key: value if not isinstance(value, np.ndarray) else len(value)
        for key, value in validation.items()
    }
    extras = {
        "params": region.payload_params(),
        "validation": summary,
        "metrics": _metrics(region),
        "uv": affine | {"s_sign": s_sign, "layout": flat.layout.value},
    }
    return region_glb(
        mesh.vertices[flat.vertex_ids], uv, flat.vertex_ids, flat.faces, region.faces, extras
    )


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
