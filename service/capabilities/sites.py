"""``POST /v1/sites``: sites (grafts) placed on the region at a density, one for the region
or one per zone drawn on the map, or from a density map: Poisson-disk samples of the surface
with their normals, face ids and map points (docs/math.md, section 13)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

import numpy as np
from pydantic import ConfigDict, Field, model_validator

from transforms import MapTriangles, world_to_angles
from transforms.region import flagged_mask
from transforms.sites import (
    SPACING_RULE,
    SitePart,
    Sites,
    SitesDoNotFit,
    minimum_distance,
    place_sites,
    site_normals,
)

from ..encoding import Answer
from ..errors import InvalidInput, check_count
from ..outputs import Output
from ..outputs.picture import Drawn
from .context import GROWTH_BYTES, GROWTH_BYTES_PER_SITE, SITE_BYTES, Context
from .drawn import (
    Outline,
    Zone,
    check_drawn,
    check_names,
    checked_zone,
    overlaps,
    warn_outside,
)
from .fields import PictureParams, choice, output_choice
from .growth import (
    ExitAngle,
    Grown,
    Growth,
    GrowthAnswer,
    SitesAt,
    check_growth,
    grow,
    growth_answer,
    growth_drawn,
    growth_lines,
    site_growth,
    zone_growth,
)
from .inputs import PngFile, PngPart
from .region.answers import ResolvedParams
from .region.params import MESH_PARAMS_EXAMPLE, MeshParams
from .region.pictures import glb, map_renderers
from .region.resolve import MeshInput, MeshRegion, flatten, map_triangles
from .rows import MeshCapability
from .scalp import warn_implausible
from .siteparts import SiteZoneResult, density_map_part, part_quotas, zone_parts
from .units import KnownDistance, LengthUnit, Units, in_cm2, mm_per_unit, warn_of_size
from .warnings import WarnedAnswer

#: Sites per cm² a density may ask for (a site every 0.1 mm or so).
MAX_DENSITY_PER_CM2 = 10_000.0
DensityPerCm2 = Annotated[float, Field(allow_inf_nan=False, gt=0, le=MAX_DENSITY_PER_CM2)]
#: The spacing asked for, millimetres: a micron to a kilometre, so that in any unit the mesh
#: may have (1e-3 to 1e6 mm a unit, units.MM_PER_UNIT) the sites a unit² it allows
#: stay finite (1e-300 overflowed them; 1e300, its square).
MIN_SPACING_MM = (1e-3, 1e6)
SpacingMm = Annotated[float, Field(allow_inf_nan=False, ge=MIN_SPACING_MM[0], le=MIN_SPACING_MM[1])]


class SiteZone(Zone):
    """A zone drawn on the map (as for /v1/measure) and the density of sites in it."""

    density_per_cm2: DensityPerCm2 | None = Field(
        None, description="Sites per cm² of the zone's surface (default: params.density_per_cm2)."
    )
    exit_angle_deg: ExitAngle | None = Field(
        None,
        description="With params.growth: the angle between the hair and the scalp in this "
        "zone, degrees (default: growth.exit_angle_deg).",
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
    min_spacing_mm: SpacingMm | None = Field(
        None,
        description="No two sites closer than this in 3D, millimetres: a micron to a "
        "kilometre. Default: 0.7 / sqrt(density) in each zone, at the density placed "
        "(docs/math.md, section 13).",
    )
    density_range: Annotated[list[Annotated[float, Field(ge=0, le=MAX_DENSITY_PER_CM2)]],
                             Field(min_length=2, max_length=2)] | None = Field(
        None,
        description="With a density_map part: the sites per cm² its grey values 0 and 255 "
        "stand for, [lo, hi] (linear between).",
    )  # fmt: skip
    seed: int = Field(0, ge=0, le=2**63 - 1, description="Same inputs and seed: same sites.")
    growth: Growth | None = Field(
        None,
        description="Which way the hair grows (docs/math.md, section 19): flow curves and "
        "whorls drawn on the map, and the exit angle; each site then has its direction. "
        "Without flow or whorls, the head's landmarks (params.frame or region.scalp) give the "
        "default: a whorl at the vertex, turning clockwise.",
    )
    allow_flagged: bool = Field(
        False,
        description="Whether sites may go on triangles the validation flags (stretched "
        "triangles are open either way: the map is one to one there).",
    )
    output: output_choice(
        (Output.JSON, Output.PLY, Output.GLB, Output.SVG, Output.PNG),
        "json (application/json); ply (application/ply: a point cloud with normals and face "
        "ids); glb (model/gltf-binary: the region mesh and a POINTS primitive of the sites); "
        "svg (image/svg+xml) or png (image/png): the map with the sites and the zones.",
    ) = None

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


@dataclass(frozen=True)
class Placed:
    """Sites placed on a region (docs/math.md, section 13).

    Attributes
    ----------
    region : MeshRegion
    triangles : MapTriangles
    sites : Sites, positions in the region's faces, barycentric weights, points, parts
    normals : (n, 3) float, unit: the region's vertex normals interpolated
    map_points : (n, 2) float, the layout's x, y (the correspondence of section 12)
    theta, phi : (n,) float, the transform of the points
    zones : tuple of SiteZoneResult, in the order of ``sites.part``
    min_distance : float, the smallest distance between two sites, measured
    mm_per_unit : float
    grown : Grown or None, each site's growth (with ``params.growth``)
    """

    region: MeshRegion
    triangles: MapTriangles
    sites: Sites
    normals: np.ndarray
    map_points: np.ndarray
    theta: np.ndarray
    phi: np.ndarray
    zones: tuple[SiteZoneResult, ...]
    min_distance: float
    mm_per_unit: float
    grown: Grown | None = None


@dataclass(frozen=True)
class SitesInput(MeshInput[SitesParams]):
    """A sites request: the mesh, the params, the mask and the ``density_map`` part."""

    density_map: PngFile | None = None


def place(given: SitesInput, ctx: Context) -> Placed:
    """Sites on the region of ``params`` at its densities (:func:`transforms.sites.place_sites`):
    the count of each zone its area times its density (or shares of ``count``), spaced at
    least ``min_spacing_mm`` and the default rule's spacing apart."""
    params = given.params
    scale = mm_per_unit(params.units)
    if scale is None:
        raise InvalidInput(
            "units",
            "sites per cm² need the mesh's length unit (mm, cm or m) or a known distance",
        )
    check_drawn(ctx, params.zones)
    flows = check_growth(ctx, params.growth, params.zones) if params.growth else []
    outlines = _apart([checked_zone(zone, k) for k, zone in enumerate(params.zones)])
    image = _density_image(params, given.density_map, ctx)
    region = flatten(given, ctx)
    triangles = map_triangles(region, ctx)
    # Stretched faces stay open: their map is one to one, sites on them are where it says.
    flagged = flagged_mask(region.flat.validation, len(triangles), stretched=False)
    open_faces = ~flagged | params.allow_flagged
    if image is not None:
        found = [density_map_part(region, triangles, image, open_faces)]
    else:
        found = list(zone_parts(triangles, params, outlines, open_faces))
    unit_area = in_cm2(1.0, scale)  # cm² per mesh unit²
    expected = [float(np.dot(part.core.area, part.core.density)) * unit_area for part in found]
    total = params.count if params.count is not None else sum(expected)
    # A unit that inflates the count is named in the refusal, as in the warning.
    size = warn_of_size(ctx, params.units, scale, region)
    check_count(round(total), ctx.settings.max_sites, "sites", "MESHFLAT_MAX_SITES", size or "")
    _warn_outside(ctx, region, outlines, found)
    quotas = part_quotas(expected, params.count)
    ctx.charge(SITE_BYTES * sum(quotas))
    asked = None if params.min_spacing_mm is None else params.min_spacing_mm / scale
    parts, results = [], []
    for part, quota, count in zip(found, quotas, expected, strict=True):
        # The density placed: as asked, scaled to the quota (a count, or rounding).
        placed = part.core.density * unit_area * (quota / count if count > 0 else 0.0)
        if asked is None:  # the default rule (13.1) at the density placed
            with np.errstate(divide="ignore"):
                spacing = SPACING_RULE / np.sqrt(placed)
            spacing[placed == 0] = 1.0  # no site goes there
        else:
            spacing = np.full_like(placed, asked)
        parts.append(part.sites(quota, spacing))
        least = float(spacing[placed > 0].min()) if quota and (placed > 0).any() else None
        results.append(part.result(quota, least, unit_area))
    warn_implausible(ctx, params, results, scale)
    sites = _placed(triangles, parts, params, scale)
    normals = site_normals(triangles.surface_points, triangles.faces, sites, region.frame.center)
    map_points = triangles.on_map(sites.triangles, sites.weights)
    theta, phi, _ = world_to_angles(sites.points, region.frame, region.chart)
    grown = None
    if params.growth is not None:
        ctx.charge(GROWTH_BYTES + GROWTH_BYTES_PER_SITE * len(sites.triangles))
        at = SitesAt(sites, normals, map_points, _exit_angles(params, len(results)),
                     [zone.spacing for zone in results])  # fmt: skip
        grown = grow(ctx, params, flows, region, triangles, at)
    return Placed(
        region, triangles, sites, normals, map_points, theta, phi, tuple(results),
        minimum_distance(sites.points), scale, grown,
    )  # fmt: skip


