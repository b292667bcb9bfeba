"""Request parameters: the pydantic models at the edge, nothing else (their resolution into
the core's objects is :mod:`service.operations`).

The vocabularies come from where they are defined: methods and layouts from the core
(:class:`transforms.Method`, :class:`transforms.Layout`), answer forms from
:class:`service.outputs.Output`, file formats from the reader registry
(:data:`service.meshio.FORMATS`).
"""

from __future__ import annotations

import math
from enum import StrEnum
from typing import Annotated, ClassVar, Literal

from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    PrivateAttr,
    field_validator,
    model_validator,
)

from transforms import Layout, Method
from transforms.selection import NAMED_CENTERS, Channel, CornerRule

from .meshio import FORMATS
from .outputs import Output
from .outputs.colours import ColourBy


def choice(vocabulary: type[StrEnum]):
    """A field type that takes one of ``vocabulary``'s values and holds its member; in the
    schema, the plain ``enum`` of the values (no separate component)."""
    values = tuple(member.value for member in vocabulary)
    return Annotated[Literal[values], AfterValidator(vocabulary)]


#: The centres a mesh request may name instead of a point: the core's, and "auto" (fitted).
CENTERS = (*NAMED_CENTERS, "auto")

Number = Annotated[float, Field(allow_inf_nan=False)]
PositiveNumber = Annotated[float, Field(allow_inf_nan=False, gt=0)]
#: A coordinate or a direction's component: within +-1e15, so that sums of squares (lengths,
#: dot products) stay finite in double precision; far beyond any scan's units.
Coordinate = Annotated[float, Field(allow_inf_nan=False, ge=-1e15, le=1e15)]
Vector3 = Annotated[list[Coordinate], Field(min_length=3, max_length=3)]
# Long lists stop at their first bad item (fail_fast): a body of a million wrong items would
# otherwise build a million error objects, some 280 bytes for each byte of it.
Matrix3 = Annotated[list[Vector3], Field(min_length=3, max_length=3)]

#: The paper's example.
DEFAULT_SIGMA = 0.3


class _Strict(BaseModel):
    # strict: no coercion (false is not 0, "1" is not 1), as the JSON schema says.
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, strict=True)


class PoleUp(_Strict):
    """The local frame from two world directions."""

    pole: Vector3 = Field(description="World direction that becomes local +Y (the warp's pole).")
    up: Vector3 = Field(description="World direction whose part orthogonal to pole becomes +Z.")


class ChartParams(_Strict):
    """How directions become angles: method, cap and frame rotation."""

    method: choice(Method) = Field(
        Method.DISTORTED,
        description="distorted: pole warp then eq. 1; standard: eq. 1 only; separable: the "
        "paper's alternative.",
    )
    sigma: Number | None = Field(
        None,
        gt=0,
        description="Warp parameter (> 0); the cap's angle is 2 atan(sigma). Default 0.3. "
        "At most one of sigma and pole_angle_deg; standard takes neither.",
    )
    pole_angle_deg: Number | None = Field(
        None, gt=0, lt=180, description="The cap's angle rho in degrees, 0 < rho < 180."
    )
    rotation: Matrix3 | PoleUp | None = Field(
        None,
        description="World-to-local rotation: a 3x3 matrix (rows), or {pole, up}. "
        "Default: identity.",
    )

    @model_validator(mode="after")
    def _one_cap(self) -> ChartParams:
        if self.sigma == "auto" and self.pole_angle_deg is not None:
            raise ValueError(
                'sigma, pole_angle_deg: sigma "auto" chooses the cap, so pole_angle_deg '
                "cannot be given too"
            )
        if self.sigma is not None and self.pole_angle_deg is not None:
            # Both, as an answer's params hold them, are fine when they name the same cap.
            agree = isinstance(self.sigma, float) and math.isclose(
                math.degrees(2.0 * math.atan(self.sigma)), self.pole_angle_deg, rel_tol=1e-9
            )
            if not agree:
                raise ValueError(
                    "sigma, pole_angle_deg: give one, not both, or two that agree (they set "
                    "the same cap, rho = 2 atan(sigma))"
                )
        if self.method == "standard" and (
            self.sigma is not None or self.pole_angle_deg is not None
        ):
            raise ValueError(
                "sigma, pole_angle_deg: method 'standard' has no warp, so it takes neither"
            )
        return self


class PointsRequest(ChartParams):
    """Points to transform."""

    points: Annotated[list[Vector3], Field(min_length=1, fail_fast=True)] = Field(
        description="World points [[x, y, z], ...]."
    )
    center: Vector3 = Field([0.0, 0.0, 0.0], description="The centre c, world coordinates.")

    model_config = ConfigDict(
        json_schema_extra={
            "examples": [
                {
                    "points": [[0.0, 0.0, -1.0], [1.0, 0.5, -0.2]],
                    "method": "distorted",
                    "sigma": 0.3,
                    "rotation": {"pole": [0.0, 1.0, 0.0], "up": [0.0, 0.0, 1.0]},
                }
            ]
        }
    )


