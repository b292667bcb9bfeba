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
from ..errors import InvalidInput
from ..outputs import Output
from ..timings import Timings
from .context import JSON_BYTES_PER_BYTE, READER_BYTES_PER_BYTE, Context
from .inputs import MASK, MeshPart, PngPart, Upload
from .region.params import MeshParams
from .region.pictures import Renderer
from .region.resolve import MeshInput


@dataclass(frozen=True)
class Capability:
    """What every route of the table has.

    Attributes
    ----------
    name : the route's name (its OpenAPI operation id starts with it)
    path, summary, description : the route and its documentation
    operation : the use-case, ``(input, ctx) -> result``
    response : the JSON answer's model; ``response.of(result)`` builds it
    """

    name: str
    path: str
    summary: str
    description: str
    operation: Callable
    response: type[BaseModel]
    parse_bytes_per_byte: ClassVar[int]

    def encoded(self, result, timings: Timings) -> bytes:
        """The JSON answer to ``result`` (timed as ``encode``)."""
        with timings.measure("encode"):
            return encode(self.response.of(result))


#: The parts of a route that reads one mesh: the mesh, and the texture mask of a region.
MESH_PARTS = (MeshPart("mesh"), MASK)


@dataclass(frozen=True)
class MeshCapability(Capability):
    """A multipart route: its mesh parts, PNG parts and a ``params`` JSON field, read into
    its typed ``input`` (one field a part, and ``params``); its use-case is
    ``(input, ctx) -> result``.

    Attributes
    ----------
    params : the model of the ``params`` field
    parts : the files it reads, its own mesh first
    input : the use-case's input type, built from the params and the parts
    renderers : the other forms of the answer, ``(result, params, ctx) -> bytes`` by Output
    """

    params: type[MeshParams]
    parts: tuple[MeshPart | PngPart, ...] = MESH_PARTS
    input: type = MeshInput
    renderers: Mapping[Output, Renderer] = field(default_factory=dict)
    #: What parsing the body may take per byte, beside the mesh (charged by the admission).
    parse_bytes_per_byte: ClassVar[int] = READER_BYTES_PER_BYTE

    def __post_init__(self) -> None:
        names = {item.name for item in fields(self.input)}
        declared = {part.name for part in self.parts} | {"params"}
        if names != declared:  # a row that cannot build its input is a bug: fail at import
            raise TypeError(f"{self.name}: input fields {sorted(names)}, parts {sorted(declared)}")

    @property
    def command(self) -> str:
        """The command line's command: the path's last part."""
        return self.path.rsplit("/", 1)[-1]

    @property
    def mesh(self) -> MeshPart:
        """The route's own mesh part."""
        return self.parts[0]

    @property
    def outputs(self) -> tuple[Output, ...]:
        """The forms of the answer, JSON first."""
        return (Output.JSON, *self.renderers)

    def output_of_file(self, name: str, field: str) -> Output:
        """The form a file name's extension asks for, among this route's (the command
        line's ``--out``, a batch's ``outputs``: ``field``).

        Raises
        ------
        InvalidInput
            Another extension (naming ``field`` and this route's extensions).
        """
        suffix = PurePath(name).suffix.lower()
        found = next((o for o in self.outputs if suffix == f".{o.value}"), None)
        if found is None:
            *most, last = (f".{output.value}" for output in self.outputs)
            choices = f"{', '.join(most)} or {last}" if most else last
            raise InvalidInput(field, f"{name!r}: use {choices}")
        return found

    def input_of(self, params: MeshParams, files: Mapping[str, Upload], ctx: Context):
        """The use-case's input: ``params`` and each part read from ``files`` (name -> the
        file as sent), charged to ``ctx``.

        Raises
        ------
        InvalidInput
            The route's mesh is missing, or a file is one the route does not read (a misspelt
            part would be left out unseen).
        UnreadablePart
            A mesh that cannot be read.
        """
        if self.mesh.name not in files:
            self.mesh.read(None, params, ctx)  # the refusal of a missing mesh
        taken = ("params", *(part.name for part in self.parts))
        for name in files:
            if name not in taken:
                raise InvalidInput(
                    name, f"this route reads no part of that name; it reads {', '.join(taken)}"
                )
        read = {part.name: part.read(files.get(part.name), params, ctx) for part in self.parts}
        return self.input(params=params, **read)

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
            return self.encoded(result, timings)
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
        return self.encoded(result, timings)
