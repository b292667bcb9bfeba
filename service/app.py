"""The ASGI app, ``service.app:app``, built from environment settings by :func:`create_app`."""

from __future__ import annotations

import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from importlib.metadata import version

from fastapi import FastAPI
from fastapi.middleware.cors import CORSMiddleware
from fastapi_offline import FastAPIOffline
from starlette.concurrency import run_in_threadpool

from . import demo, document, problems, server
from .observability import JsonFormatter, RequestContext, capture_warnings
from .routes import router
from .selfcheck import run_self_check
from .settings import Settings, container_memory

logger = logging.getLogger("meshflat")
if not logger.handlers:  # imported without `meshflat serve`'s logging set-up
    _handler = logging.StreamHandler()
    _handler.setFormatter(JsonFormatter())
    logger.addHandler(_handler)
    logger.setLevel(logging.INFO)
    logger.propagate = False


def create_app(settings: Settings | None = None) -> FastAPI:
    """The service with ``settings`` (default: from ``MESHFLAT_*`` environment variables)."""
    settings = settings or Settings.from_env()

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        """Tune the interpreter and the allocator, then flatten a bundled scan once, off the
        event loop, and log the outcome; /readyz answers 200 after it passes."""
        capture_warnings()
        if not server.tune_process():
            logger.info("allocator: not glibc, default settings kept")
        if not settings.api_keys:
            logger.warning(
                "no API keys are configured (MESHFLAT_API_KEYS, MESHFLAT_API_KEYS_FILE): "
                "every /v1 route is open to anyone who can reach the service"
            )
        logger.info(
            "memory budget: %d MiB for this worker's jobs (%s)",
            settings.memory_budget_bytes // 2**20,
            "MESHFLAT_MEMORY_BUDGET"
            if settings.memory_budget
            else f"from a container limit of {container_memory() // 2**20} MiB",
        )
        check = await run_in_threadpool(run_self_check)
        (logger.info if check.ok else logger.error)(str(check))
        app.state.ready = check.ok
        yield

    # The documentation UI's scripts and styles come from the package (fastapi-offline), not
    # a CDN: a deployment behind a firewall still shows /docs and /redoc.
    app = FastAPIOffline(
        lifespan=lifespan,
        title="meshflat",
        version=version("meshflat"),
        summary="Flattens a region of a 3D mesh into seam-free distorted-pole spherical "
        "coordinates.",
        description=document.DESCRIPTION,
    )
    app.state.settings = settings
    app.state.ready = False
    app.openapi = lambda: document.build(app)
    problems.install(app)
    app.include_router(router)
    app.include_router(demo.router)
    app.mount("/static", demo.static_files(), name="static")
    # Outermost last: every answer, refusals and 500s included, gets a request id, a log line,
    # metrics and the CORS headers (so that a browser can read it).
    server.install(app, settings)
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


app = create_app()
