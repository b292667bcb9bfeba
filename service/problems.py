"""Errors as RFC 9457 problem details (``application/problem+json``).

Every 4xx and 5xx the service sends has ``type``, ``title``, ``status`` and a ``detail`` that
names the field, the face or vertex, and the limit; ``field`` and ``indices`` repeat the
first two for programs.
"""

from __future__ import annotations

import logging
import re
from collections.abc import Iterator
from contextlib import contextmanager
from http import HTTPStatus

import orjson
from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from pydantic import BaseModel, Field, ValidationError
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.responses import Response
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from transforms import EmptyRegionError, TransformInputError

from .errors import JSON_BODY, ErrorPlaces, InvalidInput, OverLimit, UnknownMesh, UnreadableMesh
from .meshio import MeshFormatError, MeshTooLargeError
from .observability import REJECTIONS

PROBLEM_JSON = "application/problem+json"
logger = logging.getLogger("meshflat")


class ProblemDetails(BaseModel):
    """RFC 9457 problem details."""

    type: str = Field(description="A URI naming the kind of problem.")
    title: str = Field(description="Short summary of the kind of problem.")
    status: int = Field(description="The HTTP status code.")
    detail: str = Field(description="What is wrong here: the field, face or vertex, the limit.")
    field: str | None = Field(None, description="The parameter or part at fault, if one is.")
    indices: list[int] | None = Field(
        None, description="The first offending vertex, face or point ids, if any."
    )


class Problem(Exception):
    """An error answered as a problem: raise it anywhere a request is handled."""

    def __init__(
        self,
        status: int,
        detail: str,
        kind: str = "invalid-request",
        field: str | None = None,
        indices: list[int] | tuple[int, ...] | None = None,
        headers: dict[str, str] | None = None,
    ) -> None:
        super().__init__(detail)
        self.status, self.detail, self.kind = status, detail, kind
        self.field = field
        self.indices = list(indices) if indices else None
        self.headers = headers


#: The problems every route may answer, for the OpenAPI document.
PROBLEMS = {
    status: {
        # Problems are only ever application/problem+json (the schema is added to the
        # document's components by service.document).
        "content": {
            "application/problem+json": {"schema": {"$ref": "#/components/schemas/ProblemDetails"}}
        },
        "description": text,
    }
    for status, text in (
        (400, "Malformed request (for example a broken multipart body)."),
        (413, "Body, file or mesh beyond a limit; the detail names the limit."),
        (401, "No valid API key (when the service has keys): the detail says which."),
        (
            408,
            "The body did not arrive within the time limit (MESHFLAT_REQUEST_TIMEOUT) or at "
            "the least rate (MESHFLAT_MIN_UPLOAD_RATE).",
        ),
        (415, "Wrong content type."),
        (
            422,
            "Invalid parameters or an unreadable mesh; the detail names the field, face or vertex.",
        ),
        (
            503,
            "Busy: too many jobs or uploads in flight, or the memory budget taken; "
            "Retry-After gives the seconds to wait.",
        ),
        (504, "The job did not finish within the time limit (MESHFLAT_REQUEST_TIMEOUT)."),
    )
}
#: The problem of a mesh route whose params.mesh_sha256 names a mesh not held.
MESH_NOT_HELD = PROBLEMS[422] | {
    "description": "params.mesh_sha256 names a mesh this worker does not hold (never sent to "
    "it, or let go since): POST it to /v1/meshes again."
}
PROBLEMS[503]["headers"] = {
    "Retry-After": {"description": "Seconds to wait.", "schema": {"type": "integer"}}
}


def problem_body(problem: Problem) -> bytes:
    """The problem's JSON document."""
    body = {
        "type": f"urn:meshflat:problem:{problem.kind}",
        "title": HTTPStatus(problem.status).phrase,
        "status": problem.status,
        "detail": problem.detail,
    }
    if problem.field:
        body["field"] = problem.field
    if problem.indices:
        body["indices"] = problem.indices
    return orjson.dumps(body)


def problem_response(problem: Problem) -> Response:
    REJECTIONS.labels(problem.kind).inc()
    return Response(
        problem_body(problem),
        status_code=problem.status,
        media_type=PROBLEM_JSON,
        headers=problem.headers,
    )


#: The kind of problem by core error type (the first that matches); others: invalid-input.
_KINDS = ((EmptyRegionError, "empty-region"),)


#: What :func:`problem_of` translates: every error a use-case, a reader or a params model
#: raises for bad input.
INPUT_ERRORS = (
    TransformInputError,
    InvalidInput,
    OverLimit,
    UnknownMesh,
    UnreadableMesh,
    MeshFormatError,
    ValidationError,
)


