"""Typed inputs: the parts a route declares (:class:`MeshPart`, :class:`PngPart`), each read
from its file into a mesh or an image, and the params JSON read into the route's model.

The HTTP form reader (:mod:`service.forms`) and the command line (:mod:`service.cli`) both
hand a row (:meth:`service.capabilities.rows.MeshCapability.input_of`) the params and the
files they were given, and get back the typed input its use-case takes: meshes read, PNGs as
:class:`PngFile` for the use-case to decode once it knows it wants them. Params models hold
JSON only, never a file's bytes.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import NamedTuple, TypeVar

from pydantic import BaseModel, ValidationError
from pydantic_core import InitErrorDetails, PydanticCustomError

from ..errors import InvalidInput, UnreadableMesh
from ..images import Png, read_png
from ..jsonkeys import repeated_key
from ..meshio import READERS, Mesh, MeshFormatError, format_of, read_mesh
from ..observability import observe_mesh
from .context import Context

M = TypeVar("M", bound=BaseModel)


class Upload(NamedTuple):
    """A file as sent: its name (None when the form gave none) and its bytes."""

    filename: str | None
    data: bytes | memoryview


def parse_params(model: type[M], text: bytes) -> M:
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


def _formats() -> str:
    *most, last = (reader.title for reader in READERS.values())
    return f"{', '.join(most)} or {last}"


@dataclass(frozen=True)
class MeshPart:
    """A mesh file the route reads; a route reads every one of its meshes (a missing one is
    refused).

    Attributes
    ----------
    name : the part's name in the form (the input's field)
    description : what it is, for the OpenAPI document and the command line's help; None for
        the route's own mesh (its format may also come from ``params.format``)
    """

    name: str
    description: str | None = None

    @property
    def documented(self) -> str:
        """What the part is, for the OpenAPI document and the command line's help."""
        if self.description is not None:
            return self.description
        return (
            f"The mesh file: {_formats()}; the format comes from the file name's extension or "
            "params.format."
        )

    def missing(self) -> InvalidInput:
        """The refusal of a request without this part."""
        return InvalidInput(self.name, f"the form has no '{self.name}' file field")

    def read(self, upload: Upload, ctx: Context, own: bool, declared: str | None = None) -> Mesh:
        """The mesh in ``upload``, its format from ``declared`` or its file name, read within
        the settings' limits; its counts are charged to ``ctx`` before its arrays are built:
        the route's ``own`` mesh by :meth:`Context.charge_mesh`, another on top of it.

        Raises
        ------
        UnreadableMesh
            Not a readable mesh, or beyond a limit
            (:class:`~service.meshio.MeshTooLargeError`).
        """
        charge = ctx.charge_mesh if own else ctx.charge_other_mesh
        limits = replace(ctx.settings.limits, on_counts=charge)
        try:
            mesh = read_mesh(upload.data, format_of(upload.filename, declared), limits)
        except MeshFormatError as error:
            raise UnreadableMesh(self.name, error) from None
        observe_mesh(mesh.format, len(mesh.vertices), len(mesh.faces))
        return mesh


@dataclass(frozen=True)
class PngPart:
    """A PNG the route may read (:func:`service.images.read_png`); it may be left out.

    Attributes
    ----------
    name : the part's name in the form (the input's field)
    description : what it is, for the OpenAPI document and the command line's help
    framed : whether it is drawn on the PNG answer's grid (its size then is
        ``params.image_width`` x ``params.image_height``)
    grey_only : whether only 8-bit grey (with alpha or not) is taken
    """

    name: str
    description: str
    framed: bool = False
    grey_only: bool = False

    @property
    def documented(self) -> str:
        return self.description


@dataclass(frozen=True)
class PngFile:
    """A PNG part as sent, decoded only when the use-case reads it (:meth:`read`), after its
    own checks of whether the part is wanted at all: a refusal for a part that should not
    have been sent comes before any pixel is decoded or charged."""

    part: PngPart
    upload: Upload

    def read(self, params: BaseModel, ctx: Context) -> Png:
        """The image, its pixels charged to ``ctx`` before they are decoded, at most
        MESHFLAT_MAX_IMAGE_PIXELS of them.

        Raises
        ------
        InvalidInput
            Not a PNG, another size, too many pixels, truncated or inconsistent, another mode
            (naming the part).
        """
        part = self.part
        size = (params.image_width, params.image_height) if part.framed else None
        return read_png(
            bytes(self.upload.data),
            part.name,
            ctx.charge,
            size,
            part.grey_only,
            ctx.settings.max_image_pixels,
        )


#: The ``mask`` part every mesh route reads for a ``region.texture_mask``.
MASK = PngPart(
    "mask",
    "A PNG painted in the mesh's texture coordinates (grey, or colour read as its luminance; "
    "8 or 16 bits): the mask of region.texture_mask.",
)