class InverseRequest(ChartParams):
    """Angles to turn back into points."""

    theta: Annotated[list[Number], Field(min_length=1, fail_fast=True)] = Field(
        description="Polar angles in [0, pi] (radians)."
    )
    phi: Annotated[list[Number], Field(min_length=1, fail_fast=True)] = Field(
        description="Azimuths in [-pi, pi] (radians), one per theta."
    )
    r: list[Number] | Number | None = Field(
        None, description="Distances from the centre (one per theta, or one for all); default 1."
    )
    center: Vector3 = Field([0.0, 0.0, 0.0], description="The centre c, world coordinates.")

    model_config = ConfigDict(
        json_schema_extra={
            "examples": [{"theta": [1.2, 2.0], "phi": [-1.0, -2.5], "r": 1.0, "sigma": 0.3}]
        }
    )

    @model_validator(mode="after")
    def _one_value_per_point(self) -> InverseRequest:
        n = len(self.theta)
        if len(self.phi) != n:
            raise ValueError(
                f"theta, phi: one phi per theta; got {n} theta and {len(self.phi)} phi"
            )
        if isinstance(self.r, list) and len(self.r) != n:
            raise ValueError(
                f"theta, r: one r per theta (or a single number); got {n} theta and {len(self.r)} r"
            )
        return self


class LengthUnit(StrEnum):
    """The length units a mesh may be in."""

    MM = "mm"
    CM = "cm"
    M = "m"

    @property
    def mm(self) -> float:
        """Millimetres in one unit."""
        return {"mm": 1.0, "cm": 10.0, "m": 1000.0}[self.value]


class KnownDistance(_Strict):
    """The mesh's scale from a distance known in millimetres."""

    between: Annotated[list[Vector3], Field(min_length=2, max_length=2)] = Field(
        description="Two world points of the mesh, [[x, y, z], [x, y, z]] (the pupils, say)."
    )
    mm: PositiveNumber = Field(description="Their distance in millimetres.")


class Landmarks(_Strict):
    """Anatomical landmarks of the head, world points on its surface (docs/math.md, section
    14)."""

    nasion: Vector3 = Field(description="The deepest point between the eyes, on the nose's root.")
    inion: Vector3 = Field(description="The bump at the back of the skull, above the neck.")
    left_tragus: Vector3 = Field(description="The left ear's tragus, before the ear canal.")
    right_tragus: Vector3 = Field(description="The right ear's tragus.")
    vertex: Vector3 | None = Field(
        None, description="The top of the head (optional): checks that left and right are not "
        "swapped.",
    )  # fmt: skip


class LandmarkFrame(_Strict):
    """A frame that belongs to the head, from its landmarks."""

    landmarks: Landmarks = Field(
        description="The centre sits a quarter of the tragi's distance above their midpoint, "
        "the pole points down the neck and local +Z towards the nasion (docs/math.md, section "
        "14): the same head, in any pose or scan, gets the same frame."
    )


class Scalp(_Strict):
    """The scalp by anatomy: the surface above a plane through the brow and the inion, the
    piece of it joined to the top of the head (docs/math.md, section 14)."""

    landmarks: Landmarks
    offset_mm: Number = Field(
        10.0,
        ge=-100,
        le=100,
        description="How far above the nasion and the inion the boundary passes, mm.",
    )
    units: choice(LengthUnit) | KnownDistance = Field(
        description="The mesh's length unit, or a known distance (between two landmarks, "
        "say): offset_mm in mesh units."
    )


class Cone(_Strict):
    axis: Vector3 = Field(description="World direction of the cone's axis (non-zero).")
    half_angle_deg: Number = Field(gt=0, le=180, description="Half-angle in degrees.")
    apex: Vector3 | None = Field(
        None,
        description="Where the cone starts, world coordinates. Default: the bounding-box "
        "centre of the whole mesh, whatever center is (so a fitted centre sent back selects "
        "the same faces); answers give it resolved.",
    )


class VertexColor(_Strict):
    """The faces painted in the file's vertex colours."""

    channel: choice(Channel) = Field(
        description="The colour channel read (r, g, b, a, or the luminance, Rec. 709's "
        "0.2126 r + 0.7152 g + 0.0722 b), each 0 to 1 (8- and 16-bit colours are scaled)."
    )
    min: Number = Field(0.5, ge=0, le=1, description="A vertex passes at this value or above.")
    rule: choice(CornerRule) = Field(
        CornerRule.ALL,
        description="How many of a face's three vertices must pass: all, any or majority.",
    )