def problem_of(error: Exception, places: ErrorPlaces = JSON_BODY) -> Problem:
    """The problem that a core input error, a use-case's refusal (:mod:`service.errors`), a
    mesh reader's error or a parameter model's validation error is, its field placed by
    ``places``; the one translation of them.

    Raises
    ------
    TypeError
        ``error`` is none of those (a bug: let it become a 500).
    """
    if isinstance(error, InvalidInput):
        where, label = places.named(error.field), places.named(error.item)
        if error.name is not None:
            label = f"{label} ({error.name!r})"
        detail = f"{label}{error.about}: {error.message}"
        return Problem(422, detail, "invalid-request", where, error.indices)
    if isinstance(error, OverLimit):
        where = places.named(error.field)
        return Problem(413, f"{where}: {error.message}", "too-many-points", where)
    if isinstance(error, UnknownMesh):
        where = places.named(error.field)
        return Problem(
            404,
            f"{where}: this worker holds no mesh of SHA-256 {error.digest} (it was never sent "
            "here, or the cache has let go of it): POST the mesh to /v1/meshes again, or send "
            "it in the request's mesh part",
            "mesh-not-held",
            where,
        )
    if isinstance(error, UnreadableMesh):
        return _unreadable(error.error, error.part)
    if isinstance(error, MeshFormatError):
        return _unreadable(error, places.data or "mesh")
    if isinstance(error, ValidationError):
        return validation_problem(error.errors(), places.prefix)
    if isinstance(error, TransformInputError):
        where = places.of(error.field)
        kind = next((k for t, k in _KINDS if isinstance(error, t)), "invalid-input")
        return Problem(422, f"{where}: {error.message}", kind, where, list(error.indices))
    raise TypeError(f"no problem for {type(error).__name__}")


def _unreadable(error: MeshFormatError, part: str) -> Problem:
    if isinstance(error, MeshTooLargeError):
        return Problem(413, f"{part}: {error}", "mesh-too-large", part)
    return Problem(422, f"{part}: {error}", "unreadable-mesh", part)


@contextmanager
def core_errors_as_problems(places: ErrorPlaces) -> Iterator[None]:
    """Raise what :func:`problem_of` makes of any error of :data:`INPUT_ERRORS`."""
    try:
        yield
    except INPUT_ERRORS as error:
        raise problem_of(error, places) from None


#: How pydantic labels a union's member in an error's location.
_UNION_MEMBER = re.compile(r"[\w-]+\[.*\]|str|int|float|bool|constrained-[\w-]+")


def _member_label(location: tuple) -> int | None:
    """Where in an error's location pydantic names the union member it tried, if it does."""
    for at, part in enumerate(location):
        if isinstance(part, str) and _UNION_MEMBER.fullmatch(part):
            return at
    return None


def _without_members_not_taken(errors: list[dict]) -> list[dict]:
    """pydantic reports every member of a union that failed. When one of them took the
    input (the error lies inside it, or is not a wrong type), the others' "should be a valid
    string" and the like only say which type the input is not: leave them out."""
    wrong_types, taken = [], set()  # per error: its union's field if a wrong-type one
    for item in errors:
        location = tuple(item.get("loc", ()))
        at = _member_label(location)
        wrong_type = at is not None and len(location) == at + 1 and item["type"].endswith("_type")
        wrong_types.append(location[:at] if wrong_type else None)
        if at is not None and not wrong_type:
            taken.add(location[:at])
    return [item for item, field in zip(errors, wrong_types, strict=True) if field not in taken]


def validation_problem(errors: list[dict], prefix: str = "") -> Problem:
    """A 422 naming up to five invalid fields (pydantic's errors); ``prefix`` places them
    (``params.`` for the multipart JSON field)."""
    messages, first_field = [], None
    errors = _without_members_not_taken(errors)
    for item in errors[:5]:
        # pydantic names the member of a union it tried ("function-after[...]"): not a field.
        parts = [str(part) for part in item.get("loc", ()) if part != "body"]
        parts = [part for part in parts if not _UNION_MEMBER.fullmatch(part)]
        location = (prefix + ".".join(parts)).rstrip(".")
        message = str(item.get("msg", "invalid")).removeprefix("Value error, ")
        first_field = first_field or location or None
        messages.append(f"{location}: {message}" if location else message)
    if len(errors) > 5:
        messages.append(f"and {len(errors) - 5} more")
    return Problem(422, "; ".join(messages), "invalid-request", first_field)


def install(app: FastAPI) -> None:
    """Register the handlers that turn every error into a problem response."""

    @app.exception_handler(Problem)
    async def on_problem(_: Request, exc: Problem) -> Response:
        return problem_response(exc)

    @app.exception_handler(RequestValidationError)
    async def on_validation_error(_: Request, exc: RequestValidationError) -> Response:
        return problem_response(validation_problem(exc.errors()))

    @app.exception_handler(StarletteHTTPException)
    async def on_http_error(_: Request, exc: StarletteHTTPException) -> Response:
        detail = exc.detail if isinstance(exc.detail, str) else HTTPStatus(exc.status_code).phrase
        return problem_response(
            Problem(exc.status_code, detail, "http-error", headers=getattr(exc, "headers", None))
        )


class UnexpectedErrors:
    """ASGI middleware: any exception no handler took becomes a 500 problem, and the log
    gets its type and the route only (never its message or traceback, which could quote an
    uploaded mesh); the exception is not raised further, so the server logs nothing more."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        started = False

        async def watched(message: Message) -> None:
            nonlocal started
            started = started or message["type"] == "http.response.start"
            await send(message)

        try:
            await self.app(scope, receive, watched)
        except Exception as exc:
            # The route's template, not the path, which a client writes (a sample's name).
            route = getattr(scope.get("route"), "path", "an unmatched path")
            logger.error("unexpected %s on %s %s", type(exc).__name__, scope["method"], route)
            if not started:
                problem = Problem(
                    500, "the service failed unexpectedly; the error is logged", "internal-error"
                )
                await problem_response(problem)(scope, receive, send)
