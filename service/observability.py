"""Metrics, request ids and JSON logs.

Prometheus metrics live in this module, one set per process. With several worker processes
(``meshflat serve`` with MESHFLAT_WORKERS > 1) each writes its values into the directory named
by ``PROMETHEUS_MULTIPROC_DIR`` (numbers only, never a request's content) and ``/metrics``
sums them, so any worker answers for all.

Every request gets an id: the caller's ``X-Request-ID`` when it is a plain token of at most
128 characters, a new one otherwise; it is returned in ``X-Request-ID`` and carried by every
log line written while the request is handled. Log lines are JSON objects; none quotes a
request body, a file name or an exception message (which could quote a mesh).
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import re
import time
import uuid
import warnings
from contextvars import ContextVar
from datetime import UTC, datetime
from pathlib import Path

from prometheus_client import (
    CONTENT_TYPE_LATEST,
    REGISTRY,
    CollectorRegistry,
    Counter,
    Gauge,
    Histogram,
    generate_latest,
)
from prometheus_client import multiprocess as prometheus_multiprocess
from starlette.responses import Response
from starlette.routing import BaseRoute, Match
from starlette.types import ASGIApp, Message, Receive, Scope, Send

logger = logging.getLogger("meshflat")

REQUESTS = Counter(
    "meshflat_requests",
    "Requests answered, by route, method and status.",
    ["route", "method", "status"],
)
LATENCY = Histogram(
    "meshflat_request_duration_seconds",
    "Time from a request's arrival to the end of its answer, by route, method and status.",
    ["route", "method", "status"],
    buckets=(0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1, 2.5, 5, 10, 30, 60, 120),
)
_SIZE_BUCKETS = (100, 1e3, 1e4, 3e4, 1e5, 3e5, 1e6, 3e6, 1e7)
MESH_VERTICES = Histogram(
    "meshflat_mesh_vertices",
    "Vertices of the meshes read, by format.",
    ["format"],
    buckets=_SIZE_BUCKETS,
)
MESH_FACES = Histogram(
    "meshflat_mesh_faces",
    "Triangles of the meshes read, by format.",
    ["format"],
    buckets=_SIZE_BUCKETS,
)
JOBS_IN_FLIGHT = Gauge(
    "meshflat_jobs_in_flight",
    "Jobs admitted and not yet finished: uploading, waiting for a slot or computing.",
    multiprocess_mode="livesum",
)
UPLOADS_IN_PROGRESS = Gauge(
    "meshflat_uploads_in_progress",
    "Requests admitted whose bodies are still arriving.",
    multiprocess_mode="livesum",
)
MEMORY_RESERVED = Gauge(
    "meshflat_memory_reserved_bytes",
    "Bytes of the memory budget held by the jobs in flight (bodies, readers, computations) "
    "and the mesh cache.",
    multiprocess_mode="livesum",
)
MESH_CACHE_BYTES = Gauge(
    "meshflat_mesh_cache_bytes",
    "Bytes the mesh cache holds (meshes sent once and what was computed from them), part of "
    "the memory reserved.",
    multiprocess_mode="livesum",
)
MESH_CACHE_STEPS = Counter(
    "meshflat_mesh_cache_steps",
    "Steps on a held mesh (a region resolved or flattened, its map, a locate index), by "
    "whether the cache had them (reused) or they were computed and kept (computed).",
    ["result"],
)
JOBS_COMPUTING = Gauge(
    "meshflat_jobs_computing", "Jobs computing in a slot.", multiprocess_mode="livesum"
)
COMPUTE_SECONDS = Counter(
    "meshflat_compute_seconds",
    "Seconds the compute slots have been busy, summed over the slots: its rate over "
    "MESHFLAT_MAX_JOBS x workers is how full they are.",
)
REJECTIONS = Counter(
    "meshflat_rejections",
    "Requests refused with a problem answer, by reason (the problem type's last part).",
    ["reason"],
)

#: The id of the request being handled (the log filter and the problem answers read it).
request_id: ContextVar[str] = ContextVar("request_id", default="-")
#: Methods counted by name; any other token a client sends is "other" (a bounded label set).
_METHODS = frozenset({"GET", "HEAD", "POST", "PUT", "DELETE", "PATCH", "OPTIONS"})
_PLAIN_ID = re.compile(rb"[A-Za-z0-9._:\-]{1,128}")


def observe_mesh(mesh_format: str, vertices: int, faces: int) -> None:
    MESH_VERTICES.labels(mesh_format).observe(vertices)
    MESH_FACES.labels(mesh_format).observe(faces)


def metrics_response() -> Response:
    """The Prometheus text exposition of this process, or of all workers' processes."""
    if multiprocess_dir() is None:
        return Response(generate_latest(REGISTRY), media_type=CONTENT_TYPE_LATEST)
    forget_dead_workers()  # whenever a worker died, and whichever worker is asked
    registry = CollectorRegistry()
    prometheus_multiprocess.MultiProcessCollector(registry)
    return Response(generate_latest(registry), media_type=CONTENT_TYPE_LATEST)


def multiprocess_dir() -> Path | None:
    name = os.environ.get("PROMETHEUS_MULTIPROC_DIR")
    return Path(name) if name else None


