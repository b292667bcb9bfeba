"""The ASGI app, ``service.app:app``."""

from __future__ import annotations

import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from importlib.metadata import version

from fastapi import FastAPI
from pydantic import BaseModel
from starlette.concurrency import run_in_threadpool

from .allocator import keep_large_blocks
from .selfcheck import run_self_check

logger = logging.getLogger("meshflat")
if not logger.handlers:
    _handler = logging.StreamHandler()
    _handler.setFormatter(logging.Formatter("%(levelname)s:     %(message)s"))
    logger.addHandler(_handler)
    logger.setLevel(logging.INFO)


@asynccontextmanager
async def lifespan(_: FastAPI) -> AsyncIterator[None]:
    """Tune the allocator, then flatten a bundled scan once, off the event loop, and log the
    outcome."""
    if not keep_large_blocks():
        logger.info("allocator: not glibc, default settings kept")
    check = await run_in_threadpool(run_self_check)
    (logger.info if check.ok else logger.error)(str(check))
    yield


app = FastAPI(
    lifespan=lifespan,
    title="meshflat",
    version=version("meshflat"),
    summary="Flattens a region of a 3D mesh into seam-free distorted-pole spherical coordinates.",
    description=(
        "Angles follow eq. 1 of the paper throughout: `theta` is the polar angle from local "
        "+Z in [0, pi], `phi` the azimuth from +X towards +Y in (-pi, pi]. The paper's "
        "'alternative approach' section swaps these two names; meshflat does not."
    ),
)


class Health(BaseModel):
    """The service is up."""

    status: str = "ok"


@app.get("/healthz", tags=["health"], summary="Liveness")
def healthz() -> Health:
    """Answers while the process serves requests."""
    return Health()