def _exit_angles(params: SitesParams, parts: int) -> list[float]:
    """Each part's exit angle: its zone's, else growth's."""
    default = params.growth.exit_angle_deg
    if not params.zones:
        return [default] * parts
    return [default if z.exit_angle_deg is None else z.exit_angle_deg for z in params.zones]


def _warn_outside(ctx: Context, region: MeshRegion, outlines: list[Outline], found) -> None:
    """Warn of each zone that covers none of the map (no surface area)."""
    for k, (outline, part) in enumerate(zip(outlines, found, strict=False)):
        if part.area == 0:
            warn_outside(ctx, region, f"zones.{k}", outline.name, outline.rings[0])


def _apart(outlines: list[Outline]) -> list[Outline]:
    """The zones, refused when two overlap (a site's density would be ambiguous there)."""
    for pair in overlaps(outlines):
        raise InvalidInput(
            f"zones.{pair.j}",
            "a site's density would be ambiguous there",
            name=outlines[pair.j].name,
            about=f" overlaps params.zones.{pair.i} ({outlines[pair.i].name!r})",
        )
    return outlines


def _placed(triangles: MapTriangles, parts: list[SitePart], params: SitesParams, mm_per_unit):
    """:func:`transforms.sites.place_sites` with the seed; a part too full is refused, naming
    the parameter that asked for too many."""
    try:
        return place_sites(
            triangles.surface_points, triangles.faces, parts, np.random.default_rng(params.seed)
        )
    except SitesDoNotFit as error:
        if params.min_spacing_mm is not None:
            field = "min_spacing_mm"
        elif params.density_range is not None:
            field = "density_range"
        elif params.zones:
            field = f"zones.{error.part}"
        else:
            field = "density_per_cm2"
        raise InvalidInput(
            field,
            f"{error.words}, at a spacing of {error.spacing * mm_per_unit:.4g} mm; ask for "
            "fewer sites (count, density) or a smaller min_spacing_mm",
            name=error.name,
        ) from None


