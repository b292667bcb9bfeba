"""Requests' bytes into parameter models and meshes: a JSON body, or a multipart form with a
``mesh`` file and a ``params`` JSON field. Shared by the routes and the command line.

Errors are the models' and readers' own (pydantic's ``ValidationError``,
:class:`~service.meshio.MeshFormatError`), which
:func:`service.problems.core_errors_as_problems` places; the content type and the form's
shape are HTTP matters, answered here as problems.
"""

from __future__ import annotations

from typing import TypeVar

from pydantic import BaseModel

from .meshio import Mesh, format_of, read_mesh
from .multipart import parse_form
from .observability import observe_mesh
from .params import MeshParams
from .problems import Problem
from .settings import Settings

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
    return model.model_validate_json(body)


def mesh_params(model: type[P], text: bytes) -> P:
    """The ``params`` JSON validated as ``model``."""
    return model.model_validate_json(text)


def load_mesh(data: bytes, filename: str | None, params: MeshParams, settings: Settings) -> Mesh:
    """The mesh in ``data`` (its format from ``params.format`` or the file name), read within
    the settings' limits.

    Raises
    ------
    MeshFormatError
        Not a readable mesh, or beyond a limit (:class:`~service.meshio.MeshTooLargeError`).
    """
    mesh = read_mesh(data, format_of(filename, params.format), settings.limits)
    observe_mesh(mesh.format, len(mesh.vertices), len(mesh.faces))
    return mesh


def mesh_form(body: bytes, content_type: str, settings: Settings, model: type[P]) -> tuple[P, Mesh]:
    """The params (default ``{}``) and the mesh of a multipart mesh request."""
    form = parse_form(body, content_type)
    params = mesh_params(model, bytes(form["params"].data) if "params" in form else b"{}")
    if "mesh" not in form:
        raise Problem(422, "mesh: the form has no 'mesh' file field", "invalid-request", "mesh")
    part = form["mesh"]
    return params, load_mesh(bytes(part.data), part.filename, params, settings)
