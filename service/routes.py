"""The HTTP edge: health, the samples, and the routes of :mod:`service.capabilities`
registered from their rows. A handler admits the job, reads the body, and runs the
capability off the event loop (:func:`service.server.admission.run_job`): the body becomes
the use-case's input (:mod:`service.forms`), the use-case runs with the job's context, and
its result is answered in the form asked for.
"""

from __future__ import annotations

from functools import partial
from typing import Annotated

from fastapi import APIRouter, Path, Request
from starlette.concurrency import run_in_threadpool
from starlette.responses import Response

from . import document, heldmeshes
from .capabilities import (
    JSON_CAPABILITIES,
    MESH_CAPABILITIES,
    Capability,
    JsonCapability,
    MeshCapability,
)
from .capabilities.context import Context
from .encoding import JSON
from .errors import JSON_BODY
from .forms import choose_output, mesh_form, parse_json
from .meshio import READERS, format_of
from .observability import metrics_response
from .outputs import Output
from .problems import MESH_NOT_HELD, PROBLEMS, Problem, core_errors_as_problems
from .samples import SAMPLES, SampleInfo, sample_infos
from .selfcheck import Health
from .server.admission import Job, run_job
from .timings import Timings

router = APIRouter()


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


@router.get(
    "/v1/samples",
    tags=["samples"],
    summary="The bundled sample meshes",
    responses={401: PROBLEMS[401]},
)
async def samples() -> list[SampleInfo]:
    """Real scans bundled with the service, with their face counts and credits."""
    return await run_in_threadpool(sample_infos)


def _media_type(name: str) -> str:
    return READERS[format_of(name, None)].media_type


_MEDIA_TYPES = {reader.media_type: {} for reader in READERS.values()}


@router.get(
    "/v1/samples/{name}",
    tags=["samples"],
    summary="Download a sample mesh",
    response_class=Response,
    responses={
        200: {
            "content": _MEDIA_TYPES,
            "description": "The file.",
        },
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
        media_type=_media_type(name),
        headers={"Content-Disposition": f'attachment; filename="{name}"'},
    )


# -- the capabilities ----------------------------------------------------------------------


def answer_json(capability: JsonCapability, body: bytes, content_type: str, job: Job) -> Response:
    """A JSON route's answer to its body (CPU-bound: run it off the event loop)."""
    timings = Timings(job.deadline)
    with core_errors_as_problems(JSON_BODY):
        with timings.measure("parse"):
            request = parse_json(capability.request, body, content_type)
        data = capability.answer(request, Context(job.settings, job.ticket), timings)
    return Response(data, media_type=JSON, headers={"Server-Timing": timings.header()})


def answer_mesh(
    capability: MeshCapability,
    body: bytes,
    content_type: str,
    job: Job,
    accept: str | None = None,
) -> Response:
    """A mesh route's answer to a multipart body, in the form ``Accept`` or
    ``params.output`` asks for (CPU-bound: run it off the event loop)."""
    timings = Timings(job.deadline)
    ctx = Context(job.settings, job.ticket, meshes=job.meshes)
    with core_errors_as_problems(capability.places):
        with timings.measure("parse"):
            given = mesh_form(body, content_type, capability, ctx)
            # Every mesh route has several forms (JSON and Arrow at least).
            requested = getattr(given.params, "output", None)
            output = choose_output(accept, requested, capability.outputs)
        data = capability.answer(given, ctx, output, timings)
    headers = {"Server-Timing": timings.header(), "Vary": "Accept"}
    if output is not Output.JSON:
        headers["Content-Disposition"] = f'inline; filename="region{output.suffix}"'
    return Response(data, media_type=output.media_type, headers=headers)


def _post(capability: Capability, work_of, **documentation) -> None:
    """Register ``capability``'s route: its handler runs ``work_of(request)`` as a job."""

    async def endpoint(request: Request) -> Response:
        return await run_job(request, work_of(request), capability.parse_bytes_per_byte)

    router.add_api_route(
        capability.path,
        endpoint,
        methods=["POST"],
        name=capability.name,
        summary=capability.summary,
        response_model=capability.response,
        **documentation,
    )


def _json_route(capability: JsonCapability) -> None:
    _post(
        capability,
        lambda _: partial(answer_json, capability),
        tags=["transforms"],
        description=capability.description,
        responses=PROBLEMS,
        openapi_extra=document.json_body(capability.request),
    )


def _mesh_route(capability: MeshCapability) -> None:
    _post(
        capability,
        lambda request: partial(answer_mesh, capability, accept=request.headers.get("accept")),
        tags=["meshes"],
        description=document.mesh_description(capability),
        responses=PROBLEMS | {404: MESH_NOT_HELD} | document.other_forms(capability),
        openapi_extra=document.multipart_body(capability),
    )


for _capability in JSON_CAPABILITIES:
    _json_route(_capability)
for _capability in MESH_CAPABILITIES:
    _mesh_route(_capability)


# -- meshes sent once ----------------------------------------------------------------------


@router.post(
    heldmeshes.PATH,
    tags=["meshes"],
    summary="Send a mesh once; name it by its SHA-256 in later requests",
    status_code=201,
    response_model=heldmeshes.HeldMesh,
    responses={
        200: {"model": heldmeshes.HeldMesh, "description": "The worker held it already."},
        201: {"description": "Kept."},
        **{status: PROBLEMS[status] for status in (400, 401, 408, 413, 415, 422, 503, 504)},
    },
    openapi_extra=heldmeshes.request_body(),
)
async def hold_mesh(request: Request) -> Response:
    """Multipart: the `mesh` part (and `params` with its `format`, if the file name does not
    tell). The worker reads it and keeps it in memory (never on disk) and answers the
    SHA-256 of the part's bytes, which every mesh route takes as `params.mesh_sha256`
    instead of its mesh part; the region, map and locate index that requests compute from
    it are kept with it for the same params. A cache, not a store: the worker lets go of
    the least recently used within MESHFLAT_MESH_CACHE_BYTES and whenever its jobs need the
    memory, and each worker and replica has its own: a route answers 404 for a digest the
    worker does not hold, and the client sends the mesh again. A mesh held already is not
    read again (200)."""
    work = partial(heldmeshes.hold_mesh, request.app.state.mesh_cache)
    return await run_job(request, work, heldmeshes.PARSE_BYTES_PER_BYTE)
