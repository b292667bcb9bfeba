"""``POST /v1/register``: a follow-up scan registered to the baseline (landmarks or the
scans' moments, then point-to-plane ICP), answered with the transform, the residuals and the
baseline's frame expressed for the follow-up, so that both scans get the same map
(docs/math.md, section 15)."""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from typing import Annotated, Literal

import numpy as np
from pydantic import ConfigDict, Field, model_validator

from transforms import Frame, flatten_region
from transforms.registration import (
    Registration,
    RegistrationAmbiguous,
    Surface,
    apply,
    on_surface_distance,
    register,
)

from ..errors import InvalidInput
from ..meshio import Mesh
from ..outputs import Output
from ..outputs.picture import Drawn
from .context import Context
from .drawn import Outline, Zone, beside_map, check_names, checked_zone, warn_outside
from .fields import PictureParams, Strict, choice, output_choice
from .inputs import MeshPart, PngFile
from .region.answers import ResolvedParams
from .region.params import MESH_PARAMS_EXAMPLE, Landmarks, MeshParams
from .region.pictures import map_renderers
from .region.resolve import MeshInput, MeshRegion, checked_landmarks, flatten, region_faces
from .rows import MeshCapability
from .units import KnownDistance, LengthUnit, mm_per_unit, warn_of_size
from .warnings import WarnedAnswer

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


class ScanLandmarks(Strict):
    """The landmarks of either scan (the pairs given seed the registration)."""

    baseline: Landmarks | None = None
    follow_up: Landmarks | None = None


class RegisterParams(MeshParams, PictureParams):
    """The JSON of the ``params`` field of /v1/register: the baseline's region and frame as
    for /v1/flatten (``region`` is the part to align on), the landmarks, the mode and the
    units; zones to draw on the overlay picture."""

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


#: A follow-up point lies on the baseline when within this distance of it (mm).
OVERLAP_MM = 2.0
#: The least share of the follow-up's area on the baseline for a registration to be given:
#: most of it (a cropped follow-up lies on the baseline whole; a rigid fit of a scan 5 %
#: larger leaves about a third on it).
MIN_OVERLAP = 0.5


@dataclass(frozen=True)
class Registered:
    """A follow-up registered to the baseline (docs/math.md, section 15).

    Attributes
    ----------
    region : MeshRegion, the baseline's region, flattened with its frame
    found : Registration, the transform and the residuals
    follow_boundary : (k, 2, 2) float, the follow-up's region's boundary edges on the
        baseline's map (its faces over the baseline's region, mapped with ``frame``)
    zones : tuple of Outline, checked, to draw
    seeded_by : "landmarks" or "moments"
    overlap : float, the share of the follow-up's area within ``overlap_mm`` of the baseline
    overlap_mm : float, ``OVERLAP_MM``
    rms_mm, p95_mm : float, the residuals over that overlap
    frame : Frame, the baseline's frame expressed for the follow-up
    mm_per_unit : float
    """

    region: MeshRegion
    found: Registration
    seeded_by: str
    overlap: float
    overlap_mm: float
    rms_mm: float
    p95_mm: float
    frame: Frame
    mm_per_unit: float
    follow_boundary: np.ndarray
    zones: tuple[Outline, ...]


@dataclass(frozen=True)
class RegisterInput:
    """A registration: the two scans, the params and the baseline's texture mask.

    Attributes
    ----------
    baseline, follow_up : Mesh, as read
    params : RegisterParams
    mask : PngFile or None, the baseline's ``region.texture_mask``
    """

    baseline: Mesh
    follow_up: Mesh
    params: RegisterParams
    mask: PngFile | None = None


