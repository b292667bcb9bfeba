"""What every row of the capability table has: its route, its params model and parts, its
use-case, its answer model and its other forms. The routes (:mod:`service.routes`), the
OpenAPI document (:mod:`service.document`), its examples, the command line and the batch are
all derived from the rows, which the capability modules define and
:mod:`service.capabilities` lists.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, fields, replace
from pathlib import PurePath
from typing import ClassVar

from pydantic import BaseModel

from ..encoding import encode
from ..errors import JSON_BODY, ErrorPlaces, InvalidInput, UnknownMesh
from ..meshio import Mesh
from ..outputs import Output
from ..outputs.arrow import arrow_stream
from ..timings import Timings
from .context import JSON_BYTES_PER_BYTE, READER_BYTES_PER_BYTE, Context
from .inputs import MASK, MeshPart, PngFile, PngPart, Upload
from .region.params import MeshParams
from .region.pictures import Renderer
from .region.resolve import MeshInput
from .warnings import WarnedAnswer


@dataclass(frozen=True)
class Capability:
    """What every route of the table has.

    Attributes
    ----------
    name : the route's name (its OpenAPI operation id starts with it)
    path, summary, description : the route and its documentation
    operation : the use-case, ``(input, ctx) -> result``
    response : the JSON answer's model (a :class:`~.warnings.WarnedAnswer`: it carries the
        warnings); ``response.of(result)`` builds it
    """

    name: str
    path: str
    summary: str
    description: str
    operation: Callable
    response: type[BaseModel]
    parse_bytes_per_byte: ClassVar[int]

    def __post_init__(self) -> None:
        if not issubclass(self.response, WarnedAnswer):  # its warnings would be lost: a bug
            raise TypeError(f"{self.name}: its answer {self.response.__name__} carries no warnings")

    @property
    def places(self) -> ErrorPlaces:
        """Where the fields of a refusal or a warning lie in this route's request."""
        return JSON_BODY

    def encoded(self, result, ctx: Context, timings: Timings) -> bytes:
        """The JSON answer to ``result``, with the warnings its use-case added to ``ctx``
        (timed as ``encode``)."""
        with timings.measure("encode"):
            return encode(self.json_answer(result, ctx))

    def json_answer(self, result, ctx: Context) -> BaseModel:
        """The JSON answer's model for ``result``, with the warnings of ``ctx``: what the JSON
        encodes and the forms made of it (Arrow) carry."""
        return self.response.of(result).warned(ctx.warnings, self.places)


#: The mesh part of most routes.
MESH = MeshPart("mesh")


