"""The ASGI app, ``service.app:app``, built from environment settings by :func:`create_app`."""

from __future__ import annotations

import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from importlib.metadata import version

from fastapi import FastAPI
from fastapi.middleware.cors import CORSMiddleware
from fastapi.openapi.utils import get_openapi
from pydantic.json_schema import models_json_schema
from starlette.concurrency import run_in_threadpool

from . import demo, problems
from .allocator import keep_large_blocks
from .api import router
from .auth import PROTECTED_PREFIX, KeyCheck, RequireApiKey
from .bodylimit import BodySizeLimit
from .examples import add_examples
from .observability import JsonFormatter, RequestContext
from .params import (
    FitParams,
    FlattenParams,
    InverseRequest,
    LocateParams,
    MeshParams,
    PointsRequest,
)
from .problems import ProblemDetails
from .selfcheck import run_self_check
from .settings import Settings

logger = logging.getLogger("meshflat")
if not logger.handlers:  # imported without `meshflat serve`'s logging set-up
    _handler = logging.StreamHandler()
    _handler.setFormatter(JsonFormatter())
    logger.addHandler(_handler)
    logger.setLevel(logging.INFO)
    logger.propagate = False

DESCRIPTION = """
meshflat flattens a region of a 3D mesh into distorted-pole spherical coordinates: the poles
and the seam of ordinary spherical coordinates are moved by a Moebius "pole warp" into a cap
of angle `rho = 2 atan(sigma)` around the local +Y axis, so a region outside that cap maps to
one seam-free patch.

Angles follow eq. 1 of the paper throughout: `theta` is the polar angle from local +Z in
[0, pi], `phi` the azimuth from +X towards +Y in (-pi, pi], in the local frame
`q = R (p - c)`. The paper's "alternative approach" section swaps these two names; meshflat
does not. The paper's printed eq. 2 is not the inverse of eq. 1; meshflat uses the true one.

Every error is `application/problem+json` (RFC 9457) whose `detail` names the field, the face
or vertex, and the limit.
"""


def create_app(settings: Settings | None = None) -> FastAPI:
    """The service with ``settings`` (default: from ``MESHFLAT_*`` environment variables)."""
    settings = settings or Settings.from_env()

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        """Tune the allocator, then flatten a bundled scan once, off the event loop, and log
        the outcome; /readyz answers 200 after it passes."""
        if not keep_large_blocks():
            logger.info("allocator: not glibc, default settings kept")
        if not settings.api_keys:
            logger.warning(
                "no API keys are configured (MESHFLAT_API_KEYS, MESHFLAT_API_KEYS_FILE): "
                "every /v1 route is open to anyone who can reach the service"
            )
        check = await run_in_threadpool(run_self_check)
        (logger.info if check.ok else logger.error)(str(check))
        app.state.ready = check.ok
        yield

    app = FastAPI(
        lifespan=lifespan,
        title="meshflat",
        version=version("meshflat"),
        summary="Flattens a region of a 3D mesh into seam-free distorted-pole spherical "
        "coordinates.",
        description=DESCRIPTION,
    )
    app.state.settings = settings
    app.state.ready = False
    app.openapi = lambda: _openapi(app)
    problems.install(app)
    app.include_router(router)
    app.include_router(demo.router)
    app.mount("/static", demo.static_files(), name="static")
    # Outermost last: every answer, refusals and 500s included, gets a request id, a log line,
    # metrics and the CORS headers (so that a browser can read it).
    app.add_middleware(BodySizeLimit, limit=settings.max_upload_bytes)
    app.add_middleware(RequireApiKey, check=KeyCheck(settings.api_keys))
    app.add_middleware(problems.UnexpectedErrors)
    app.add_middleware(
        CORSMiddleware,
        allow_origins=list(settings.cors_origins),
        allow_methods=["GET", "POST"],
        allow_headers=["Authorization", "X-API-Key", "Content-Type", "Accept", "X-Request-ID"],
        expose_headers=["X-Request-ID", "Retry-After", "Server-Timing", "Content-Disposition"],
        max_age=600,
    )
    # Routes for the metrics' labels: FastAPI's own (documents, /static) and the routers'.
    own = [route for route in app.router.routes if hasattr(route, "path")]
    app.add_middleware(RequestContext, routes=[*own, *router.routes, *demo.router.routes])
    return app


def _openapi(app: FastAPI) -> dict:
    """FastAPI's document plus the MeshParams schema, which the multipart bodies refer to,
    and answers computed for the request examples."""
    if app.openapi_schema is None:
        document = get_openapi(
            title=app.title,
            version=app.version,
            summary=app.summary,
            description=app.description,
            routes=app.routes,
        )
        _, definitions = models_json_schema(
            [
                (MeshParams, "validation"),
                (FlattenParams, "validation"),
                (FitParams, "validation"),
                (LocateParams, "validation"),
                (PointsRequest, "validation"),
                (InverseRequest, "validation"),
                (ProblemDetails, "serialization"),
            ],
            ref_template="#/components/schemas/{model}",
        )
        document.setdefault("components", {}).setdefault("schemas", {}).update(
            definitions.get("$defs", {})
        )
        app.openapi_schema = add_examples(_declare_keys(document))
    return app.openapi_schema


def _declare_keys(document: dict) -> dict:
    """The two ways to send an API key, required by every ``/v1`` operation (they are
    checked only when the service has keys: service.auth)."""
    document["components"]["securitySchemes"] = {
        "bearer": {"type": "http", "scheme": "bearer", "description": "An API key."},
        "apiKey": {"type": "apiKey", "in": "header", "name": "X-API-Key"},
    }
    for path, operations in document["paths"].items():
        if path.startswith(PROTECTED_PREFIX):
            for operation in operations.values():
                operation["security"] = [{"bearer": []}, {"apiKey": []}]
    return document


app = create_app()