#: An id a feature_id region asks for: exact as a double (the ids are read as doubles).
FeatureIdValue = Annotated[int, Field(ge=-(2**53), le=2**53)]


class FeatureId(_Strict):
    """The faces of some ids of a per-vertex or per-face attribute of the file."""

    attribute: str = Field(
        "_FEATURE_ID_0",
        min_length=1,
        max_length=256,
        description="A glTF vertex attribute (_FEATURE_ID_0, as EXT_mesh_features names "
        "them) or a PLY vertex or face property, by name.",
    )
    values: Annotated[list[FeatureIdValue], Field(min_length=1, max_length=10_000)] = Field(
        description="The ids that are in (whole numbers of at most 2^53 in size: a file's ids "
        "are compared as doubles, exact up to there)."
    )
    rule: choice(CornerRule) = Field(
        CornerRule.ALL,
        description="For a per-vertex attribute: how many of a face's vertices must hold "
        "one of the ids.",
    )


class TextureMask(_Strict):
    """The faces under a mask painted in the mesh's own texture coordinates."""

    min: Number = Field(
        0.5,
        ge=0,
        le=1,
        description="A face is in when the mask's mean over its triangle in texture space "
        "(grey 0 to 1, the luminance of a colour mask; 0 off the image) is at least this.",
    )


class Region(_Strict):
    """Which faces: exactly one of ``faces``, ``vertices``, ``groups``, ``cone``, ``scalp``,
    ``vertex_color``, ``feature_id`` or ``texture_mask``."""

    model_config = ConfigDict(json_schema_extra=lambda schema: _one_property(schema))

    # Absent fields stay None (the defaults are not validated); null is not accepted.
    faces: Annotated[list[int], Field(min_length=1, fail_fast=True)] = Field(
        None, description="Triangle ids of the file, no repeats."
    )
    vertices: Annotated[list[int], Field(min_length=1, fail_fast=True)] = Field(
        None, description="Vertex ids: the faces whose three vertices are all listed."
    )
    groups: Annotated[list[str], Field(min_length=1, fail_fast=True)] = Field(
        None, description="OBJ g/o/usemtl names, glTF mesh or node names."
    )
    cone: Cone = Field(
        None,
        description="Faces whose centroid, seen from the apex, lies within half_angle_deg of axis.",
    )
    scalp: Scalp = Field(
        None,
        description="Faces whose centroid lies above the plane through the nasion and the "
        "inion raised by offset_mm, level from ear to ear (docs/math.md, section 14).",
    )

    vertex_color: VertexColor = Field(
        None,
        description="Faces whose vertices' colour channel is at least min (by rule).",
    )
    feature_id: FeatureId = Field(
        None,
        description="Faces whose id in a vertex or face attribute of the file is listed.",
    )
    texture_mask: TextureMask = Field(
        None,
        description="Faces under the mask PNG sent as the form's part 'mask', read through "
        "the mesh's texture coordinates (glTF TEXCOORD_0, OBJ vt, PLY u v).",
    )

    @model_validator(mode="after")
    def _exactly_one(self) -> Region:
        kinds = tuple(type(self).model_fields)
        given = [name for name in kinds if name in self.model_fields_set]
        if len(given) != 1:
            raise ValueError(
                f"give exactly one of {', '.join(kinds[:-1])} or {kinds[-1]}"
                + (f", not {' and '.join(given)}" if given else "")
            )
        return self


def _one_property(schema: dict) -> None:
    """Region's JSON schema: exactly one property, none of them null (the None defaults only
    mark what was not given)."""
    schema.update(minProperties=1, maxProperties=1)
    for field in schema["properties"].values():
        field.pop("default", None)


#: A scalp-like region: the faces within 60 degrees of +Y, the cap around -Y (the neck).
MESH_PARAMS_EXAMPLE = {
    "method": "distorted",
    "sigma": 0.3,
    "center": "bbox_center",
    "rotation": {"pole": [0.0, -1.0, 0.0], "up": [0.0, 0.0, 1.0]},
    "region": {"cone": {"axis": [0.0, 1.0, 0.0], "half_angle_deg": 60.0}},
}


class AutoPole(_Strict):
    """The pole chosen by meshflat, the roll following a hint."""

    pole: Literal["auto"] = Field(description="Choose the pole (see /v1/fit).")
    up: Vector3 | None = Field(
        None,
        description="World direction whose part orthogonal to the chosen pole becomes local "
        "+Z. Default: the direction in which the region spreads most about the pole.",
    )


