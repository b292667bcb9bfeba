"""A request's body into a use-case's input: a JSON body into its model, or a multipart form
(a ``params`` JSON field and the route's file parts) into the route's typed input
(:meth:`service.capabilities.MeshCapability.input_of`); and the answer's form from
``Accept``. The HTTP side of the routes; the command line builds the same inputs from files.

Errors are the models', readers' and use-cases' own, which
:func:`service.problems.core_errors_as_problems` places; the content type, the form's shape
and content negotiation are HTTP matters, answered here as problems.
"""

from __future__ import annotations

from typing import TypeVar

from pydantic import BaseModel

from .capabilities import MeshCapability
from .capabilities.context import JSON_BYTES_PER_BYTE, Context
from .capabilities.inputs import Upload, parse_params
from .outputs import Output
from .problems import Problem
from .server.multipart import parse_form

#: The largest ``params`` field of a mesh form: parameters are a few hundred bytes, a region
#: of listed face ids a few MB.
MAX_PARAMS_BYTES = 32 * 2**20

M = TypeVar("M", bound=BaseModel)


def parse_json(model: type[M], body: bytes, content_type: str) -> M:
    """``body`` validated as ``model`` (a 415 unless the content type is JSON).

    Raises
    ------
    pydantic.ValidationError
        The body is not JSON or not valid as ``model``.
    """
    media_type = content_type.partition(";")[0].strip()
    if media_type.lower() != "application/json":
        raise Problem(
            415,
            f"send application/json, not {media_type or 'an untyped body'}",
            "unsupported-media-type",
        )
    return parse_params(model, body)


def mesh_form(body: bytes | bytearray, content_type: str, capability: MeshCapability, ctx: Context):
    """The typed input of a multipart mesh request: its params (default ``{}``) and the
    route's parts, each mesh read in place from a view into ``body`` (no copy of the
    upload)."""
    form = parse_form(body, content_type)
    text = form["params"].data if "params" in form else b"{}"
    if len(text) > MAX_PARAMS_BYTES:
        raise Problem(
            413,
            f"params: the field has {len(text):,} bytes; the limit is {MAX_PARAMS_BYTES:,}",
            "body-too-large",
            "params",
        )
    ctx.charge(JSON_BYTES_PER_BYTE * len(text))  # its parse, beyond the reader's allowance
    params = parse_params(capability.params, bytes(text))
    files = {
        name: Upload(part.filename, part.data) for name, part in form.items() if name != "params"
    }
    return capability.input_of(params, files, ctx)


def choose_output(
    accept: str | None, requested: str | None, allowed: tuple[Output, ...] = tuple(Output)
) -> Output:
    """The answer's form among ``allowed``: ``params.output`` when given, else the one the
    ``Accept`` header prefers (RFC 9110: each form takes the quality of the most specific
    range that matches it; ties go to the range listed first, then to the order of
    ``allowed``); JSON when there is no header.

    Raises
    ------
    Problem
        406 when ``Accept`` allows none of the forms.
    """
    if requested is not None:
        if Output(requested) not in allowed:
            known = ", ".join(output.value for output in allowed)
            raise Problem(422, f"params.output: one of {known}", "invalid-request", "params.output")
        return Output(requested)
    if accept is None or not accept.strip():
        return Output.JSON
    ranges = [_media_range(item) for item in accept.split(",") if item.strip()]
    scored = []
    for order, output in enumerate(allowed):
        kind, subtype = output.media_type.split("/")
        matches = [
            (specificity, -position, quality)
            for position, (range_kind, range_subtype, quality) in enumerate(ranges)
            if (specificity := _specificity(range_kind, range_subtype, kind, subtype)) >= 0
        ]
        if matches:
            specificity, position, quality = max(matches)
            if quality > 0:
                scored.append((quality, position, -order, output))
    if not scored:
        produced = ", ".join(output.media_type for output in allowed)
        raise Problem(
            406,
            f"Accept: {accept.strip()!r} allows none of {produced} (or set params.output)",
            "not-acceptable",
            "Accept",
        )
    return max(scored)[-1]


def _media_range(item: str) -> tuple[str, str, float]:
    """``type``, ``subtype`` and quality of one element of an Accept header."""
    media_range, *parameters = (part.strip() for part in item.split(";"))
    kind, _, subtype = media_range.lower().partition("/")
    quality = 1.0
    for parameter in parameters:
        name, _, value = parameter.partition("=")
        if name.strip().lower() == "q":
            try:
                quality = min(max(float(value), 0.0), 1.0)
            except ValueError:
                quality = 0.0
    return kind, subtype or "*", quality


def _specificity(range_kind: str, range_subtype: str, kind: str, subtype: str) -> int:
    """2 for an exact match, 1 for ``type/*``, 0 for ``*/*``, -1 for no match."""
    if range_kind == kind and range_subtype == subtype:
        return 2
    if range_kind == kind and range_subtype == "*":
        return 1
    return 0 if range_kind == "*" and range_subtype == "*" else -1
