"""The ASGI app, ``service.app:app``, built from environment settings by :func:`create_app`."""

from __future__ import annotations

import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from importlib.metadata import version

from fastapi import FastAPI
from fastapi.openapi.utils import get_openapi
from pydantic.json_schema import models_json_schema
from starlette.concurrency import run_in_threadpool

from . import demo, problems
from .allocator import keep_large_blocks
from .api import router
from .bodylimit import BodySizeLimit
from .examples import add_examples
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
if not logger.handlers:
    _handler = logging.StreamHandler()
    _handler.setFormatter(logging.Formatter("%(levelname)s:     %(message)s"))
    logger.addHandler(_handler)
    logger.setLevel(logging.INFO)

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
    app.add_middleware(BodySizeLimit, limit=settings.max_upload_bytes)
    app.add_middleware(problems.UnexpectedErrors)
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
        app.openapi_schema = add_examples(document)
    return app.openapi_schema


app = create_app()