def _density_image(
    params: SitesParams, density_map: PngFile | None, ctx: Context
) -> np.ndarray | None:
    """(h, w) float: the density_map part's sites per cm² (grey 0-255 to density_range), or
    None without density_range.

    Raises
    ------
    InvalidInput
        A map without density_range, density_range without a map, or a map that is not an
        8-bit grey PNG of the PNG answer's size.
    """
    if params.density_range is None:
        if density_map is not None:
            raise InvalidInput(
                "density_map", "a density map needs params.density_range, and no zones or density"
            )
        return None
    if density_map is None:
        raise InvalidInput(
            "density_map",
            "density_range needs the map: a multipart part 'density_map', a grey PNG",
        )
    low, high = params.density_range
    return low + (high - low) * density_map.read(params, ctx).values


class SiteArrays(Answer):
    position: list[list[float]] = Field(description="World points [x, y, z] on the surface.")
    normal: list[list[float]] = Field(
        description="Unit normals: the region's vertex normals (each the sum of its faces' "
        "normals weighted by area) interpolated with the barycentric weights, pointing away "
        "from the frame's centre."
    )
    face: list[int] = Field(description="The file's id of the triangle each site is on.")
    barycentric: list[list[float]] = Field(
        description="Weights of the triangle's corners (in the file's order), in [0, 1] and "
        "summing to 1: position is their combination of the corners."
    )
    theta: list[float] = Field(description="The transform of position: polar angle, radians.")
    phi: list[float] = Field(description="The transform of position: azimuth, radians.")
    x: list[float] = Field(
        description="The layout's x of the site: the same weights of the triangle's corners "
        "on the map (the correspondence of /v1/measure)."
    )
    y: list[float] = Field(description="The layout's y, likewise.")
    direction: list[list[float]] | None = Field(
        None,
        description="With params.growth: the unit vector the hair grows along, cos(a) tangent "
        "+ sin(a) normal, a the exit angle.",
    )
    tangent: list[list[float]] | None = Field(
        None,
        description="With params.growth: the growth field's unit tangent at the site, "
        "orthogonal to normal.",
    )
    exit_angle_deg: list[float] | None = Field(
        None, description="With params.growth: the angle a between direction and the scalp."
    )
    map_direction: list[list[float]] | None = Field(
        None, description="With params.growth: the unit 2D direction of tangent on the map."
    )