@dataclass(frozen=True)
class MeshCapability(Capability):
    """A multipart route: its own mesh, the ``mask`` of a ``region.texture_mask``, the parts
    it reads beyond those, and a ``params`` JSON field, read into its typed ``input`` (a
    field a part, and ``params``); its use-case is ``(input, ctx) -> result``.

    Attributes
    ----------
    params : the model of the ``params`` field
    mesh : its own mesh part (``params.format`` may name its format)
    extra_parts : the files it reads beyond its mesh and the mask (a second mesh, an image)
    input : the use-case's input type, built from the params and the parts
    renderers : the other forms of the answer, ``(result, params, ctx) -> bytes`` by Output
    """

    params: type[MeshParams]
    mesh: MeshPart = MESH
    extra_parts: tuple[MeshPart | PngPart, ...] = ()
    input: type = MeshInput
    renderers: Mapping[Output, Renderer] = field(default_factory=dict)
    #: What parsing the body may take per byte, beside the mesh (charged by the admission).
    parse_bytes_per_byte: ClassVar[int] = READER_BYTES_PER_BYTE

    def __post_init__(self) -> None:
        super().__post_init__()
        names = {item.name for item in fields(self.input)}
        declared = {part.name for part in self.parts} | {"params"}
        if names != declared:  # a row that cannot build its input is a bug: fail at import
            raise TypeError(f"{self.name}: input fields {sorted(names)}, parts {sorted(declared)}")

    @property
    def command(self) -> str:
        """The command line's command: the path's last part."""
        return self.path.rsplit("/", 1)[-1]

    @property
    def parts(self) -> tuple[MeshPart | PngPart, ...]:
        """Every file part the route reads: its mesh, the mask, the others."""
        return (self.mesh, MASK, *self.extra_parts)

    @property
    def places(self) -> ErrorPlaces:
        """Where the fields of a refusal lie in this route's request: its parameters under
        ``params.``, whatever else the core names (vertices, faces, points derived from them)
        under the route's own mesh part."""
        return ErrorPlaces("params.", frozenset(self.params.model_fields), self.mesh.name)

    @property
    def outputs(self) -> tuple[Output, ...]:
        """The forms of the answer: JSON first, its own others, and the JSON's arrays as
        Arrow columns last (every mesh answer has arrays: ids, faces, the params' centre)."""
        return (Output.JSON, *self.renderers, Output.ARROW)

    def output_of_file(self, name: str, field: str) -> Output:
        """The form a file name's extension asks for, among this route's (the command
        line's ``--out``, a batch's ``outputs``: ``field``).

        Raises
        ------
        InvalidInput
            Another extension (naming ``field`` and this route's extensions).
        """
        suffix = PurePath(name).suffix.lower()
        found = next((o for o in self.outputs if suffix == o.suffix), None)
        if found is None:
            *most, last = (output.suffix for output in self.outputs)
            choices = f"{', '.join(most)} or {last}" if most else last
            raise InvalidInput(field, f"{name!r}: use {choices}")
        return found

    def input_of(self, params: MeshParams, files: Mapping[str, Upload], ctx: Context):
        """The use-case's input: ``params``, each mesh of ``files`` (name -> the file as sent)
        read and charged to ``ctx``, each PNG as a :class:`~.inputs.PngFile` for the use-case
        to decode once it knows it wants it (None where not sent).

        The route's own mesh may instead be one the server holds, named by
        ``params.mesh_sha256`` (:class:`~.context.MeshStore`); its computation is charged as
        a read mesh's is.

        Raises
        ------
        InvalidInput
            A mesh is missing, or a file is one the route does not read (a misspelt part would
            be left out unseen); a mesh part and ``mesh_sha256`` both; ``mesh_sha256`` on the
            command line.
        UnreadableMesh
            A mesh that cannot be read.
        UnknownMesh
            ``mesh_sha256`` names a mesh the server does not hold.
        """
        held = None
        if params.mesh_sha256 is not None:
            held = self._held_mesh(params.mesh_sha256, files, ctx)
        elif self.mesh.name not in files:
            raise self.mesh.missing()
        taken = ("params", *(part.name for part in self.parts))
        for name in files:
            if name not in taken:
                raise InvalidInput(
                    name, f"this route reads no part of that name; it reads {', '.join(taken)}"
                )
        read = {}
        for part in self.parts:
            upload = files.get(part.name)
            if isinstance(part, PngPart):
                read[part.name] = None if upload is None else PngFile(part, upload)
            elif part is self.mesh and held is not None:
                read[part.name] = held
            elif upload is None:
                raise part.missing()
            elif part is self.mesh:
                read[part.name] = part.read(upload, ctx, own=True, declared=params.format)
            else:
                read[part.name] = part.read(upload, ctx, own=False)
        return self.input(params=params, **read)

    def _held_mesh(self, digest: str, files: Mapping[str, Upload], ctx: Context) -> Mesh:
        """The mesh ``params.mesh_sha256`` names, its computation charged to ``ctx``."""
        if ctx.meshes is None:  # the command line, the batch
            raise InvalidInput(
                "mesh_sha256",
                "names a mesh sent to a server's POST /v1/meshes; here, give the mesh's file",
            )
        if self.mesh.name in files:
            raise InvalidInput(
                "mesh_sha256",
                f"the form has a '{self.mesh.name}' part too: send the mesh or name it, not both",
            )
        mesh = ctx.meshes.mesh(digest.lower())
        if mesh is None:
            raise UnknownMesh("mesh_sha256", digest.lower())
        ctx.charge_mesh(len(mesh.vertices), len(mesh.faces))
        return mesh

    def answer(self, given, ctx: Context, output: Output, timings: Timings) -> bytes:
        """The answer's bytes in ``output`` (one of :attr:`outputs`); the use-case sees it as
        ``params.output`` (chosen by the Accept header, or the command line's file name)."""
        params = given.params
        if "output" in type(params).model_fields and params.output is not output:
            given = replace(given, params=params.model_copy(update={"output": output}))
        with timings.measure("compute"):
            result = self.operation(given, ctx)
        return self.render(result, given.params, output, ctx, timings)

    def render(
        self, result, params: MeshParams, output: Output, ctx: Context, timings: Timings
    ) -> bytes:
        """The bytes of ``result`` in ``output``: one computation can be answered in several
        forms (``meshflat batch`` writes each output a manifest line names)."""
        if output is Output.JSON:
            return self.encoded(result, ctx, timings)
        if output is Output.ARROW:
            with timings.measure("encode"):
                return arrow_stream(self.json_answer(result, ctx), ctx.charge)
        with timings.measure("encode"):
            return self.renderers[output](result, params, ctx)


@dataclass(frozen=True)
class JsonCapability(Capability):
    """A route whose body is one JSON model; its use-case is ``(request, ctx) -> result``.

    Attributes
    ----------
    request : the body's model
    """

    request: type[BaseModel]
    #: What parsing the body may take per byte (charged by the admission).
    parse_bytes_per_byte: ClassVar[int] = JSON_BYTES_PER_BYTE

    def answer(self, request: BaseModel, ctx: Context, timings: Timings) -> bytes:
        with timings.measure("compute"):
            result = self.operation(request, ctx)
        return self.encoded(result, ctx, timings)