AUTO_DESCRIPTION = (
    '"auto": chosen with the others to minimise the region\'s isometric energy within the '
    "bounds min_kernel_depth and min_margin_deg (see /v1/fit)."
)


class MeshParams(ChartParams):
    """The JSON of the ``params`` field of /v1/flatten, /v1/validate and /v1/fit."""

    center: Vector3 | Literal[CENTERS] = Field(
        "bbox_center",
        description="The centre: world point, or the area-weighted centroid or bounding-box "
        "centre of the region (of the whole mesh when the region is a cone), or "
        + AUTO_DESCRIPTION
        + " A cone region is taken around its apex, not the centre.",
    )
    sigma: PositiveNumber | Literal["auto"] | None = Field(
        None,
        description="Warp parameter (> 0); the cap's angle is 2 atan(sigma), or "
        + AUTO_DESCRIPTION
        + " Default (neither sigma nor pole_angle_deg): the sigma of least isometric energy "
        "whose cap fits inside the largest cap free of region directions, min_margin_deg to "
        "spare (the start of /v1/fit, with no search); the answer's params give it. At most "
        "one of sigma and pole_angle_deg; standard takes neither.",
    )
    rotation: Matrix3 | PoleUp | AutoPole | Literal["auto", "identity"] | None = Field(
        None,
        description="World-to-local rotation: a 3x3 matrix (rows), {pole, up}, "
        '{"pole": "auto", "up": [x, y, z]} (the roll follows up), "identity" (the world '
        "axes), or "
        + AUTO_DESCRIPTION
        + ' Default: {"pole": "auto"} without the search: the pole in the middle of the '
        "largest cap free of region directions seen from the centre, local +Z along the "
        "direction in which the region spreads most about it (the sign from the third "
        "moment); the answer's params give the matrix.",
    )
    layout: choice(Layout) = Field(
        Layout.THETA_PHI,
        description="The 2D layout: theta_phi, the paper's (phi, theta); or mercator, x = phi, "
        "y = ln tan((pi - theta) / 2), conformal apart from the radial projection. The "
        "metrics (and for auto, the energy) are measured on it; /v1/flatten then also answers "
        "x and y per vertex.",
    )
    min_kernel_depth: Number = Field(
        0.05,
        ge=0,
        le=1,
        description="For auto: how deep the centre stays inside the region's kernel, as a "
        "fraction of the kernel's inscribed radius.",
    )
    min_margin_deg: Number = Field(
        2.0,
        ge=0,
        lt=90,
        description="For auto: the least margin, in degrees, from the region to the seam and "
        "the singular points.",
    )
    region: Region | None = Field(None, description="Which faces; null: the whole mesh.")
    untangle: bool = Field(
        False,
        description="Make the answer's layout fold-free: the vertices of flipped triangles "
        "and as few neighbours as needed move in 2D (Garanzha et al., Foldover-free maps in "
        "50 lines of code, 2021) until every region triangle has the map's orientation; all "
        "other vertices keep the transform's coordinates. vertices.x and vertices.y (and the "
        "GLB's UVs and the pictures) then hold the repaired layout, theta and phi the "
        "transform's, and the answer has an untangle block.",
    )
    format: Literal[FORMATS] | None = Field(
        None, description="The file's format; default: from the file name's extension."
    )
    frame: LandmarkFrame | None = Field(
        None,
        description="The frame from the head's landmarks, instead of center and rotation: the "
        'same for every scan of a head. With sigma "auto" only sigma is fitted; a fixed '
        "sigma gives the same map for every scan.",
    )

    model_config = ConfigDict(json_schema_extra={"examples": [MESH_PARAMS_EXAMPLE]})

    @model_validator(mode="after")
    def _frame_or_center_and_rotation(self) -> MeshParams:
        if self.frame is not None:
            given = [name for name in ("center", "rotation") if name in self.model_fields_set]
            if given:
                raise ValueError(
                    f"frame: the landmarks fix the centre and the rotation; leave out "
                    f"{' and '.join(given)}"
                )
        return self

    #: The form's part holding the mesh the route works on.
    MESH_PART: ClassVar[str] = "mesh"
    #: The form's file parts besides the mesh that the route reads: name -> what it is.
    FILE_PARTS: ClassVar[dict[str, str]] = {
        "mask": "A PNG painted in the mesh's texture coordinates (grey, or colour read as "
        "its luminance; 8 or 16 bits): the mask of region.texture_mask."
    }
    #: Those the command line takes as positional arguments after the mesh.
    POSITIONAL_PARTS: ClassVar[tuple[str, ...]] = ()
    #: Their file names and bytes, as sent (:meth:`with_parts`).
    _parts: dict[str, tuple[str | None, bytes]] = PrivateAttr(default_factory=dict)

    def with_parts(self, parts: dict[str, tuple[str | None, bytes]]):
        """These params holding the form's ``parts`` (name -> (file name, bytes)) this model
        reads (:data:`FILE_PARTS`)."""
        self._parts = {name: part for name, part in parts.items() if name in self.FILE_PARTS}
        return self

    def part(self, name: str) -> bytes | None:
        """The bytes of the form's part ``name``, or None when it was not sent."""
        found = self._parts.get(name)
        return None if found is None else found[1]

    def part_filename(self, name: str) -> str | None:
        """The file name the form's part ``name`` was sent with."""
        found = self._parts.get(name)
        return None if found is None else found[0]

    @property
    def auto(self) -> bool:
        """Whether meshflat chooses any of centre, rotation and sigma."""
        if self.frame is not None:
            return self.sigma == "auto"
        return (
            self.center == "auto"
            or self.sigma == "auto"
            or self.rotation == "auto"
            or isinstance(self.rotation, AutoPole)
        )