def forget_dead_workers() -> None:
    """Drop the live gauges of worker processes that no longer run (a worker killed
    mid-request would otherwise count its jobs in flight for ever)."""
    directory = multiprocess_dir()
    if directory is None:
        return
    for path in directory.glob("gauge_live*_*.db"):
        pid = int(path.stem.rpartition("_")[2])
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            # Two restarted workers may clean up the same files at once.
            with contextlib.suppress(FileNotFoundError):
                prometheus_multiprocess.mark_process_dead(pid, str(directory))
        except PermissionError:
            pass  # alive, someone else's


class RequestContext:
    """ASGI middleware (the outermost): the request id, one access log line and the request
    metrics for every HTTP request, whatever answered it."""

    def __init__(self, app: ASGIApp, routes: list[BaseRoute]) -> None:
        self.app, self.routes = app, routes

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        started = time.perf_counter()
        given = dict(scope["headers"]).get(b"x-request-id", b"")
        rid = given.decode() if _PLAIN_ID.fullmatch(given) else uuid.uuid4().hex
        token = request_id.set(rid)
        status = 500

        async def tagged(message: Message) -> None:
            nonlocal status
            if message["type"] == "http.response.start":
                status = message["status"]
                message.setdefault("headers", [])
                message["headers"] = [
                    *message["headers"],
                    (b"x-request-id", rid.encode()),
                ]
            await send(message)

        try:
            await self.app(scope, receive, tagged)
        finally:
            seconds = time.perf_counter() - started
            route = self._route_of(scope)
            method = scope["method"] if scope["method"] in _METHODS else "other"
            labels = (route, method, str(status))
            REQUESTS.labels(*labels).inc()
            LATENCY.labels(*labels).observe(seconds)
            extra = {
                "method": method,
                "route": route,
                "status": status,
                "duration_ms": round(seconds * 1e3, 1),
            }
            charged = scope.get("state", {}).get("charged_bytes")
            if charged is not None:  # a mesh or JSON job's charge to the memory budget
                extra["charged_bytes"] = charged
            logger.info("request", extra=extra)
            request_id.reset(token)

    def _route_of(self, scope: Scope) -> str:
        """The route's template, never the raw path (a label per route, not per URL typed),
        also for requests refused before routing (401, 413)."""
        route = scope.get("route")
        if route is None:
            route = next((r for r in self.routes if r.matches(scope)[0] == Match.FULL), None)
        return getattr(route, "path", None) or "unmatched"


# -- logs ---------------------------------------------------------------------------------


class JsonFormatter(logging.Formatter):
    """One JSON object per line: time, level, logger, message, request id and the record's
    ``extra`` fields. Exception texts are left out (they could quote a request)."""

    _STANDARD = frozenset(vars(logging.LogRecord("", 0, "", 0, "", None, None))) | {
        "message",
        "asctime",
        "color_message",
    }

    def format(self, record: logging.LogRecord) -> str:
        entry = {
            "time": datetime.fromtimestamp(record.created, UTC).isoformat(timespec="milliseconds"),
            "level": record.levelname.lower(),
            "logger": record.name,
            "message": record.getMessage(),
            "request_id": request_id.get(),
        }
        for key, value in vars(record).items():
            if key not in self._STANDARD:
                entry[key] = value
        if record.exc_info:
            entry["error"] = record.exc_info[0].__name__ if record.exc_info[0] else "unknown"
        return json.dumps(entry, default=str)


def log_config() -> dict:
    """``logging.config.dictConfig`` for the service, uvicorn, Python's warnings and every
    other library: JSON lines on stderr; the service writes its own access line (with the
    route, not the URL), so uvicorn's is off."""
    handler = {"class": "logging.StreamHandler", "formatter": "json", "stream": "ext://sys.stderr"}
    return {
        "version": 1,
        "disable_existing_loggers": False,
        "formatters": {"json": {"()": JsonFormatter}},
        "handlers": {"stderr": handler},
        "loggers": {
            "meshflat": {"handlers": ["stderr"], "level": "INFO", "propagate": False},
            "uvicorn": {"handlers": ["stderr"], "level": "INFO", "propagate": False},
            "uvicorn.error": {"level": "INFO"},
            "uvicorn.access": {"handlers": [], "level": "WARNING", "propagate": False},
            # Python warnings (numpy's, a library's) as log records: JSON like the rest.
            "py.warnings": {"handlers": ["stderr"], "level": "WARNING", "propagate": False},
        },
        # Any other library's log records, which would otherwise reach stderr as plain text.
        "root": {"handlers": ["stderr"], "level": "WARNING"},
    }


_shown_before: list = []  # warnings.showwarning as it was before capture_warnings


def capture_warnings(on: bool = True) -> None:
    """Route ``warnings.warn`` through logging (the ``py.warnings`` logger of
    :func:`log_config`) so that no line of the log is plain text; ``on=False`` undoes it."""
    if on and warnings.showwarning is not log_warning:
        _shown_before[:] = [warnings.showwarning]
        warnings.showwarning = log_warning
    elif not on and warnings.showwarning is log_warning and _shown_before:
        warnings.showwarning = _shown_before.pop()


def log_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """A warning as a log record with its category and the place that raised it, but not its
    text, which may quote a value of the request (numpy's overflow does not; a library's
    warning about a file's field could)."""
    logging.getLogger("py.warnings").warning(
        "python warning",
        extra={"category": category.__name__, "where": f"{Path(filename).name}:{lineno}"},
    )
