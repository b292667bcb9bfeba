"""``POST /v1/compare``: the change between two visits. The follow-up is registered to the
baseline as /v1/register does; values on each scan (one a vertex, or a picture on its own
map) are averaged over zones drawn on the baseline's map and read at spots; each spot is
found again on the follow-up, where to put the trichoscope next time (docs/math.md,
section 22)."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Annotated, Literal

import numpy as np
from pydantic import ConfigDict, Field, model_validator

from transforms import MapTriangles, TransformInputError, cover_zone, flatten_region
from transforms.compare import (
    ZoneMean,
    relative_change,
    values_at,
    zone_mean,
)

from ..encoding import Answer
from ..errors import InvalidInput
from ..meshio import Mesh
from ..outputs import Output
from ..outputs.colours import difference_colouring
from ..outputs.picture import Drawn
from .context import MAP_BYTES_PER_FACE, Context
from .drawn import (
    Outline,
    Zone,
    check_drawn,
    check_names,
    checked_zone,
    warn_outside,
)
from .fields import Coordinate, ValueRange, choice, output_choice
from .inputs import MeshPart, PngFile, PngPart
from .region.answers import ResolvedParams
from .region.params import Region
from .region.pictures import map_renderers
from .region.resolve import MeshInput, map_triangles, select_region
from .register import (
    FOLLOW_UP,
    REGISTER_EXAMPLE,
    Registered,
    RegisterInput,
    RegisterParams,
    register_scans,
)
from .rows import MeshCapability
from .spots import ScanMap, Spot, SpotCompared, SpotFound, find_spots, number_or_none
from .transfer import image_at_vertices, vertex_values
from .units import KnownDistance, LengthUnit, Units, in_cm2, in_mm, mm_per_unit
from .warnings import WarnedAnswer, WarningCode

#: A zone whose share with values on a scan is below this is said (values_missing): more
#: than 1 % missing. Two scans' regions do not end at the same triangle edge, so a zone
#: across the border of the baseline's region misses a sliver of the follow-up's.
FULL_COVERAGE = 0.99

ValueList = Annotated[list[Coordinate], Field(min_length=1, fail_fast=True)]


class CompareParams(RegisterParams):
    """The JSON of the ``params`` field of /v1/compare: the registration's params as for
    /v1/register (the baseline's region and frame, landmarks, mode), the units, zones and
    spots on the baseline's map, and the values of either scan."""

    units: choice(LengthUnit) | KnownDistance = Field(
        description="The baseline's length unit (mm, cm or m), or its scale from a known "
        "distance: the zones' areas in cm², the residuals and the spots' reach in mm."
    )
    zones: Annotated[list[Zone], Field(max_length=256)] = Field(
        [],
        description="Zones drawn on the baseline's map (as for /v1/measure): each scan's "
        "values averaged over each, area-weighted on that scan's surface.",
    )
    spots: Annotated[list[Spot], Field(max_length=1024)] = Field(
        [],
        description="Points on the baseline's map, with the values measured there when "
        "known: each found again on the follow-up.",
    )
    baseline_values: ValueList | str | None = Field(
        None,
        description="Values on the baseline: one a vertex of its file (in its order), or "
        "the name of a per-vertex property of the file; or send a baseline_values PNG part "
        "instead. Each within +-1e15.",
    )
    follow_up_values: ValueList | str | None = Field(
        None,
        description="Values on the follow-up, as baseline_values, for the follow-up's file; "
        "or a follow_up_values PNG part.",
    )
    value_range: ValueRange | None = Field(
        None,
        description="With a values PNG part: the values its black and white stand for "
        "(default [0, 1]), as /v1/transfer's.",
    )
    follow_up_region: Region | None = Field(
        None,
        description="The follow-up's region, in its own file's terms (as region is the "
        "baseline's; no texture_mask): the part whose values count, and with a "
        "follow_up_values PNG the part that picture was drawn for. Default: the follow-up's "
        "faces over the baseline's region, as registered.",
    )
    output: output_choice(
        (Output.JSON, Output.SVG, Output.PNG),
        "json (application/json), svg (image/svg+xml) or png (image/png): the difference "
        "map, the follow-up's values less the baseline's on the baseline's map, with the "
        "zones and spots.",
    ) = None

    @model_validator(mode="after")
    def _something_to_compare(self) -> CompareParams:
        check_names("spots", self.spots)
        if not self.zones and not self.spots:
            raise ValueError("zones, spots: send zones or spots (or both) to compare")
        return self

    model_config = ConfigDict(
        json_schema_extra={
            "examples": [
                {
                    **REGISTER_EXAMPLE,
                    "baseline_values": [float(k) for k in range(12)],
                    "follow_up_values": [1.2 * k for k in range(12)],
                    "spots": [{"name": "crown", "x": 0.0, "y": 0.5}],
                }
            ]
        }
    )


@dataclass(frozen=True)
class CompareInput(RegisterInput):
    """A comparison: the two scans, the params, the baseline's texture mask and the values
    pictures, each on its own scan's map.

    Attributes
    ----------
    baseline_values, follow_up_values : PngFile or None
    """

    baseline_values: PngFile | None = None
    follow_up_values: PngFile | None = None


@dataclass(frozen=True)
class ZoneChange:
    """A zone on both scans: its outline, its area on the baseline's surface (mesh units²)
    and on the map (the layout's units², the part over the baseline's region), and each
    scan's mean over it (None: no values for that scan)."""

    outline: Outline
    area: float
    map_area: float
    baseline: ZoneMean | None
    follow_up: ZoneMean | None


@dataclass(frozen=True)
class Compared:
    """A comparison: the registration, the zones and spots on both scans, and the scans on
    the baseline's map with their values (for the difference map)."""

    registered: Registered
    zones: tuple[ZoneChange, ...]
    spots: tuple[SpotFound, ...]
    base: ScanMap
    follow: ScanMap
    mm_per_unit: float

    @cached_property
    def difference(self) -> np.ndarray | None:
        """(m,) float: the follow-up's values less the baseline's at each baseline region
        face (the mean at its corners, the follow-up's read at the corners' map points in
        its map triangles; NaN where either has none); None without values on both. Found
        when a picture asks for it."""
        base, follow = self.base, self.follow
        if base.values is None or follow.values is None:
            return None
        corners = base.triangles.map_points
        at = values_at(follow.triangles, corners, follow.values)
        return (at - base.values)[base.triangles.faces].mean(axis=1)


def compare(given: CompareInput, ctx: Context) -> Compared:
    """The follow-up registered to the baseline (:func:`.register.register_scans`), each
    scan's values averaged over the zones and read at the spots, the spots found again on
    the follow-up (docs/math.md, section 22)."""
    params = given.params
    _check_sources(given)
    scale = mm_per_unit(params.units)
    listed = {
        "baseline": _listed(given.baseline, params.baseline_values, "baseline_values"),
        "follow_up": _listed(given.follow_up, params.follow_up_values, "follow_up_values"),
    }
    check_drawn(ctx, params.zones)
    registered = register_scans(given, ctx)
    region = registered.region
    x, y = region.layout
    base = ScanMap(
        map_triangles(region, ctx),
        _values(listed["baseline"], given.baseline_values, region.flat, (x, y), params, ctx),
    )
    follow = _follow_map(given, registered, listed["follow_up"], ctx)
    zones = tuple(
        _zone(ctx, registered, base, follow, zone, k) for k, zone in enumerate(params.zones)
    )
    spots = find_spots(ctx, given, registered, base, follow, scale)
    return Compared(registered, zones, spots, base, follow, scale)


def _check_sources(given: CompareInput) -> None:
    """Refuse values given twice for one scan, a follow-up picture without the region it
    was drawn for, and a value_range without a picture."""
    params = given.params
    if params.follow_up_region is not None and params.follow_up_region.texture_mask is not None:
        raise InvalidInput(
            "follow_up_region.texture_mask",
            "the mask part is the baseline's; give the follow-up's region by faces, groups, "
            "a cone, landmarks or vertex colours",
        )
    for name in ("baseline_values", "follow_up_values"):
        if getattr(given, name) is not None and getattr(params, name) is not None:
            raise InvalidInput(name, f"send the {name} part or params.{name}, not both")
    if given.follow_up_values is not None and params.follow_up_region is None:
        raise InvalidInput(
            "follow_up_region",
            "a follow_up_values picture is read on the grid /v1/transfer gives the follow-up "
            "with the registration's frame and a region of the follow-up: send that region "
            "as params.follow_up_region",
        )
    pictures = given.baseline_values is not None or given.follow_up_values is not None
    if params.value_range is not None and not pictures:
        raise InvalidInput(
            "value_range", "it says what a values picture's grey stands for; no picture was sent"
        )


def _listed(mesh: Mesh, values, field: str) -> np.ndarray | None:
    """(n,) float: values listed in params, one a vertex of ``mesh``; None without."""
    return None if values is None else vertex_values(mesh, values, field)


def _values(listed, picture: PngFile | None, flat, layout, params, ctx: Context):
    """(k,) float: a scan's values at its region's vertices (``flat.vertex_ids``), from the
    list or the picture; None without either."""
    if listed is not None:
        return listed[flat.vertex_ids]
    if picture is None:
        return None
    image = picture.read(params, ctx)
    return image_at_vertices(flat, layout, image, params.value_range, ctx)


def _follow_map(given: CompareInput, registered: Registered, listed, ctx: Context) -> ScanMap:
    """The follow-up's region (params.follow_up_region, else its faces over the baseline's
    region) flattened with the baseline's frame expressed for it, with its values."""
    follow, params, region = given.follow_up, given.params, registered.region
    if params.follow_up_region is None:
        faces = np.flatnonzero(registered.on.faces)
    else:
        faces = _follow_region(follow, params, ctx)
    ctx.charge(MAP_BYTES_PER_FACE * len(faces))
    flat = flatten_region(follow.vertices, follow.faces[faces], registered.frame, region.chart,
                          threads=ctx.threads, layout=region.flat.layout)  # fmt: skip
    front = flat.layout.front_orientation(flat.validation.winding)
    triangles = MapTriangles.of(flat.x, flat.y, follow.vertices[flat.vertex_ids], flat.faces, front)
    values = _values(listed, given.follow_up_values, flat, (flat.x, flat.y), params, ctx)
    return ScanMap(triangles, values)


def _follow_region(follow: Mesh, params: CompareParams, ctx: Context) -> np.ndarray:
    """(m,) int: the follow-up's file face ids of params.follow_up_region; its errors name
    that field."""
    own = params.model_copy(update={"region": params.follow_up_region, "center": "bbox_center"})
    try:
        return select_region(MeshInput(follow, own), ctx).faces
    except TransformInputError as error:
        field = error.field if error.field.startswith("follow_up") else f"follow_up_{error.field}"
        raise TransformInputError(field, error.message, error.indices) from None


def _zone(ctx, registered: Registered, base: ScanMap, follow: ScanMap, zone, k: int) -> ZoneChange:
    """A zone's area on the baseline and its mean on each scan with values; said when it
    misses the map, or when part of it has no values on a scan."""
    outline = checked_zone(zone, k)
    cover = cover_zone(base.triangles, outline.rings)
    area = cover.total(base.triangles.surface_area)
    if area == 0:  # the same words as /v1/register's for a zone beside the map's box
        warn_outside(ctx, registered.region, f"zones.{k}", outline.name, outline.rings[0])
    means = {}
    for name, scan in (("baseline", base), ("follow_up", follow)):
        if scan.values is None:
            means[name] = None
            continue
        own = cover if scan is base else cover_zone(scan.triangles, outline.rings)
        means[name] = zone_mean(scan.triangles, own, scan.values)
    on_map = cover.total(np.abs(base.triangles.signed_map_area))
    change = ZoneChange(outline, area, on_map, means["baseline"], means["follow_up"])
    _warn_of_gaps(ctx, change, k)
    return change


def coverage(change: ZoneChange) -> tuple[float | None, float | None]:
    """The share of the zone's part on the baseline's map that has values on each scan
    (None: no values for it): both on the map, where a noisier surface has no more area."""
    whole = change.map_area
    shares = []
    for mean in (change.baseline, change.follow_up):
        if mean is None:
            shares.append(None)
        else:
            shares.append(min(1.0, mean.valued_map_area / whole) if whole > 0 else 0.0)
    return shares[0], shares[1]


def _warn_of_gaps(ctx: Context, change: ZoneChange, k: int) -> None:
    """The ``values_missing`` warning for a zone part of which has no values on a scan."""
    shares = coverage(change)
    gaps = [
        f"{scan} {share:.1%}"
        for scan, share in zip(("baseline", "follow-up"), shares, strict=True)
        if share is not None and share < FULL_COVERAGE
    ]
    if not gaps or change.area == 0:
        return
    ctx.warn(
        WarningCode.VALUES_MISSING,
        f"zones.{k}",
        f"the zone {change.outline.name!r} has values on only part of its area on the "
        f"baseline's map ({', '.join(gaps)}): the means are over the parts with values; a "
        "follow-up cropped there, a zone beyond a scan's region or a picture transparent "
        "there leaves the rest out",
    )


class ZoneCompared(Answer):
    name: str
    area_cm2: float = Field(
        description="The zone's area on the baseline's surface, cm² (as /v1/measure's)."
    )
    baseline: float | None = Field(
        description="The baseline's values averaged over the zone, area-weighted on its "
        "surface, linear inside each triangle; null without baseline values or where the "
        "zone has none."
    )
    follow_up: float | None = Field(description="The same on the follow-up's surface.")
    change: float | None = Field(description="follow_up - baseline.")
    change_percent: float | None = Field(
        description="100 x change / |baseline|; null where baseline is 0 or null."
    )
    baseline_coverage: float | None = Field(
        description="The share of the zone's part on the baseline's map that has baseline "
        "values (1: all); null without baseline values."
    )
    follow_up_coverage: float | None = Field(
        description="The share of that part the follow-up covers with values (below 1: "
        "cropped there, off its region, or a picture transparent there: said in warnings)."
    )

    @classmethod
    def of(cls, change: ZoneChange, mm_per_unit: float) -> ZoneCompared:
        base, follow = (None if m is None else m.mean for m in (change.baseline, change.follow_up))
        both = base is not None and follow is not None
        difference, percent = relative_change(base, follow) if both else (np.nan, np.nan)
        shares = coverage(change)
        return cls.build(
            name=change.outline.name,
            area_cm2=in_cm2(change.area, mm_per_unit),
            baseline=number_or_none(base),
            follow_up=number_or_none(follow),
            change=number_or_none(difference),
            change_percent=number_or_none(percent),
            baseline_coverage=shares[0],
            follow_up_coverage=shares[1],
        )


class CompareRegistration(Answer):
    transform: list[list[float]] = Field(
        description="The 4x4 matrix (rows) that maps the follow-up's points onto the "
        "baseline, as /v1/register's."
    )
    scale: float = Field(description="Its scale: 1 for rigid.")
    seeded_by: Literal["landmarks", "moments"] = Field(
        description="What the registration started from, as /v1/register's."
    )
    overlap: float = Field(description="As /v1/register's.")
    rms_mm: float = Field(description="As /v1/register's.")
    p95_mm: float = Field(description="As /v1/register's.")
    frame: ResolvedParams = Field(
        description="The baseline's frame expressed for the follow-up: the follow-up's map "
        "(follow_up_x, follow_up_y; the grid of a follow_up_values picture)."
    )


class CompareResponse(WarnedAnswer):
    params: ResolvedParams = Field(description="The baseline's params, resolved.")
    units: Units = Field(description="The scale used.")
    registration: CompareRegistration
    zones: list[ZoneCompared] = Field(description="The zones, in the order given.")
    spots: list[SpotCompared] = Field(description="The spots, in the order given.")

    @classmethod
    def of(cls, compared: Compared) -> CompareResponse:
        registered, scale = compared.registered, compared.mm_per_unit
        found = registered.on.found
        return cls.build(
            params=ResolvedParams.of_region(registered.region),
            units=Units.build(mm_per_unit=scale),
            registration=CompareRegistration.build(
                transform=found.matrix,
                scale=found.scale,
                seeded_by=registered.seeded_by,
                overlap=registered.overlap,
                rms_mm=in_mm(registered.rms, scale),
                p95_mm=in_mm(registered.p95, scale),
                frame=ResolvedParams.of(registered.region.chart, registered.frame),
            ),
            zones=[ZoneCompared.of(zone, scale) for zone in compared.zones],
            spots=[SpotCompared.of(spot) for spot in compared.spots],
        )


def _drawn(compared: Compared) -> tuple[Drawn, ...]:
    """Each zone labelled with its change on the map, and with its area in the legend."""
    drawn = []
    for zone in compared.zones:
        answer = ZoneCompared.of(zone, compared.mm_per_unit)
        percent = answer.change_percent
        change = "no change measured" if percent is None else _percent(percent)
        words = f"{answer.area_cm2:.2f} cm², {change}"
        drawn.append(Drawn(zone.outline.rings, True, zone.outline.name, words, label=change))
    return tuple(drawn)


def _percent(value: float) -> str:
    """A change as a label says it: signed, one decimal, no "-0.0"."""
    return "0.0 %" if round(value, 1) == 0 else f"{value:+.1f} %"


def _spot_points(compared: Compared) -> np.ndarray | None:
    """(s, 2): the spots on the baseline's map, or None without any."""
    if not compared.spots:
        return None
    return np.array([[found.spot.x, found.spot.y] for found in compared.spots])


def headline(compared: Compared) -> str:
    """The picture's caption line: what it shows and the registration's residuals."""
    registered = compared.registered
    rms = in_mm(registered.rms, compared.mm_per_unit)
    what = (
        "follow-up minus baseline"
        if compared.difference is not None
        else "zones and spots (no values on both scans: no difference drawn)"
    )
    return f"meshflat compare: {what}; registration RMS {rms:.3g} mm over {registered.overlap:.0%}"


#: The forms of a comparison besides JSON, by :class:`Output`: the difference map on the
#: baseline's map (a diverging scale about 0), with the zones and spots.
RENDERERS = map_renderers(
    lambda compared: compared.registered.region,
    _drawn,
    sites_of=_spot_points,
    headline_of=headline,
    colouring_of=lambda compared: (
        None if compared.difference is None else difference_colouring(compared.difference)
    ),
    dots="spots",
)


#: The values pictures, each on its own scan's map.
BASELINE_VALUES = PngPart(
    "baseline_values",
    "Values on the baseline as a PNG on the grid /v1/transfer gives the baseline with these "
    "params (image_width by image_height; 8- or 16-bit grey, or colour read as its "
    "luminance; the alpha as coverage), black and white standing for value_range.",
    framed=True,
)
FOLLOW_UP_VALUES = PngPart(
    "follow_up_values",
    "Values on the follow-up as a PNG on the grid /v1/transfer gives the follow-up with the "
    "registration's frame and params.follow_up_region (which it then needs).",
    framed=True,
)

ROWS = (
    MeshCapability(
        name="compare",
        path="/v1/compare",
        summary="Compare two visits: change over zones and at spots",
        description="Multipart: the `baseline` and `follow_up` meshes, optional "
        "`baseline_values` and `follow_up_values` PNG parts, and a `params` JSON field: the "
        "registration's params as for /v1/register (the baseline's region and frame, "
        "`landmarks`, `mode`), `units` (required), `zones` drawn on the baseline's map (as "
        "/v1/measure's) and `spots` ({name, x, y} on that map, with `baseline` and "
        "`follow_up` values when measured); the values of each scan as a list a vertex of its "
        "file (or a per-vertex property's name) in `baseline_values` and `follow_up_values`, "
        "or as the PNG parts of those names, each on its own scan's map (the grid of "
        "/v1/transfer; for the follow-up, with the registration's frame and "
        "`follow_up_region`). The follow-up is registered as /v1/register does (refused "
        "alike when it does not register). Answers, per zone in the order given, its area "
        "on the baseline (cm²), each scan's values averaged over it (area-weighted on that "
        "scan's surface, linear inside its triangles), the change and its percentage, and "
        "the share of the zone each scan has values on (a zone a cropped follow-up misses "
        "in part is said in warnings, never filled in); per spot, its position on the "
        "baseline, the same spot found on the follow-up (the nearest surface point to where "
        "the registration puts it) and its place on the follow-up's map, where to put the "
        "trichoscope next time, with the values' change; and the registration (transform, "
        "rms_mm, p95_mm, overlap, the follow-up's frame) (docs/math.md, section 22). Or, by "
        "the Accept header or params.output, the difference map on the baseline's map with "
        "the zones and spots (SVG or PNG).",
        params=CompareParams,
        mesh=MeshPart("baseline"),
        extra_parts=(FOLLOW_UP, BASELINE_VALUES, FOLLOW_UP_VALUES),
        input=CompareInput,
        operation=compare,
        response=CompareResponse,
        renderers=RENDERERS,
    ),
)