class FitParams(MeshParams):
    """The JSON of the ``params`` field of /v1/fit: as for /v1/flatten, but centre, rotation
    and sigma not given are chosen ("auto")."""

    center: Vector3 | Literal[CENTERS] = Field(
        "auto", description=MeshParams.model_fields["center"].description
    )
    rotation: Matrix3 | PoleUp | AutoPole | Literal["auto", "identity"] | None = Field(
        "auto", description=MeshParams.model_fields["rotation"].description
    )

    model_config = ConfigDict(
        json_schema_extra={"examples": [{"region": MESH_PARAMS_EXAMPLE["region"]}]}
    )

    @model_validator(mode="after")
    def _choose_what_is_not_given(self) -> FitParams:
        if self.rotation is None:
            self.rotation = "auto"
        if self.sigma is None and self.pole_angle_deg is None and self.method != "standard":
            self.sigma = "auto"
        return self

    @property
    def auto(self) -> bool:
        """Always: /v1/fit answers through the fit (and its explanation) even when the caller
        fixed all three."""
        return True


class LocateVia(StrEnum):
    """How /v1/locate finds the surface point of a query (docs/math.md, section 12)."""

    RAY = "ray"
    MAP = "map"


class LocateParams(MeshParams):
    """The JSON of the ``params`` field of /v1/locate: a region and its frame as for
    /v1/flatten (``"auto"`` allowed), and the query directions."""

    theta: Annotated[list[Number], Field(min_length=1, fail_fast=True)] = Field(
        description="Polar angles of the query directions, radians, in [0, pi], in the frame "
        "the other params resolve to."
    )
    phi: Annotated[list[Number], Field(min_length=1, fail_fast=True)] = Field(
        description="Azimuths, radians, in [-pi, pi]; one per theta."
    )
    via: choice(LocateVia) = Field(
        LocateVia.RAY,
        description="ray: the point the ray from the centre in direction (theta, phi) meets "
        "first. map: the point the map shows at (theta, phi): the layout's (x, y) of those "
        "angles (the answered layout, untangled when untangle is set) in the region triangle "
        "that holds it, lifted with the same barycentric weights (the map is linear inside "
        "each triangle, as the GLB's UVs and the pictures draw it).",
    )

    model_config = ConfigDict(
        json_schema_extra={
            "examples": [{**MESH_PARAMS_EXAMPLE, "theta": [1.5, 1.7], "phi": [-1.6, -1.4]}]
        }
    )

    @model_validator(mode="after")
    def _one_phi_per_theta(self) -> LocateParams:
        if len(self.phi) != len(self.theta):
            raise ValueError(
                f"theta, phi: one phi per theta; got {len(self.theta)} theta and "
                f"{len(self.phi)} phi"
            )
        return self


def output_choice(outputs: tuple[Output, ...], description: str):
    """The type of the ``output`` parameter of a route that answers in ``outputs``: one of
    their names (held as the :class:`Output`) or null, ``description`` saying what each is."""
    values = tuple(output.value for output in outputs)
    return Annotated[
        Literal[values] | None,
        AfterValidator(lambda value: None if value is None else Output(value)),
        Field(
            description=f"The answer's form, for clients that cannot set Accept: {description} "
            "Default: from the Accept header, JSON without one."
        ),
    ]


class FramingParams(_Strict):
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


class FlattenParams(MeshParams, PictureParams):
    """The JSON of the ``params`` field of /v1/flatten: as for /v1/validate, and the form of
    the answer."""

    output: output_choice(
        (Output.JSON, Output.GLB, Output.SVG, Output.PNG),
        "json (application/json), glb (model/gltf-binary: the region with TEXCOORD_0 from the "
        "layout), svg (image/svg+xml) or png (image/png): a picture of the map.",
    ) = None

    model_config = ConfigDict(json_schema_extra={"examples": [MESH_PARAMS_EXAMPLE]})