def register_scans(given: RegisterInput, ctx: Context) -> Registered:
    """The follow-up registered to the baseline (:func:`transforms.registration.register`),
    on the baseline's ``region``; refused when too little of it lies on the baseline
    afterwards."""
    mesh, follow, params = given.baseline, given.follow_up, given.params
    scale = mm_per_unit(params.units)
    region = flatten(MeshInput(mesh, params, given.mask), ctx)
    base = Surface.of(mesh.vertices, mesh.faces)
    focus = Surface.of(mesh.vertices, region_faces(mesh, region.selection))
    moving = Surface.of(follow.vertices, follow.faces)
    pairs = _landmark_pairs(mesh, follow, params)
    similar = params.mode is RegisterMode.SIMILARITY
    ratio = moving.size / base.size
    if not similar and not 1 / OTHER_UNITS < ratio < OTHER_UNITS:
        raise _unregistered("a rigid motion keeps sizes", ratio, similar, landmarks_help=False)
    try:
        found = register(moving, base, pairs, scale=similar, focus=focus)
    except RegistrationAmbiguous as error:
        raise _unregistered(str(error), ratio, similar) from None
    on_base = found.residuals * scale <= OVERLAP_MM
    overlap = float(on_base.mean())
    if overlap < MIN_OVERLAP:
        raise _unregistered(
            f"after the best alignment found only {overlap:.0%} of its area lies within "
            f"{OVERLAP_MM:g} mm of the baseline (at least {MIN_OVERLAP:.0%})",
            ratio,
            similar,
        )
    residuals = found.residuals[on_base] * scale
    rms, p95 = float(np.sqrt(np.mean(residuals**2))), float(np.percentile(residuals, 95))
    # Baseline local = R (s A p + t - c) = s R A (p - A^T (c - t) / s): the same angles.
    turn, shift = found.matrix[:3, :3] / found.scale, found.matrix[:3, 3]
    rotation = region.frame.rotation @ turn
    center = turn.T @ (region.frame.center - shift) / found.scale
    frame = Frame.from_matrix(rotation, center)
    seeded = "landmarks" if pairs is not None else "moments"
    boundary = _follow_boundary(follow, found, focus, frame, region)
    zones = tuple(checked_zone(zone, k) for k, zone in enumerate(params.zones))
    _warn(ctx, params, region, zones, scale)
    return Registered(
        region, found, seeded, overlap, OVERLAP_MM, rms, p95, frame, scale, boundary, zones,
    )  # fmt: skip


def _warn(ctx: Context, params: RegisterParams, region, zones: tuple[Outline, ...], scale) -> None:
    """Warn of units that make the baseline's region implausible, and of zones drawn wholly
    beside its map."""
    warn_of_size(ctx, params.units, scale, region)
    for k, outline in enumerate(zones):
        if beside_map(outline.rings[0], *region.layout):
            warn_outside(ctx, region, f"zones.{k}", outline.name, outline.rings[0])


#: Follow-ups whose samples spread this many times as far as the baseline's, or as few, are
#: told that their units or scales may differ (a part of a head spreads at least 0.39 as far
#: as the whole: the top tenth of each sample scan); in rigid mode, those beyond
#: ``OTHER_UNITS`` times are refused before any alignment is tried.
SIZE_MISMATCH, OTHER_UNITS = 2.5, 4.0


def _unregistered(
    why: str, size_ratio: float, similar: bool, landmarks_help: bool = True
) -> InvalidInput:
    """The refusal of a follow-up that could not be registered: ``why``, and what may help
    (``size_ratio``: how far its samples spread from their centroid, over the baseline's)."""
    hints = ["give the landmarks of both scans, or a region both show"] if landmarks_help else []
    if not similar and not 1 / SIZE_MISMATCH <= size_ratio <= SIZE_MISMATCH:
        hints.insert(
            0,
            f"it is {size_ratio:.3g} times the baseline's size (its spread about its "
            "centroid): if the scans' units or scales differ, send mode similarity (or the "
            "follow-up in the baseline's units)",
        )
    elif not similar:
        hints.append("or mode similarity, if the scans differ in scale")
    return InvalidInput("follow_up", f"could not register it: {why}; {'; '.join(hints)}")


def _follow_boundary(follow: Mesh, found, focus: Surface, frame: Frame, region) -> np.ndarray:
    """(k, 2, 2) float: the boundary edges, on the map, of the follow-up's faces whose
    registered centroids lie on the baseline's region (within two sample spacings of its
    samples), flattened with the baseline's frame expressed for the follow-up."""
    centroids = follow.vertices[follow.faces].mean(axis=1)
    moved = apply(found.matrix, centroids)
    near = focus.tree.query(moved)[0] <= on_surface_distance(focus)
    if not near.any():
        return np.empty((0, 2, 2))
    flat = flatten_region(follow.vertices, follow.faces[near], frame, region.chart,
                          layout=region.flat.layout)  # fmt: skip
    points = np.column_stack([flat.x, flat.y])
    return points[flat.validation.boundary_edges]


def _landmark_pairs(mesh: Mesh, follow: Mesh, params: RegisterParams):
    """The landmarks both scans give, follow-up then baseline ((k, 3) each), or None. The
    baseline's come from params.landmarks.baseline or params.frame."""
    given = params.landmarks
    baseline = given.baseline if given is not None and given.baseline is not None else None
    if baseline is None and params.frame is not None:
        baseline = params.frame.landmarks
    if baseline is None or given is None or given.follow_up is None:
        return None
    base = checked_landmarks(mesh, baseline, "landmarks.baseline").named()
    other = checked_landmarks(follow, given.follow_up, "landmarks.follow_up").named()
    common = [name for name in base if name in other]
    return np.stack([other[n] for n in common]), np.stack([base[n] for n in common])


