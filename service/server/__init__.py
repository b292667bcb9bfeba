"""The HTTP protection around the routes, apart from what they compute: admission,
backpressure, memory and time limits of jobs (:mod:`.admission`, :mod:`.jobs`), the request
body's size (:mod:`.bodylimit`), API keys (:mod:`.auth`), the multipart parser
(:mod:`.multipart`), the header timer and lingering close of the HTTP protocol
(:mod:`.protocol`) and the allocator's settings (:mod:`.allocator`).

An app gets it all from :func:`install`; ``meshflat serve`` passes :data:`PROTOCOL` to
uvicorn; a worker calls :func:`tune_process` once at start.
"""

from __future__ import annotations

import sys

from fastapi import FastAPI

from ..meshcache import MeshCache
from ..settings import Settings
from .admission import gate_of
from .allocator import keep_large_blocks
from .auth import KeyCheck, RequireApiKey
from .bodylimit import BodySizeLimit

#: uvicorn's ``http`` protocol class: h11 with a header time limit and a lingering close.
PROTOCOL = "service.server.protocol:Protocol"

#: Seconds a thread holds the interpreter before one waiting for it takes over (5 ms by
#: default). A job's numpy calls let go of it and take it back many times, and each time
#: may wait out the other compute slot's turn; `make soak` runs on 2 CPUs served 8.6 to 8.8
#: jobs/s at capacity at 5 ms, and 8.7 to 11.9 (most above 10) at 1 ms.
SWITCH_INTERVAL = 0.001


def install(app: FastAPI, settings: Settings) -> None:
    """Put the protection in front of ``app``'s routes: its job gate (admission, compute
    slots, the memory budget: :func:`.admission.run_job` runs each job through it) and the
    mesh cache that shares its budget (``app.state.mesh_cache``), and as
    middleware the body-size limit and, with keys configured, the API keys. Call it before
    adding the middleware that must see every answer (errors, CORS, request ids), which then
    wraps these."""
    gate = gate_of(settings)
    app.state.job_gate = gate
    # Meshes sent once, kept within the jobs' budget: a job short of room empties it first.
    app.state.mesh_cache = MeshCache(settings.mesh_cache_capacity, gate.memory)
    gate.memory.reclaim = app.state.mesh_cache.reclaim
    app.add_middleware(BodySizeLimit, limit=settings.max_upload_bytes)
    app.add_middleware(RequireApiKey, check=KeyCheck(settings.api_keys))


def tune_process() -> bool:
    """Tune the interpreter's thread switching and the allocator for jobs on large meshes;
    whether the allocator could be tuned (glibc only)."""
    sys.setswitchinterval(SWITCH_INTERVAL)
    return keep_large_blocks()