#: A name of a zone or a curve: what the answer and the picture label it with.
Name = Annotated[str, Field(min_length=1, max_length=120)]
#: Coordinates on the map: the layout's x or y of a flatten answer.
MapCoordinates = Annotated[list[Coordinate], Field(fail_fast=True)]


class _MapPoints(_Strict):
    """Points on the map: as many ``y`` as ``x``."""

    x: MapCoordinates
    y: MapCoordinates

    @model_validator(mode="after")
    def _one_y_per_x(self) -> _MapPoints:
        if len(self.x) != len(self.y):
            raise ValueError(f"x, y: one y per x; got {len(self.x)} x and {len(self.y)} y")
        return self


class Ring(_MapPoints):
    """A closed ring on the map, in the layout's coordinates (``vertices.x`` and
    ``vertices.y`` of a flatten answer): straight edges from each point to the next and from
    the last back to the first (which need not be repeated)."""

    x: MapCoordinates = Field(min_length=3)
    y: MapCoordinates = Field(min_length=3)


class Zone(_Strict):
    """An area drawn on the map: an outer ring and the holes cut out of it."""

    name: Name
    outer: Ring
    holes: Annotated[list[Ring], Field(max_length=256)] = Field(
        [], description="Rings inside the outer one, apart from each other."
    )


class Curve(_MapPoints):
    """A polyline drawn on the map (a hairline, an incision), in the layout's coordinates."""

    name: Name
    x: MapCoordinates = Field(min_length=2)
    y: MapCoordinates = Field(min_length=2)


def check_names(kind: str, drawn: list) -> None:
    """Refuse two of ``drawn`` (zones or curves, ``kind``) of one name: answers, overlaps
    and the picture's legend name them."""
    seen: dict[str, int] = {}
    for i, item in enumerate(drawn):
        if item.name in seen:
            raise ValueError(
                f"{kind}.{i}: the name {item.name!r} is that of {kind}.{seen[item.name]}; "
                "each needs its own"
            )
        seen[item.name] = i


class MeasureParams(MeshParams, PictureParams):
    """The JSON of the ``params`` field of /v1/measure: a region and its frame as for
    /v1/flatten (``"auto"`` allowed), and what was drawn on its map."""

    zones: Annotated[list[Zone], Field(max_length=256)] = Field(
        [], description="Areas drawn on the map; they may overlap."
    )
    curves: Annotated[list[Curve], Field(max_length=256)] = Field(
        [], description="Polylines drawn on the map."
    )
    units: choice(LengthUnit) | KnownDistance | None = Field(
        None,
        description="The mesh's length unit (mm, cm or m), or its scale from a known "
        "distance. Without it, lengths and areas are in mesh units and no cm2 are given.",
    )
    output: output_choice(
        (Output.JSON, Output.SVG, Output.PNG),
        "json (application/json), svg (image/svg+xml) or png (image/png): the map with each "
        "zone filled, named and labelled with its area, and the curves.",
    ) = None

    @model_validator(mode="after")
    def _names_tell_apart(self) -> MeasureParams:
        check_names("zones", self.zones)
        check_names("curves", self.curves)
        return self

    model_config = ConfigDict(
        json_schema_extra={
            "examples": [
                {
                    **MESH_PARAMS_EXAMPLE,
                    "zones": [
                        {
                            "name": "crown",
                            "outer": {
                                "x": [-1.8, -1.35, -1.35, -1.8],
                                "y": [1.4, 1.4, 1.75, 1.75],
                            },
                        }
                    ],
                    "curves": [
                        {"name": "hairline", "x": [-2.0, -1.57, -1.1], "y": [1.45, 1.35, 1.45]}
                    ],
                    "units": "mm",
                }
            ]
        }
    )


#: Sites per cm² a density may ask for (a site every 0.1 mm or so).
MAX_DENSITY_PER_CM2 = 10_000.0
DensityPerCm2 = Annotated[float, Field(allow_inf_nan=False, gt=0, le=MAX_DENSITY_PER_CM2)]


class SiteZone(Zone):
    """A zone drawn on the map (as for /v1/measure) and the density of sites in it."""

    density_per_cm2: DensityPerCm2 | None = Field(
        None, description="Sites per cm² of the zone's surface (default: params.density_per_cm2)."
    )


