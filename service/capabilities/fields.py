"""The vocabulary of request parameters: the field types every params model is made of,
strict models, a choice among a vocabulary's values, the answer's form and the picture's
size.

The vocabularies come from where they are defined: methods and layouts from the core
(:class:`transforms.Method`, :class:`transforms.Layout`), answer forms from
:class:`service.outputs.Output`, colourings from :class:`service.outputs.colours.ColourBy`,
file formats from the reader registry (:data:`service.meshio.FORMATS`).
"""

from __future__ import annotations

from enum import StrEnum
from typing import Annotated, Literal

from pydantic import AfterValidator, BaseModel, ConfigDict, Field

from ..outputs import Output
from ..outputs.colours import ColourBy


def choice(vocabulary: type[StrEnum]):
    """A field type that takes one of ``vocabulary``'s values and holds its member; in the
    schema, the plain ``enum`` of the values (no separate component)."""
    values = tuple(member.value for member in vocabulary)
    return Annotated[Literal[values], AfterValidator(vocabulary)]


Number = Annotated[float, Field(allow_inf_nan=False)]
PositiveNumber = Annotated[float, Field(allow_inf_nan=False, gt=0)]
#: A coordinate or a direction's component: within +-1e15, so that sums of squares (lengths,
#: dot products) stay finite in double precision; far beyond any scan's units.
MAX_COORDINATE = 1e15
Coordinate = Annotated[float, Field(allow_inf_nan=False, ge=-MAX_COORDINATE, le=MAX_COORDINATE)]
Vector3 = Annotated[list[Coordinate], Field(min_length=3, max_length=3)]
# Long lists stop at their first bad item (fail_fast): a body of a million wrong items would
# otherwise build a million error objects, some 280 bytes for each byte of it.
Matrix3 = Annotated[list[Vector3], Field(min_length=3, max_length=3)]
#: A name of a zone or a curve: what the answer and the picture label it with.
Name = Annotated[str, Field(min_length=1, max_length=120)]


#: Coordinates on the map: the layout's x or y of a flatten answer.
def _low_below_high(value_range: tuple[float, float]) -> tuple[float, float]:
    if not value_range[0] < value_range[1]:
        raise ValueError("[low, high] with low < high")
    return value_range


#: The values a picture's black and white stand for, or values are drawn between.
ValueRange = Annotated[tuple[Coordinate, Coordinate], AfterValidator(_low_below_high)]
MapCoordinates = Annotated[list[Coordinate], Field(fail_fast=True)]


class Strict(BaseModel):
    """A params model: no field beyond its own, no NaN or Inf, no coercion (false is not 0,
    "1" is not 1), as the JSON schema says."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, strict=True)


def output_choice(outputs: tuple[Output, ...], description: str):
    """The type of the ``output`` parameter of a route that answers in ``outputs`` and, as
    every mesh route, Arrow: one of their names (held as the :class:`Output`) or null,
    ``description`` saying what each of ``outputs`` is."""
    values = tuple(output.value for output in (*outputs, Output.ARROW))
    return Annotated[
        Literal[values] | None,
        AfterValidator(lambda value: None if value is None else Output(value)),
        Field(
            description=f"The answer's form, for clients that cannot set Accept: {description} "
            f"{ARROW_FORM} Default: from the Accept header, JSON without one."
        ),
    ]


#: What the Arrow form of every mesh route is, in an ``output`` parameter's description.
ARROW_FORM = (
    "Or arrow (application/vnd.apache.arrow.stream): the JSON answer's arrays as the columns "
    "of an Arrow IPC stream, named by their dotted paths, the rest as JSON in the schema's "
    "metadata (docs/api.md)."
)


class FramingParams(Strict):
    """The size of a picture answer, and so the pixel grid of every image on the map."""

    image_width: int = Field(
        1200, ge=480, le=4096, description="Width of an SVG or PNG answer, pixels."
    )
    image_height: int = Field(
        800, ge=360, le=4096, description="Height of an SVG or PNG answer, pixels."
    )


class PictureParams(FramingParams):
    """The size of a picture answer and what it draws."""

    grid_lines: int = Field(
        0,
        ge=0,
        le=40,
        description="A reference grid over the map of an SVG or PNG answer: where this many "
        "evenly spaced planes square to the frame's local X axis, and as many square to its "
        "local Z axis (the two directions across the pole), cut the region (docs/math.md "
        "section 17); 0: none.",
    )
    colour_by: choice(ColourBy) = Field(
        ColourBy.FLAGS,
        description="What colours the map's triangles in an SVG or PNG answer (and the GLB's "
        "vertices, as COLOR_0): the validation's flags, or a distortion measure as a factor "
        "of at least 1 (isometric energy, conformal s1/s2, area exp|log(s1 s2)|; docs/math.md "
        "section 7) in viridis on a log scale from 1 to its 99th percentile, with a colour bar "
        "marking its p50 and p95; flagged triangles keep their colours.",
    )
