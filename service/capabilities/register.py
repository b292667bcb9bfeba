"""``POST /v1/register``: a follow-up scan registered to the baseline on its region
(landmarks or the scans' moments, then point-to-plane ICP on the whole scans and region to
region), answered with the transform, the regions' residuals and the baseline's frame
expressed for the follow-up, so that both scans get the same map (docs/math.md, section
15)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum
from functools import cached_property
from typing import Annotated, Literal

import numpy as np
from pydantic import ConfigDict, Field, model_validator

from transforms import Frame, flatten_region
from transforms.registration import (
    OnRegion,
    RegionScans,
    RegistrationAmbiguous,
    Surface,
    held,
    register,
    register_region,
    unit_of,
)

from ..errors import InvalidInput
from ..meshio import Mesh
from ..outputs import Output
from ..outputs.picture import Drawn
from .context import Context
from .drawn import (
    Outline,
    Zone,
    beside_map,
    check_drawn,
    check_names,
    checked_zone,
    warn_outside,
)
from .fields import PictureParams, Strict, choice, output_choice
from .inputs import MeshPart, PngFile
from .region.answers import ResolvedParams
from .region.heads import checked_landmarks
from .region.params import MESH_PARAMS_EXAMPLE, Landmarks, MeshParams
from .region.pictures import map_renderers
from .region.resolve import MeshInput, MeshRegion, flatten
from .rows import MeshCapability
from .units import KnownDistance, LengthUnit, Units, in_mm, mm_per_unit, warn_of_size
from .warnings import WarnedAnswer

#: Landmarks at vertices of the examples' unit icosahedron (the left and right tragi on
#: either side of x, the nasion in front, +y, and the inion behind).
_EXAMPLE_LANDMARKS = {
    "nasion": [0.0, 0.525731112, 0.850650808],
    "inion": [0.0, -0.525731112, 0.850650808],
    "left_tragus": [-0.850650808, 0.0, 0.525731112],
    "right_tragus": [0.850650808, 0.0, 0.525731112],
}


#: A registration of the examples' icosahedron to itself, by its landmarks.
REGISTER_EXAMPLE = {
    **MESH_PARAMS_EXAMPLE,
    "units": "mm",
    "landmarks": {"baseline": _EXAMPLE_LANDMARKS, "follow_up": _EXAMPLE_LANDMARKS},
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
    for /v1/flatten (``region`` is the part to align on and to measure on), the landmarks, the
    mode and the units; zones to draw on the overlay picture."""

    landmarks: ScanLandmarks | None = Field(
        None,
        description="Landmarks of the baseline and of the follow-up: when both are given, "
        "the registration starts from them (else from the scans' moments, several starts).",
    )
    mode: choice(RegisterMode) = Field(
        RegisterMode.RIGID,
        description="rigid (a rotation and a translation) or similarity (and a scale).",
    )
    units: choice(LengthUnit) | KnownDistance | None = Field(
        None,
        description="The baseline's length unit (mm, cm or m), or its scale from a known "
        "distance: the residuals in mm too, and the overlap counted within 2 mm. Without it, "
        "the residuals are in mesh units alone and the overlap is counted within 1/40 of the "
        "baseline region's spread about its centroid.",
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

    model_config = ConfigDict(json_schema_extra={"examples": [REGISTER_EXAMPLE]})


#: A follow-up point lies on the baseline's region when within this distance of it (mm)...
OVERLAP_MM = 2.0
#: ... or, without ``units``, within this share of the region's RMS distance from its
#: centroid (2 mm on the bundled fsaverage scalp, whose spread is 83 mm).
OVERLAP_SHARE = 1 / 40
#: The least share of the follow-up's region's area on the baseline's region for a
#: registration to be given: most of it (a cropped follow-up lies on the baseline whole; a
#: rigid fit of a scan 5 % larger leaves about a third on it). The whole scans must agree as
#: far (the larger of the follow-up's share on the baseline and the baseline's on it): a
#: region alone, turned half round or scaled, may fit where the scans do not (the scalp's
#: dome on another part of a half head: 57-67 % of its region on the scalp, 31-44 % of the
#: follow-up on the baseline).
MIN_OVERLAP = 0.5


@dataclass(frozen=True)
class Registered:
    """A follow-up registered to the baseline on its region (docs/math.md, section 15).

    Attributes
    ----------
    region : MeshRegion, the baseline's region, flattened with its frame
    on : OnRegion, the transform, the follow-up's region and its residuals against the
        baseline's region (mesh units)
    follow : Mesh, the follow-up as read
    follow_boundary : (k, 2, 2) float, the follow-up's region's boundary edges on the
        baseline's map (mapped with ``frame``), found when a picture asks for them
    zones : tuple of Outline, checked, to draw
    seeded_by : "landmarks" or "moments"
    overlap : float, the share of the follow-up's region's area within
        ``overlap_distance`` of the baseline's region
    overlap_distance : float, mesh units: ``OVERLAP_MM`` with units, else ``OVERLAP_SHARE``
        of the baseline region's spread
    rms, p95 : float, mesh units, the residuals over that overlap
    frame : Frame, the baseline's frame expressed for the follow-up
    mm_per_unit : float or None, from params.units
    """

    region: MeshRegion
    on: OnRegion
    seeded_by: str
    overlap: float
    overlap_distance: float
    rms: float
    p95: float
    frame: Frame
    mm_per_unit: float | None
    follow: Mesh
    zones: tuple[Outline, ...]

    @cached_property
    def follow_boundary(self) -> np.ndarray:
        return _follow_boundary(self.follow, self.on.faces, self.frame, self.region)


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
    """The follow-up registered to the baseline on the baseline's ``region``
    (:func:`transforms.registration.register_region`): its sizes, overlap and residuals are
    the regions'; refused when too little of the follow-up's region lies on the baseline's
    afterwards."""
    mesh, follow, params = given.baseline, given.follow_up, given.params
    check_drawn(ctx, params.zones, cover=False)  # only drawn: checked, never covered
    scale = mm_per_unit(params.units)
    region = flatten(MeshInput(mesh, params, given.mask), ctx)
    sent = RegionScans(follow.vertices, follow.faces, mesh.vertices, mesh.faces,
                       region.selection.faces)  # fmt: skip
    similar = params.mode is RegisterMode.SIMILARITY
    sizes = _log_sizes(sent)
    _check_sizes(sizes, similar)
    bounds = _scale_bounds(sizes) if similar else None
    # Registered in a unit where the region spreads about 1, and answered in the scans'.
    unit = unit_of(sizes.region)
    scans = sent.scaled(unit)
    pairs = _landmark_pairs(mesh, follow, params, unit)
    try:
        # Rigid: only as far as the sparse samples, the region's rounds go on from it; with
        # a scale, on all the samples (from the sparse ones' pose alone, half a head at 10
        # times its size was answered 200 mm off rather than refused).
        last = "samples" if similar else "sparse"
        whole = register(scans.follow, scans.base, pairs, similar, bounds, last=last)
    except RegistrationAmbiguous as error:
        raise _unregistered(str(error), _mismatch(scans, None), similar) from None
    _check_scale(whole.scale, bounds)
    within = OVERLAP_MM / scale * unit if scale is not None else OVERLAP_SHARE * scans.target.size
    _check_agreement(scans, whole.matrix, within, _Reach(scale, unit), similar, None)
    on = register_region(scans, whole, scale=similar, bounds=bounds)
    _check_scale(on.found.scale, bounds)
    on_base = on.found.residuals <= within
    overlap = float(on_base.mean()) if on_base.size else 0.0
    if overlap < MIN_OVERLAP:
        why = _too_little(on, overlap, within / unit, scale)
        raise _unregistered(why, _mismatch(scans, on), similar)
    _check_agreement(scans, on.found.matrix, within, _Reach(scale, unit), similar, on)
    on, within = on.scaled(1.0 / unit), within / unit
    residuals = on.found.residuals[on_base]
    rms, p95 = float(np.sqrt(np.mean(residuals**2))), float(np.percentile(residuals, 95))
    # Baseline local = R (s A p + t - c) = s R A (p - A^T (c - t) / s): the same angles.
    found = on.found
    turn, shift = found.matrix[:3, :3] / found.scale, found.matrix[:3, 3]
    rotation = region.frame.rotation @ turn
    center = turn.T @ (region.frame.center - shift) / found.scale
    frame = Frame.from_matrix(rotation, center)
    seeded = "landmarks" if pairs is not None else "moments"
    zones = tuple(checked_zone(zone, k) for k, zone in enumerate(params.zones))
    _warn(ctx, params, region, zones, scale)
    return Registered(
        region, on, seeded, overlap, within, rms, p95, frame, scale, follow, zones,
    )  # fmt: skip


def _warn(ctx: Context, params: RegisterParams, region, zones: tuple[Outline, ...], scale) -> None:
    """Warn of units that make the baseline's region implausible, and of zones drawn wholly
    beside its map."""
    warn_of_size(ctx, params.units, scale, region)
    for k, outline in enumerate(zones):
        if beside_map(outline.rings[0], *region.layout):
            warn_outside(ctx, region, f"zones.{k}", outline.name, outline.rings[0])


def _too_little(on: OnRegion, overlap: float, within: float, scale: float | None) -> str:
    """Why a registration whose overlap is below ``MIN_OVERLAP`` is refused (``within``: the
    distance it counts within, mesh units)."""
    if on.source is None:
        return "after the best alignment found none of it lies over the baseline's region"
    return (
        f"after the best alignment found only {overlap:.0%} of its area over the baseline's "
        f"region lies within {_distance(within, scale)} of that region (at least "
        f"{MIN_OVERLAP:.0%})"
    )


@dataclass(frozen=True)
class _Reach:
    """How the scans' lengths are told: ``mm_per_unit`` (None without units) of the scans
    as sent, registered in ``unit`` (:func:`transforms.registration.unit_of`) times them."""

    mm_per_unit: float | None
    unit: float


def _check_agreement(scans: RegionScans, matrix, within, reach: _Reach, similar, on) -> None:
    """Refuse a registration under whose 4x4 ``matrix`` the whole scans disagree: checked
    on the whole scans' alignment (before the regions', which a misplaced start would only
    spend time on) and on the regions' (``on``), which must not slide the scans apart.
    ``scans``, ``matrix`` and ``within`` are in the registration's unit (``reach``)."""
    agree = scans.agreement(matrix, within)
    if max(agree) >= MIN_OVERLAP:
        return
    stage = "the whole scans'" if on is None else "the regions'"
    distance = _distance(within / reach.unit, reach.mm_per_unit)
    why = (
        f"after the best alignment found ({stage}) only {agree[0]:.0%} of the follow-up lies "
        f"within {distance} of the baseline, and {agree[1]:.0%} of the baseline within it of "
        f"the follow-up (at least {MIN_OVERLAP:.0%} of either)"
    )
    raise _unregistered(why, _mismatch(scans, on), similar)


def _distance(within: float, scale: float | None) -> str:
    """The overlap's distance as the refusals say it."""
    if scale is not None:
        return f"{OVERLAP_MM:g} mm"
    return f"{within:.3g} mesh units (1/{1 / OVERLAP_SHARE:g} of the region's spread)"


#: Follow-ups whose samples spread this many times as far as the baseline's, or as few, are
#: told that their units or scales may differ (a part of a head spreads at least 0.39 as far
#: as the whole: the top tenth of each sample scan); in rigid mode, those beyond
#: ``OTHER_UNITS`` times are refused before any alignment is tried. The follow-up's whole is
#: weighed against the baseline's whole above and against its region below (a follow-up
#: cropped to the region is as large as the region); the follow-up's region, once found,
#: against the baseline's region.
SIZE_MISMATCH, OTHER_UNITS = 2.5, 4.0
#: In similarity mode, the follow-up may spread at most ``SCALE_RANGE`` times as far as the
#: whole baseline and at least 1/``SCALE_RANGE`` as far as its region (checked before any
#: alignment, on sizes taken in each scan's own unit: docs/math.md, section 15); the scale
#: fitted must leave it within ``OTHER_UNITS`` of them, as rigid mode asks of it as sent:
#: ICP holds its scale there, and a fit held at either bound is refused (a collapse onto a
#: point of the baseline, or a blow-up).
SCALE_RANGE = 100.0


@dataclass(frozen=True)
class LogSizes:
    """log2 of the spreads (:attr:`Surface.size`) of the whole follow-up, the whole baseline
    and the baseline's region, each taken in its scan's own unit (no overflow)."""

    follow: float
    base: float
    region: float


def _log_sizes(scans: RegionScans) -> LogSizes:
    region = scans.base_faces[scans.region]
    return LogSizes(
        Surface.log_size(scans.follow_vertices, scans.follow_faces),
        Surface.log_size(scans.base_vertices, scans.base_faces),
        Surface.log_size(scans.base_vertices, region),
    )


def _times(log2: float) -> str:
    """``2 ** log2`` in words: a float's ``.3g``, or a power of ten beyond its range."""
    if abs(log2) < 1000:
        return f"{2.0**log2:.3g}"
    return f"about 1e{round(log2 * math.log10(2))}" if math.isfinite(log2) else "0"


def _check_sizes(sizes: LogSizes, similar: bool) -> None:
    """Refuse, before any alignment, a follow-up whose size is out of the mode's range:
    ``SCALE_RANGE`` in either mode (no similarity would do: its units are told), and in rigid
    mode ``OTHER_UNITS`` (similarity would)."""
    beyond = _out_of_scale(sizes, SCALE_RANGE)
    if not similar and beyond is None:
        outside = _out_of_scale(sizes, OTHER_UNITS)
        if outside is not None:
            why = "a rigid motion keeps sizes"
            raise _unregistered(why, outside, similar, landmarks_help=False)
    if beyond is None:
        return
    raise InvalidInput(
        "follow_up",
        f"could not register it: {beyond} (its spread about its centroid), and similarity "
        f"mode registers follow-ups from 1/{SCALE_RANGE:g} of the baseline region's size to "
        f"{SCALE_RANGE:g} times the whole baseline's; send it in units nearer the baseline's",
    )


def _out_of_scale(sizes: LogSizes, factor: float) -> str | None:
    """What is wrong with the follow-up's size, when its samples spread more than ``factor``
    times as far as the whole baseline's, or less than 1/``factor`` of its region's; else
    None."""
    if not math.isfinite(sizes.follow):
        return "it has no area"
    if sizes.follow - sizes.base > math.log2(factor):
        return f"it is {_times(sizes.follow - sizes.base)} times the baseline's size"
    if sizes.region - sizes.follow > math.log2(factor):
        return f"it is {_times(sizes.follow - sizes.region)} times the baseline region's size"
    return None


def _scale_bounds(sizes: LogSizes) -> tuple[float, float]:
    """The least and the most scale a similarity may fit: the follow-up then at least
    1/``OTHER_UNITS`` of the baseline region's size, and at most ``OTHER_UNITS`` times the
    whole baseline's."""
    room = math.log2(OTHER_UNITS)
    return 2.0 ** (sizes.region - sizes.follow - room), 2.0 ** (sizes.base - sizes.follow + room)


def _check_scale(fitted: float, bounds: tuple[float, float] | None) -> None:
    """Refuse a similarity whose fitted scale ICP held at a bound of ``bounds``: it would
    have gone beyond (a follow-up shrinking onto a point of the baseline lies on it whole)."""
    if not held(fitted, bounds):
        return
    low, high = bounds
    if fitted <= low * (1 + 1e-9):
        what = (
            f"its floor {low:.3g} (the follow-up 1/{OTHER_UNITS:g} of the baseline region's size)"
        )
    else:
        what = f"its ceiling {high:.3g} (the follow-up {OTHER_UNITS:g} times the baseline's size)"
    raise InvalidInput(
        "follow_up",
        f"could not register it: the fitted scale {fitted:.3g} is held at {what}, the bound "
        "ICP keeps it within (beyond it the follow-up would collapse towards a point of the "
        "baseline, or swell past it); give the landmarks of both scans, or a region both show",
    )


def _mismatch(scans: RegionScans, on: OnRegion | None) -> str | None:
    """The size hint of a refusal after an alignment: the follow-up's region against the
    baseline's once found, else the follow-up's whole (``SIZE_MISMATCH``)."""
    if on is None or on.source is None or not scans.target.size > 0:
        return _out_of_scale(_log_sizes(scans), SIZE_MISMATCH)
    ratio = on.source.size / scans.target.size
    if 1 / SIZE_MISMATCH <= ratio <= SIZE_MISMATCH:
        return None
    return f"its part over the baseline's region is {ratio:.3g} times that region's size"


def _unregistered(
    why: str, outside: str | None, similar: bool, landmarks_help: bool = True
) -> InvalidInput:
    """The refusal of a follow-up that could not be registered: ``why``, and what may help
    (``outside``: how its size differs from the baseline's, when it does by far)."""
    hints = ["give the landmarks of both scans, or a region both show"] if landmarks_help else []
    if not similar and outside is not None:
        hints.insert(
            0,
            f"{outside} (its spread about its centroid): if the scans' units or scales "
            "differ, send mode similarity (or the follow-up in the baseline's units)",
        )
    elif not similar:
        hints.append("or mode similarity, if the scans differ in scale")
    return InvalidInput("follow_up", f"could not register it: {why}; {'; '.join(hints)}")


def _follow_boundary(follow: Mesh, over: np.ndarray, frame: Frame, region) -> np.ndarray:
    """(k, 2, 2) float: the boundary edges, on the map, of the follow-up's region (its faces
    ``over`` the baseline's region), flattened with the baseline's frame expressed for the
    follow-up."""
    if not over.any():
        return np.empty((0, 2, 2))
    flat = flatten_region(follow.vertices, follow.faces[over], frame, region.chart,
                          layout=region.flat.layout)  # fmt: skip
    points = np.column_stack([flat.x, flat.y])
    return points[flat.validation.boundary_edges]


def _landmark_pairs(mesh: Mesh, follow: Mesh, params: RegisterParams, unit: float):
    """The landmarks both scans give, follow-up then baseline ((k, 3) each, times ``unit``),
    or None. The baseline's come from params.landmarks.baseline or params.frame."""
    given = params.landmarks
    baseline = given.baseline if given is not None and given.baseline is not None else None
    if baseline is None and params.frame is not None:
        baseline = params.frame.landmarks
    if baseline is None or given is None or given.follow_up is None:
        return None
    base = checked_landmarks(mesh, baseline, "landmarks.baseline").named()
    other = checked_landmarks(follow, given.follow_up, "landmarks.follow_up").named()
    common = [name for name in base if name in other]
    return unit * np.stack([other[n] for n in common]), unit * np.stack([base[n] for n in common])


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
        description="The share of the follow-up's region (its faces over the baseline's "
        "region, as registered) whose area lies within overlap_distance of the baseline's "
        "region after registration (a registration below half is refused)."
    )
    overlap_distance: float = Field(
        description="The distance overlap counts within, mesh units: 2 mm with params.units, "
        "else 1/40 of the baseline region's RMS distance from its centroid."
    )
    overlap_distance_mm: float | None = Field(
        description="The same in mm (2; with params.units, else null)."
    )
    rms: float = Field(
        description="RMS of the residuals (the follow-up's region against the baseline's "
        "region) over the overlap, mesh units."
    )
    p95: float = Field(description="Their 95th percentile, mesh units.")
    rms_mm: float | None = Field(description="rms in mm (with params.units, else null).")
    p95_mm: float | None = Field(description="p95 in mm (with params.units, else null).")
    units: Units | None = Field(description="The scale used; null without params.units.")
    frame: ResolvedParams = Field(
        description="The baseline's frame expressed for the follow-up: sent as the "
        "follow-up's params (method, sigma, center, rotation), its map lands on the "
        "baseline's."
    )

    @classmethod
    def of(cls, registered: Registered) -> RegisterResponse:
        region, found, scale = registered.region, registered.on.found, registered.mm_per_unit
        return cls.build(
            params=ResolvedParams.of_region(region),
            transform=found.matrix,
            scale=found.scale,
            seeded_by=registered.seeded_by,
            overlap=registered.overlap,
            overlap_distance=registered.overlap_distance,
            overlap_distance_mm=in_mm(registered.overlap_distance, scale),
            rms=registered.rms,
            p95=registered.p95,
            rms_mm=in_mm(registered.rms, scale),
            p95_mm=in_mm(registered.p95, scale),
            units=None if scale is None else Units.build(mm_per_unit=scale),
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
        "field: the baseline's region (the part to align on and to measure on: the scalp "
        "changes over time, the face and ears less) and frame as for /v1/flatten, `landmarks` "
        "of either scan, `mode` (rigid or similarity) and, optionally, `units`. Seeded by the "
        "landmarks of both scans when given, else by the scans' moments (their principal axes "
        "in 24 turns, centroids or ends matched, and in similarity mode also scaled to the "
        "scans' spreads; refused when two distinct alignments fit about as well); refined by "
        "small_gicp's point-to-plane ICP over area-weighted samples, trimmed so that a cropped "
        "follow-up still aligns, first on the whole scans, then on the regions: the "
        "follow-up's faces over the baseline's region aligned on that region (docs/math.md, "
        "section 15). In rigid mode a follow-up more than "
        f"{OTHER_UNITS:g} times the whole baseline's size, or less than "
        f"1/{OTHER_UNITS:g} of its region's, is refused at once as in other units; in either "
        f"mode, one beyond {SCALE_RANGE:g} times or 1/{SCALE_RANGE:g}. In similarity mode the "
        f"scale is held where the scaled follow-up is {OTHER_UNITS:g} times the baseline's "
        f"size at most and 1/{OTHER_UNITS:g} of its region's at least, and a fit held at "
        "either bound is refused with the scale and the bound. Answers "
        "the 4x4 transform onto the baseline, the RMS and 95th percentile of the residuals "
        "of the follow-up's region against the baseline's over the overlap (mesh units, and "
        "mm with `units`), the overlap, and the baseline's frame expressed for the follow-up, "
        "so that the follow-up's map lands on the baseline's; refuses (422) when after the "
        f"best alignment less than {MIN_OVERLAP:.0%} of the follow-up's region lies within "
        f"{OVERLAP_MM:g} mm (without `units`, {OVERLAP_SHARE:.3g} of the region's spread) of "
        "the baseline's region, or when the whole scans disagree (less than "
        f"{MIN_OVERLAP:.0%} of the follow-up within it of the baseline and of the baseline of "
        "the follow-up). Or, by the Accept header or params.output, the overlay: the "
        "baseline's map with both regions' boundaries and the zones (SVG or PNG).",
        params=RegisterParams,
        mesh=MeshPart("baseline"),
        extra_parts=(FOLLOW_UP,),
        input=RegisterInput,
        operation=register_scans,
        response=RegisterResponse,
        renderers=RENDERERS,
    ),
)