class SitesParams(MeshParams, PictureParams):
    """The JSON of the ``params`` field of /v1/sites: a region and its frame as for
    /v1/measure, the density (one for the region, or one per zone), and the count, spacing
    and seed of the sites."""

    density_per_cm2: DensityPerCm2 | None = Field(
        None,
        description="Sites per cm² over the whole region; with zones, of each zone that "
        "gives none.",
    )
    zones: Annotated[list[SiteZone], Field(max_length=256)] = Field(
        [],
        description="Zones drawn on the map (as for /v1/measure), each with its density; "
        "sites go only into zones, which must not overlap.",
    )
    units: choice(LengthUnit) | KnownDistance | None = Field(
        None,
        description="The mesh's length unit (mm, cm or m), or its scale from a known "
        "distance: needed to turn sites per cm² into sites per mesh unit².",
    )
    count: int | None = Field(
        None,
        ge=1,
        description="An exact total: the zones keep their relative densities and the "
        "spacing adapts. Default: each zone's area times its density, rounded.",
    )
    min_spacing_mm: PositiveNumber | None = Field(
        None,
        description="No two sites closer than this in 3D, millimetres. Default: "
        "0.7 / sqrt(density) in each zone, at the density placed (docs/math.md, section 13).",
    )
    density_range: Annotated[list[Annotated[float, Field(ge=0, le=MAX_DENSITY_PER_CM2)]],
                             Field(min_length=2, max_length=2)] | None = Field(
        None,
        description="With a density_map part: the sites per cm² its grey values 0 and 255 "
        "stand for, [lo, hi] (linear between).",
    )  # fmt: skip
    seed: int = Field(0, ge=0, le=2**63 - 1, description="Same inputs and seed: same sites.")
    allow_flagged: bool = Field(
        False, description="Whether sites may go on triangles the validation flags."
    )
    output: output_choice(
        (Output.JSON, Output.PLY, Output.GLB, Output.SVG, Output.PNG),
        "json (application/json); ply (application/ply: a point cloud with normals and face "
        "ids); glb (model/gltf-binary: the region mesh and a POINTS primitive of the sites); "
        "svg (image/svg+xml) or png (image/png): the map with the sites and the zones.",
    ) = None

    FILE_PARTS: ClassVar[dict[str, str]] = {
        **MeshParams.FILE_PARTS,
        "density_map": "A grey PNG (8 bits) in the framing of the PNG answer: image_width by "
        "image_height pixels, the map where the PNG answer draws it. Each region triangle takes "
        "the density of the pixel under its centroid on the map: params.density_range maps "
        "grey 0-255 to sites per cm².",
    }

    @model_validator(mode="after")
    def _a_density_for_each(self) -> SitesParams:
        if self.density_range is not None:
            lo, hi = self.density_range
            if lo > hi or self.zones or self.density_per_cm2 is not None:
                raise ValueError(
                    "density_range: [lo, hi] with lo <= hi, for a density_map part, without "
                    "zones or density_per_cm2"
                )
            return self
        if self.density_per_cm2 is not None:
            return self
        if not self.zones:
            raise ValueError(
                "density_per_cm2: sites per cm² of the region; or zones; or, with a "
                "density_map part, density_range [lo, hi] (the sites per cm² of grey 0 and 255)"
            )
        for i, zone in enumerate(self.zones):
            if zone.density_per_cm2 is None:
                raise ValueError(
                    f"zones.{i} ({zone.name!r}): give its density_per_cm2, or "
                    "params.density_per_cm2 for every zone without one"
                )
        return self

    @model_validator(mode="after")
    def _names_tell_apart(self) -> SitesParams:
        check_names("zones", self.zones)
        return self

    model_config = ConfigDict(
        json_schema_extra={
            "examples": [
                {**MESH_PARAMS_EXAMPLE, "density_per_cm2": 3, "units": "cm", "seed": 7},
                {
                    **MESH_PARAMS_EXAMPLE,
                    "zones": [
                        {
                            "name": "crown",
                            "outer": {
                                "x": [-1.8, -1.35, -1.35, -1.8],
                                "y": [1.4, 1.4, 1.75, 1.75],
                            },
                            "density_per_cm2": 30,
                        }
                    ],
                    "units": "mm",
                },
            ]
        }
    )


#: Landmarks at vertices of the examples' unit icosahedron (the left and right tragi on
#: either side of x, the nasion in front, +y, and the inion behind).
_EXAMPLE_LANDMARKS = {
    "nasion": [0.0, 0.525731112, 0.850650808],
    "inion": [0.0, -0.525731112, 0.850650808],
    "left_tragus": [-0.850650808, 0.0, 0.525731112],
    "right_tragus": [0.850650808, 0.0, 0.525731112],
}


class RegisterMode(StrEnum):
    """What a registration may change of the follow-up."""

    RIGID = "rigid"
    SIMILARITY = "similarity"


class ScanLandmarks(_Strict):
    """The landmarks of either scan (the pairs given seed the registration)."""

    baseline: Landmarks | None = None
    follow_up: Landmarks | None = None


