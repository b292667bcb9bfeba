"""Requests' bytes into parameter models and meshes: a JSON body, or a multipart form with a
``mesh`` file and a ``params`` JSON field. Shared by the routes and the command line.

Errors are the models' and readers' own (pydantic's ``ValidationError``,
:class:`~service.meshio.MeshFormatError`), which
:func:`service.problems.core_errors_as_problems` places; the content type and the form's
shape are HTTP matters, answered here as problems.
"""

from __future__ import annotations

from dataclasses import replace
from typing import TypeVar

from pydantic import BaseModel, ValidationError
from pydantic_core import InitErrorDetails, PydanticCustomError

from .jobs import JSON_BYTES_PER_BYTE, charge, charge_mesh, job_bytes
from .jsonkeys import repeated_key
from .meshio import Mesh, format_of, read_mesh
from .multipart import parse_form
from .observability import observe_mesh
from .params import MeshParams
from .problems import ErrorPlaces, Problem, core_errors_as_problems
from .settings import Settings

#: The largest ``params`` field of a mesh form: parameters are a few hundred bytes, a region
#: of listed face ids a few MB.
MAX_PARAMS_BYTES = 32 * 2**20

M = TypeVar("M", bound=BaseModel)
P = TypeVar("P", bound=MeshParams)


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
    return validated_json(model, body)


def mesh_params(model: type[P], text: bytes) -> P:
    """The ``params`` JSON validated as ``model``."""
    return validated_json(model, text)


def validated_json(model: type[M], text: bytes) -> M:
    """``text`` validated as ``model``, refusing a key given twice in one object (which the
    parser would take the last of): that error comes before the model's own, which may be
    about the value that would have been taken.

    Raises
    ------
    pydantic.ValidationError
        Not JSON, not valid as ``model``, or a repeated key (type ``duplicate_key``, its
        location the key's path).
    """
    try:
        parsed = model.model_validate_json(text)
    except ValidationError as error:
        if all(item["type"] != "json_invalid" for item in error.errors()):
            _refuse_repeated_keys(model, text)
        raise
    _refuse_repeated_keys(model, text)
    return parsed


def _refuse_repeated_keys(model: type[BaseModel], text: bytes) -> None:
    path = repeated_key(text)
    if path is not None:
        message = (
            "given more than once in one JSON object; give each key once (only one of the "
            "values would be used, silently)"
        )
        error = InitErrorDetails(
            type=PydanticCustomError("duplicate_key", message), loc=path, input=None
        )
        raise ValidationError.from_exception_data(model.__name__, [error])


def load_mesh(
    data: bytes | memoryview, filename: str | None, params: MeshParams, settings: Settings
) -> Mesh:
    """The mesh in ``data`` (its format from ``params.format`` or the file name), read within
    the settings' limits; in a job, its counts are charged to the memory budget before its
    arrays are built (:func:`service.jobs.charge_mesh`).

    Raises
    ------
    MeshFormatError
        Not a readable mesh, or beyond a limit (:class:`~service.meshio.MeshTooLargeError`).
    """
    limits = replace(settings.limits, on_counts=charge_mesh)
    mesh = read_mesh(data, format_of(filename, params.format), limits)
    observe_mesh(mesh.format, len(mesh.vertices), len(mesh.faces))
    return mesh


def mesh_form(
    body: bytes | bytearray, content_type: str, settings: Settings, model: type[P]
) -> tuple[P, Mesh]:
    """The params (default ``{}``) and the mesh of a multipart mesh request; the mesh is read
    in place, from a view into ``body`` (no copy of the upload)."""
    form = parse_form(body, content_type)
    text = form["params"].data if "params" in form else b"{}"
    if len(text) > MAX_PARAMS_BYTES:
        raise Problem(
            413,
            f"params: the field has {len(text):,} bytes; the limit is {MAX_PARAMS_BYTES:,}",
            "body-too-large",
            "params",
        )
    charge(JSON_BYTES_PER_BYTE * len(text))  # its parse, beyond the reader's allowance
    params = mesh_params(model, bytes(text))
    name = model.MESH_PART
    if name not in form:
        raise Problem(422, f"{name}: the form has no '{name}' file field", "invalid-request", name)
    taken = ("params", name, *model.FILE_PARTS)
    for key in form:
        if key not in taken:  # a misspelt part would be left out unseen
            raise Problem(
                422,
                f"{key}: this route reads no part of that name; it reads {', '.join(taken)}",
                "invalid-request",
                key,
            )
    files = {key: part for key, part in form.items() if key in model.FILE_PARTS}  # not the mesh
    params.with_parts({key: (part.filename, bytes(part.data)) for key, part in files.items()})
    part = form[name]
    return params, load_mesh(part.data, part.filename, params, settings)


def load_other_mesh(params: MeshParams, name: str, settings: Settings) -> Mesh:
    """The form's second mesh, the part ``name`` (its format from its file name), read within
    the settings' limits and charged to the job's memory budget on top of the first.

    Raises
    ------
    Problem
        422 naming the part when it is missing or not a readable mesh; 413 beyond a limit.
    """
    data = params.part(name)
    if data is None:
        raise Problem(422, f"{name}: the form has no '{name}' file field", "invalid-request", name)
    limits = replace(settings.limits, on_counts=lambda v, f: charge(job_bytes(v, f)))
    with core_errors_as_problems(ErrorPlaces("params.", frozenset(), name)):
        mesh = read_mesh(data, format_of(params.part_filename(name), None), limits)
    observe_mesh(mesh.format, len(mesh.vertices), len(mesh.faces))
    return mesh
