"""Admission of a job's request, between the routes and :mod:`.jobs`: a place taken as soon
as the headers are in (or a 503 at once), the body read at the least rate and charged to the
memory budget as it arrives, and the job run off the event loop in a compute slot, within the
time limit."""

from __future__ import annotations

import gc
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from typing import TYPE_CHECKING

import anyio
import anyio.to_thread
from fastapi import FastAPI, Request
from starlette.requests import ClientDisconnect
from starlette.responses import Response

from ..settings import Settings
from .allocator import release_free_memory
from .jobs import Deadline, JobGate, Ticket, TimeLimit, TooSlow

if TYPE_CHECKING:
    from ..meshcache import MeshCache


@dataclass(frozen=True)
class Job:
    """A served request's computation as its work sees it.

    Attributes
    ----------
    settings : Settings, the service's
    ticket : Ticket, its admission: the memory budget it charges (``charge``, ``charge_mesh``)
    deadline : Deadline, the moment its answer is due (a stage starting after it stops)
    meshes : MeshCache or None, the process's meshes sent once (:mod:`service.meshcache`)
    """

    settings: Settings
    ticket: Ticket
    deadline: Deadline
    meshes: MeshCache | None = None


#: A job's work: ``(body, content_type, job) -> Response``, run in a worker thread.
Work = Callable[[bytearray, str, Job], Response]


def settings_of(request: Request) -> Settings:
    return request.app.state.settings


async def run_job(request: Request, work: Work, parse_bytes_per_byte: int) -> Response:
    """Admit the request as soon as its headers are in (a 503 at once when this process has
    no room, see :mod:`.jobs`), read the body (at the least rate, charged to the memory
    budget), queue the job and run ``work(body, content_type, job)`` off the event loop in a
    compute slot, all within the time limit. Parsing the body is charged
    ``parse_bytes_per_byte`` of the memory budget per byte of it."""
    settings = settings_of(request)
    gate = job_gate(request.app)
    ticket = gate.admit()
    deadline = Deadline.after(settings.request_timeout, gate.clock)
    try:
        try:
            body = await read_body(request, ticket, settings, deadline)
        except ClientDisconnect:
            # Nobody is left to answer; 499 (as nginx says) marks it in the log and metrics.
            return Response(status_code=499)
        ticket.uploaded()
        ticket.charge(parse_bytes_per_byte * len(body))
        content_type = request.headers.get("content-type", "")
        meshes = getattr(request.app.state, "mesh_cache", None)
        job = partial(
            ticket.run, work, deadline, body, content_type, Job(settings, ticket, deadline, meshes)
        )
        try:
            with anyio.fail_after(max(0.0, deadline.remaining())):
                return await anyio.to_thread.run_sync(job, abandon_on_cancel=True)
        except TimeoutError:
            raise TimeLimit(settings.request_timeout, while_reading=False) from None
    finally:
        # A computation that started ends the admission itself, even one that runs on after
        # its client had the 504; this ends it for one that never started.
        ticket.release()
        request.state.charged_bytes = ticket.charged  # for the access log line


async def read_body(
    request: Request, ticket: Ticket, settings: Settings, deadline: Deadline
) -> bytearray:
    """The request's body, each piece charged to ``ticket`` as it arrives.

    Raises
    ------
    TooSlow
        After ``settings.upload_grace`` seconds, less than ``min_upload_rate`` bytes a second
        have arrived (a 408: the connection is not held by a slow or stalled client).
    TimeLimit
        The time limit passed first (408).
    ClientDisconnect
        The client left.
    """
    body = bytearray()
    rate, grace = settings.min_upload_rate, settings.upload_grace
    started = deadline.clock()
    while True:
        # The moment the bytes in so far stop being enough for the least rate.
        due = min(started + grace + len(body) / rate, deadline.at)
        try:
            with anyio.fail_after(max(1e-3, due - deadline.clock())):
                message = await request.receive()
        except TimeoutError:
            if deadline.remaining() <= 0:
                raise TimeLimit(settings.request_timeout, while_reading=True) from None
            raise TooSlow(rate, grace, len(body)) from None
        if message["type"] == "http.disconnect":
            raise ClientDisconnect
        piece = message.get("body", b"")
        if piece:
            ticket.charge(len(piece))
            body += piece
        if not message.get("more_body", False):
            return body


def job_gate(app: FastAPI) -> JobGate:
    """The process's :class:`JobGate` (one per app, a worker process has one app), which
    :func:`service.server.install` made."""
    return app.state.job_gate


def gate_of(settings: Settings) -> JobGate:
    """A job gate with the settings' bounds, whose idle worker gives its memory back."""
    return JobGate(
        settings.max_jobs,
        settings.max_waiting,
        max_uploads=settings.max_uploads,
        memory_budget=settings.memory_budget_bytes,
        on_idle=_shrink,
    )


def _shrink() -> None:
    """An idle worker gives its free heap back (see .allocator), after freeing what
    only reference cycles kept (arrays held by a traceback's frames, say)."""
    gc.collect()
    release_free_memory()