class TransferParams(MeshParams, FramingParams):
    """The JSON of the ``params`` field of /v1/transfer: as for /v1/flatten, and what crosses
    between the map and the mesh (docs/math.md, section 16)."""

    FILE_PARTS: ClassVar[dict[str, str]] = {
        **MeshParams.FILE_PARTS,
        "image": "A PNG in the framing of the PNG answer (image_width by image_height pixels, "
        "the map where the PNG answer draws it; 8- or 16-bit grey, grey and alpha, RGB or "
        "RGBA, a colour read as its luminance, the alpha as the coverage; 16 bits kept for "
        "grey and for colour, grey and alpha read at 8): its values carried onto the mesh's "
        "vertices and faces.",
    }

    values: Annotated[list[Coordinate], Field(min_length=1, fail_fast=True)] | str | None = Field(
        None,
        description="Values a vertex to draw on the map: one a vertex of the file (in its "
        "order), or the name of a per-vertex property of the file (a PLY property, a glTF "
        "custom attribute such as _FEATURE_ID_0).",
    )
    value_range: tuple[Coordinate, Coordinate] | None = Field(
        None,
        description="With an image part: the values its black and white stand for (default "
        "[0, 1]). With values: the values drawn as 0 and 65535 (default: their least and "
        "largest over the region; when all are v, a range of 1 from v towards 0). Within "
        "+-1e15, as values.",
    )
    output: output_choice(
        (Output.JSON, Output.PNG, Output.FACE_IDS, Output.BARYCENTRIC),
        "json (application/json): the values carried; png (image/png): with values, the "
        "16-bit grey and alpha PNG of them (the alpha 65535 where a triangle holds the pixel); "
        "face_ids or barycentric (application/octet-stream): the look-up images, a "
        "little-endian array behind a 16-byte header (docs/api.md says how to read it).",
    ) = None

    @field_validator("value_range")
    @classmethod
    def _low_below_high(cls, value_range):
        if value_range is not None and not value_range[0] < value_range[1]:
            raise ValueError("[low, high] with low < high")
        return value_range

    model_config = ConfigDict(
        json_schema_extra={
            "examples": [
                # A value a vertex of the 12-vertex icosahedron of the examples, drawn.
                {
                    **MESH_PARAMS_EXAMPLE,
                    "values": [float(k) for k in range(12)],
                    "image_width": 480,
                    "image_height": 360,
                },
                {**MESH_PARAMS_EXAMPLE, "output": "face_ids"},
            ]
        }
    )


class RegisterParams(MeshParams, PictureParams):
    """The JSON of the ``params`` field of /v1/register: the baseline's region and frame as
    for /v1/flatten (``region`` is the part to align on), the landmarks, the mode and the
    units; zones to draw on the overlay picture."""

    MESH_PART: ClassVar[str] = "baseline"
    FILE_PARTS: ClassVar[dict[str, str]] = {
        **MeshParams.FILE_PARTS,
        "follow_up": "The follow-up scan of the same head (OBJ, glTF, GLB, PLY or STL; its "
        "format from its file name).",
    }
    #: The parts the command line takes as positional arguments after the mesh.
    POSITIONAL_PARTS: ClassVar[tuple[str, ...]] = ("follow_up",)

    landmarks: ScanLandmarks | None = Field(
        None,
        description="Landmarks of the baseline and of the follow-up: when both are given, "
        "the registration starts from them (else from the scans' moments, several starts).",
    )
    mode: choice(RegisterMode) = Field(
        RegisterMode.RIGID,
        description="rigid (a rotation and a translation) or similarity (and a scale).",
    )
    units: choice(LengthUnit) | KnownDistance = Field(
        description="The baseline's length unit, or a known distance: the residuals in mm."
    )
    zones: Annotated[list[Zone], Field(max_length=256)] = Field(
        [], description="Zones drawn on the baseline's map (as for /v1/measure), for the picture."
    )
    output: output_choice(
        (Output.JSON, Output.SVG, Output.PNG),
        "json (application/json), svg (image/svg+xml) or png (image/png): the baseline's map "
        "with the baseline's and the follow-up's region boundaries and the zones.",
    ) = None

    @model_validator(mode="after")
    def _names_tell_apart(self) -> RegisterParams:
        check_names("zones", self.zones)
        return self

    model_config = ConfigDict(
        json_schema_extra={
            "examples": [
                {
                    **MESH_PARAMS_EXAMPLE,
                    "units": "mm",
                    "landmarks": {"baseline": _EXAMPLE_LANDMARKS, "follow_up": _EXAMPLE_LANDMARKS},
                }
            ]
        }
    )
