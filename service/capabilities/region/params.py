"""The parameters every mesh route shares: the chart (method, cap, rotation), the region
(which faces), the centre and the frame, and how the layout is made (:class:`MeshParams`);
their resolution into the core's objects is :mod:`.resolve`.
"""

from __future__ import annotations

import math
from typing import Annotated, Literal

from pydantic import ConfigDict, Field, model_validator

from transforms import Layout, Method
from transforms.selection import NAMED_CENTERS, Channel, CornerRule, Pieces

from ...meshio import FORMATS
from ..fields import Matrix3, Number, PositiveNumber, Strict, Vector3, choice
from ..units import KnownDistance, LengthUnit

#: The centres a mesh request may name instead of a point: the core's, and "auto" (fitted).
CENTERS = (*NAMED_CENTERS, "auto")

#: A SHA-256 in hex, as POST /v1/meshes answers it (either case).
SHA256_PATTERN = r"^[0-9a-fA-F]{64}$"

#: The paper's example.
DEFAULT_SIGMA = 0.3


class PoleUp(Strict):
    """The local frame from two world directions."""

    pole: Vector3 = Field(description="World direction that becomes local +Y (the warp's pole).")
    up: Vector3 = Field(description="World direction whose part orthogonal to pole becomes +Z.")


class ChartParams(Strict):
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


class Landmarks(Strict):
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


class LandmarkFrame(Strict):
    """A frame that belongs to the head, from its landmarks."""

    landmarks: Landmarks = Field(
        description="The centre sits a quarter of the tragi's distance above their midpoint, "
        "the pole points down the neck and local +Z towards the nasion (docs/math.md, section "
        "14): the same head, in any pose or scan, gets the same frame."
    )


class Scalp(Strict):
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


class Cone(Strict):
    axis: Vector3 = Field(description="World direction of the cone's axis (non-zero).")
    half_angle_deg: Number = Field(gt=0, le=180, description="Half-angle in degrees.")
    apex: Vector3 | None = Field(
        None,
        description="Where the cone starts, world coordinates. Default: the box centre of "
        "the whole mesh in its principal axes (as center's bbox_center), whatever center is "
        "(so a fitted centre sent back selects the same faces); answers give it resolved.",
    )


class VertexColor(Strict):
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


class FeatureId(Strict):
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


class TextureMask(Strict):
    """The faces under a mask painted in the mesh's own texture coordinates."""

    min: Number = Field(
        0.5,
        ge=0,
        le=1,
        description="A face is in when the mask's mean over its triangle in texture space "
        "(grey 0 to 1, the luminance of a colour mask; 0 off the image) is at least this.",
    )


class Region(Strict):
    """Which faces: exactly one of ``faces``, ``vertices``, ``groups``, ``cone``, ``scalp``,
    ``vertex_color``, ``feature_id`` or ``texture_mask``, and which of their pieces."""

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
    pieces: choice(Pieces) = Field(
        Pieces.ALL,
        description="all: every face selected; largest: only the largest connected piece of "
        "them (faces joined by an edge, corners at one position counted as one vertex), as "
        "validation.pieces and validation.stray_faces report them: a stray object or "
        "fragment beside the head is left out.",
    )

    @model_validator(mode="after")
    def _exactly_one(self) -> Region:
        kinds = REGION_KINDS
        given = [name for name in kinds if name in self.model_fields_set]
        if len(given) != 1:
            raise ValueError(
                f"give exactly one of {', '.join(kinds[:-1])} or {kinds[-1]}"
                + (f", not {' and '.join(given)}" if given else "")
            )
        return self

    def resolved(self) -> dict:
        """The region as answers repeat it: what was given, ``pieces`` only when not all."""
        given = self.model_dump(exclude_none=True)
        if self.pieces is Pieces.ALL:
            given.pop("pieces")
        return given


#: The kinds of region, of which a region names exactly one.
REGION_KINDS = (
    "faces",
    "vertices",
    "groups",
    "cone",
    "scalp",
    "vertex_color",
    "feature_id",
    "texture_mask",
)


def _one_property(schema: dict) -> None:
    """Region's JSON schema: exactly one of the kinds (with ``pieces`` beside it or not),
    none of them null (the None defaults only mark what was not given)."""
    schema["oneOf"] = [{"required": [kind]} for kind in REGION_KINDS]
    for kind in REGION_KINDS:
        schema["properties"][kind].pop("default", None)


#: A scalp-like region: the faces within 60 degrees of +Y, the cap around -Y (the neck).
MESH_PARAMS_EXAMPLE = {
    "method": "distorted",
    "sigma": 0.3,
    "center": "bbox_center",
    "rotation": {"pole": [0.0, -1.0, 0.0], "up": [0.0, 0.0, 1.0]},
    "region": {"cone": {"axis": [0.0, 1.0, 0.0], "half_angle_deg": 60.0}},
}


class AutoPole(Strict):
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
        description="The centre: world point, or the area-weighted centroid of the region's "
        "triangles, or bbox_center: the middle of the box around the region's vertices in "
        "the region's own principal axes (the area-weighted principal axes of its "
        "triangles: it moves and turns with the mesh), or "
        + AUTO_DESCRIPTION
        + " A cone's faces are selected from its apex, and the named centres (and the start "
        "of auto) are those of the faces it selects.",
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
    facing: Vector3 | None = Field(
        None,
        description="Where the face looks, a world direction (towards the nose, say): the map "
        "is rolled about the pole so that the front of the head is at the top of the "
        "pictures, the same way on every scan and in every pose (local +Z becomes facing's "
        "part across the pole; docs/math.md, section 18). The pole and sigma are still "
        "chosen as asked, the roll kept. Refused within 1 degree of the pole or its "
        'opposite. With a rotation that fixes the roll (a matrix, {pole, up}, "identity") '
        'the two must agree, as an answer\'s params do; not with {"pole": "auto", '
        '"up"} nor with frame (whose landmarks put the nasion at the top). Default: '
        "none; with a region.scalp and a rotation chosen by meshflat, its landmarks' "
        "forward direction.",
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
    mesh_sha256: Annotated[str, Field(pattern=SHA256_PATTERN)] | None = Field(
        None,
        description="Instead of the route's own mesh part: the SHA-256 (hex) of a mesh sent "
        "to POST /v1/meshes, which the worker keeps for a while (a cache: a 404 when it does "
        "not hold it, and the client sends the mesh again). The answer is the one the mesh "
        "part would give; the region, map and locate index of repeated params are kept with "
        "it. Not with the mesh part; not on the command line.",
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