class RegisterResponse(WarnedAnswer):
    params: ResolvedParams = Field(description="The baseline's params, resolved.")
    transform: list[list[float]] = Field(
        description="The 4x4 matrix (rows) that maps the follow-up's points onto the "
        "baseline: [x', y', z', 1] = M [x, y, z, 1]."
    )
    scale: float = Field(description="Its scale: 1 for rigid.")
    seeded_by: Literal["landmarks", "moments"] = Field(
        description="What the registration started from: the landmarks of both scans, or "
        "the scans' moments (their principal axes in 24 turns, the best kept)."
    )
    overlap: float = Field(
        description="The share of the follow-up's area within overlap_distance_mm of the "
        "baseline's region after registration (a registration below half is refused)."
    )
    overlap_distance_mm: float = Field(description="The distance overlap counts within, mm.")
    rms_mm: float = Field(description="RMS of the residuals over the overlap, mm.")
    p95_mm: float = Field(description="Their 95th percentile, mm.")
    frame: ResolvedParams = Field(
        description="The baseline's frame expressed for the follow-up: sent as the "
        "follow-up's params (method, sigma, center, rotation), its map lands on the "
        "baseline's."
    )

    @classmethod
    def of(cls, registered: Registered) -> RegisterResponse:
        region = registered.region
        return cls.build(
            params=ResolvedParams.of_region(region),
            transform=registered.found.matrix,
            scale=registered.found.scale,
            seeded_by=registered.seeded_by,
            overlap=registered.overlap,
            overlap_distance_mm=registered.overlap_mm,
            rms_mm=registered.rms_mm,
            p95_mm=registered.p95_mm,
            frame=ResolvedParams.of(region.chart, registered.frame),
        )


def _overlay(registered: Registered) -> tuple[Drawn, ...]:
    edges = registered.follow_boundary
    follow = Drawn(tuple(edges), False, "follow-up", f"boundary, {len(edges):,} edges")
    zones = tuple(Drawn(zone.rings, True, zone.name, "zone") for zone in registered.zones)
    return (follow, *zones)


#: The forms of a registration besides JSON, by :class:`Output`: the baseline's map with its
#: region's boundary, the follow-up's (mapped with the frame the answer gives it) and the
#: zones.
RENDERERS = map_renderers(lambda registered: registered.region, _overlay)


#: The second scan.
FOLLOW_UP = MeshPart(
    "follow_up",
    "The follow-up scan of the same head (OBJ, glTF, GLB, PLY or STL; its format from its "
    "file name).",
)

ROWS = (
    MeshCapability(
        name="register",
        path="/v1/register",
        summary="Register a follow-up scan to the baseline",
        description="Multipart: the `baseline` and `follow_up` meshes and a `params` JSON "
        "field: the baseline's region (the part to align on: the scalp changes over time, the "
        "face and ears less) and frame as for /v1/flatten, `landmarks` of either scan, `mode` "
        "(rigid or similarity) and `units`. Seeded by the landmarks of both scans when given, "
        "else by the scans' moments (their principal axes in 24 turns, centroids or ends "
        "matched, and in similarity mode also scaled to the scans' spreads; refused when two "
        "distinct alignments fit about as well); refined by small_gicp's point-to-plane ICP "
        "over area-weighted samples, trimmed so that a cropped follow-up still aligns "
        "(docs/math.md, section 15). In rigid mode a follow-up more than "
        f"{OTHER_UNITS:g} times the baseline's size, or less than "
        f"1/{OTHER_UNITS:g} of it, is refused at once as in other units. Answers "
        "the 4x4 transform onto the baseline, the RMS "
        "and 95th percentile of the residuals over the overlap (mm), the overlap, and the "
        "baseline's frame expressed for the follow-up, so that the follow-up's map lands on "
        f"the baseline's; refuses (422) when after the best alignment less than "
        f"{MIN_OVERLAP:.0%} of the follow-up lies within {OVERLAP_MM:g} "
        "mm of the baseline. Or, by the Accept header or "
        "params.output, the overlay: the baseline's map with both regions' boundaries and "
        "the zones (SVG or PNG).",
        params=RegisterParams,
        mesh=MeshPart("baseline"),
        extra_parts=(FOLLOW_UP,),
        input=RegisterInput,
        operation=register_scans,
        response=RegisterResponse,
        renderers=RENDERERS,
    ),
)