class ZoneSites(Answer):
    name: str = Field(description="The zone's name; 'region' for density_per_cm2.")
    area_cm2: float = Field(description="The zone's surface area, cm² (as /v1/measure's).")
    open_area_cm2: float = Field(
        description="The part of it sites may go on: without the triangles the validation "
        "flags (other than stretched), unless allow_flagged."
    )
    density_per_cm2: float = Field(description="The density asked for.")
    sites: int = Field(description="Sites placed in the zone.")
    achieved_density_per_cm2: float = Field(
        description="sites / open_area_cm2: the density asked for, to a site's rounding (or "
        "scaled to params.count)."
    )
    spacing_mm: float | None = Field(
        description="The least distance kept between the zone's sites and any other site "
        "(zones are placed densest first, each keeping its own spacing); null without sites."
    )
    exit_angle_deg: float | None = Field(
        None, description="With params.growth: the mean exit angle of the zone's sites."
    )
    largest_turn_deg: float | None = Field(
        None,
        description="With params.growth: the largest angle between the directions of two "
        "of the zone's sites within two spacings (null for fewer than two): how smooth the "
        "directions are (a whorl turns them sharply about its centre).",
    )


class SitesResponse(WarnedAnswer):
    params: ResolvedParams
    units: Units = Field(description="The scale used.")
    count: int = Field(description="Sites placed.")
    zones: list[ZoneSites]
    min_distance: float | None = Field(
        description="The smallest 3D distance between two sites, measured, mesh units (null "
        "for fewer than two)."
    )
    min_distance_mm: float | None = Field(description="The same in mm.")
    growth: GrowthAnswer | None = Field(None, description="With params.growth: what was used.")
    sites: SiteArrays

    @classmethod
    def of(cls, placed: Placed) -> SitesResponse:
        scale, sites = placed.mm_per_unit, placed.sites
        closest = None if not np.isfinite(placed.min_distance) else placed.min_distance
        return cls.build(
            params=ResolvedParams.of_region(placed.region),
            units=Units.build(mm_per_unit=scale),
            count=len(sites.triangles),
            zones=[
                ZoneSites.build(
                    name=zone.name,
                    area_cm2=in_cm2(zone.area, scale),
                    open_area_cm2=in_cm2(zone.open_area, scale),
                    density_per_cm2=zone.density_per_cm2,
                    sites=zone.quota,
                    achieved_density_per_cm2=zone.achieved,
                    spacing_mm=None if zone.spacing is None else zone.spacing * scale,
                    **zone_growth(placed.grown, k),
                )
                for k, zone in enumerate(placed.zones)
            ],
            min_distance=closest,
            min_distance_mm=None if closest is None else closest * scale,
            **({} if placed.grown is None else {"growth": growth_answer(placed.grown)}),
            sites=SiteArrays.build(
                position=sites.points,
                normal=placed.normals,
                face=placed.region.faces[sites.triangles],
                barycentric=sites.weights,
                theta=placed.theta,
                phi=placed.phi,
                x=np.ascontiguousarray(placed.map_points[:, 0]),
                y=np.ascontiguousarray(placed.map_points[:, 1]),
                **site_growth(placed.grown),
            ),
        )


def sites_ply(placed: Placed, params: SitesParams, ctx: Context) -> bytes:
    """The sites as a binary PLY point cloud: ``x y z`` (double), ``nx ny nz`` (float, unit
    normals), with ``params.growth`` ``dx dy dz`` (float, the unit growth direction), and
    ``face`` (int, the file's triangle id) per vertex."""
    sites = placed.sites
    vectors = [("n", placed.normals)]
    if placed.grown is not None:
        vectors.append(("d", placed.grown.direction))
    columns = [("x", "<f8"), ("y", "<f8"), ("z", "<f8")]
    columns += [(f"{prefix}{axis}", "<f4") for prefix, _ in vectors for axis in "xyz"]
    table = np.empty(len(sites.triangles), dtype=np.dtype([*columns, ("face", "<i4")]))
    for k, axis in enumerate("xyz"):
        table[axis] = sites.points[:, k]
        for prefix, values in vectors:
            table[f"{prefix}{axis}"] = values[:, k]
    table["face"] = placed.region.faces[sites.triangles]
    properties = "".join(
        f"property {'double' if kind == '<f8' else 'float'} {name}\n" for name, kind in columns
    )
    header = (
        "ply\nformat binary_little_endian 1.0\ncomment meshflat sites\n"
        f"element vertex {len(table)}\n{properties}property int face\nend_header\n"
    )
    return header.encode("ascii") + table.tobytes()


def sites_glb(placed: Placed, params: SitesParams, ctx: Context) -> bytes:
    """The region as /v1/flatten's GLB, with the sites as a POINTS primitive (none when no
    site was placed: glTF has no empty accessors) and, with growth, a LINES primitive of a
    short stroke from each site along its direction, coloured by its exit angle."""
    sites = (placed.sites.points, placed.normals) if len(placed.sites.points) else None
    lines = None
    if placed.grown is not None and sites is not None:
        lines = growth_lines(placed.grown, placed.sites.points, placed.mm_per_unit)
    return glb(placed.region, params, sites, lines)


def _site_zones(placed: Placed) -> tuple[Drawn, ...]:
    zones = tuple(
        Drawn(zone.outline.rings, True, zone.name, f"{zone.quota:,} sites")
        for zone in placed.zones
        if zone.outline is not None
    )
    if placed.grown is None:
        return zones
    return zones + growth_drawn(placed.grown, placed.triangles)


#: The forms of placed sites besides JSON, by :class:`Output`.
RENDERERS = {
    Output.PLY: sites_ply,
    Output.GLB: sites_glb,
    # The map with the zones and the sites (an SVG draws up to SVG_SITES of them).
    **map_renderers(
        lambda placed: placed.region,
        _site_zones,
        lambda placed: placed.map_points,
        lambda placed: None if placed.grown is None else placed.grown.map_direction,
    ),
}


#: The density map: a grey PNG on the PNG answer's grid.
DENSITY_MAP = PngPart(
    "density_map",
    "A grey PNG (8 bits) in the framing of the PNG answer: image_width by image_height "
    "pixels, the map where the PNG answer draws it. Each region triangle takes the density of "
    "the pixel under its centroid on the map: params.density_range maps grey 0-255 to sites "
    "per cm².",
    framed=True,
    grey_only=True,
)

ROWS = (
    MeshCapability(
        name="sites",
        path="/v1/sites",
        summary="Place sites (grafts) on the region at a density",
        description="Multipart like /v1/measure; `params` also holds the density, "
        "`density_per_cm2` for the whole region or `zones` (as /v1/measure's, not "
        "overlapping) each with its own, and `units` (required: densities are per cm²). "
        "Sites are Poisson-disk samples of the surface (random sequential adsorption, "
        "docs/math.md section 13): each zone gets its area times its density, rounded (or, "
        "with `count`, its share of that exact total), no two sites closer than "
        "`min_spacing_mm` or the default rule's 0.7 / sqrt(density), across triangle and zone "
        "borders; none on flagged triangles unless `allow_flagged`; the same `seed`, the same "
        "sites, in any pose of the mesh. Answers the sites (position, unit normal, face id, "
        "barycentric weights, theta and phi, and the layout's x and y), the count, per zone "
        "its area, sites and achieved density, and the smallest distance between two sites, "
        "measured. Or, by the Accept header or params.output: a PLY point cloud with normals "
        "and face ids, the region's GLB with the sites as a POINTS primitive, or the map with "
        "the sites and zones (SVG or PNG).",
        params=SitesParams,
        extra_parts=(DENSITY_MAP,),
        input=SitesInput,
        operation=place,
        response=SitesResponse,
        renderers=RENDERERS,
    ),
)
