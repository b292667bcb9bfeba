"""``POST /v1/measure``: zones and curves drawn on the map, measured on the surface: areas,
perimeters, lengths, the triangles inside and cut, and the overlaps of zones (docs/math.md,
section 12)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

import numpy as np
from pydantic import ConfigDict, Field, model_validator

from transforms import (
    MapTriangles,
    Polyline,
    ZoneCover,
    cover_zone,
    lift_curve,
)
from transforms.region import flagged_mask

from ..encoding import Answer
from ..outputs import Output
from ..outputs.picture import Drawn
from .context import Context
from .drawn import (
    Curve,
    Outline,
    Zone,
    charge_crossings,
    check_drawn,
    check_names,
    checked_curve,
    checked_zone,
    overlaps,
    shared_areas,
    warn_outside,
)
from .fields import PictureParams, choice, output_choice
from .region.answers import ResolvedParams
from .region.params import MESH_PARAMS_EXAMPLE, MeshParams
from .region.pictures import map_renderers
from .region.resolve import MeshInput, MeshRegion, flatten, map_triangles
from .rows import MeshCapability
from .units import (
    KnownDistance,
    LengthUnit,
    Units,
    area_text,
    in_cm2,
    in_mm,
    length_text,
    mm_per_unit,
    warn_of_size,
)
from .warnings import WarnedAnswer


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


@dataclass(frozen=True)
class Measured:
    """What was drawn on a region's map, measured on its surface.

    Attributes
    ----------
    region : MeshRegion, the region flattened
    triangles : MapTriangles, its map and surface
    flagged : (m,) bool, the region's faces the validation flags
    zones : tuple of (Outline, ZoneCover)
    curves : tuple of (name, Polyline)
    overlaps : tuple of (i, j, area): the surface area zones i and j share
    mm_per_unit : float or None, from params.units
    """

    region: MeshRegion
    triangles: MapTriangles
    flagged: np.ndarray
    zones: tuple[tuple[Outline, ZoneCover], ...]
    curves: tuple[tuple[str, Polyline], ...]
    overlaps: tuple[tuple[int, int, float], ...]
    mm_per_unit: float | None


def measure(given: MeshInput[MeasureParams], ctx: Context) -> Measured:
    """The zones and curves of ``params``, drawn on the map of the region it names, measured
    on the surface (:func:`transforms.cover_zone`, :func:`transforms.lift_curve`)."""
    params = given.params
    check_drawn(ctx, params.zones, params.curves)
    outlines = [checked_zone(zone, k) for k, zone in enumerate(params.zones)]
    curves = [checked_curve(curve, k) for k, curve in enumerate(params.curves)]
    scale = mm_per_unit(params.units)
    region = flatten(given, ctx)
    triangles = map_triangles(region, ctx)
    charge_crossings(ctx, triangles, curves)
    covers = [cover_zone(triangles, outline.rings) for outline in outlines]
    pairs = overlaps(outlines)
    areas = shared_areas(triangles, covers, pairs).tolist()
    shared = tuple((pair.i, pair.j, area) for pair, area in zip(pairs, areas, strict=True))
    lifted = tuple(
        (curve.name, lift_curve(triangles, points))
        for curve, points in zip(params.curves, curves, strict=True)
    )
    _warn(ctx, params, region, (outlines, covers), (curves, lifted), scale)
    return Measured(
        region,
        triangles,
        flagged_mask(region.flat.validation, len(triangles)),
        tuple(zip(outlines, covers, strict=True)),
        lifted,
        shared,
        scale,
    )


def _warn(ctx: Context, params, region: MeshRegion, zones, curves, scale) -> None:
    """Warn of units that make the region implausible, and of zones (their outlines and
    covers) and curves (their points and lifts) that miss the map wholly: no triangle inside
    or cut, no piece on the region."""
    outlines, covers = zones
    warn_of_size(ctx, params.units, scale, region)
    for k, (outline, cover) in enumerate(zip(outlines, covers, strict=True)):
        if not len(cover.inside) and not len(cover.partial):
            warn_outside(ctx, region, f"zones.{k}", outline.name, outline.rings[0])
    for k, (points, (name, line)) in enumerate(zip(*curves, strict=True)):
        if not (line.faces >= 0).any():
            warn_outside(ctx, region, f"curves.{k}", name, points)


class LiftedLine(Answer):
    points: list[list[float]] = Field(
        description="World points along the line on the surface: its own points and every "
        "crossing of a triangle edge, in order."
    )
    map_points: list[list[float]] = Field(description="The same points on the map, [x, y].")
    faces: list[int | None] = Field(
        description="Per piece between consecutive points, the file's id of the triangle it "
        "runs over; null where the line leaves the region (that piece is not on the surface)."
    )

    @classmethod
    def of(cls, line, region_faces: np.ndarray) -> LiftedLine:
        faces = np.where(line.faces >= 0, region_faces[np.maximum(line.faces, 0)], -1)
        return cls.build(
            points=line.surface_points,
            map_points=line.map_points,
            faces=[None if face < 0 else face for face in faces.tolist()],
        )


class ZoneMeasure(Answer):
    name: str
    area: float = Field(description="Surface area inside the outline minus the holes, mesh units².")
    area_cm2: float | None = Field(description="The same in cm² (with params.units; else null).")
    area_flagged: float = Field(
        description="The part of area on triangles the validation flags (seam, singular point, "
        "folded, back-facing, degenerate, stretched), mesh units²."
    )
    area_outside_region: float = Field(
        description="The outline's map area (layout units²) that no region triangle covers "
        "(front-facing triangles count positive, back-facing negative: exact on a fold-free map)."
    )
    map_area: float = Field(description="The zone's area on the map, layout units².")
    perimeter: float = Field(
        description="Surface length of the outer ring and the holes where they run over the "
        "region, mesh units."
    )
    perimeter_mm: float | None = Field(description="The same in mm (with params.units).")
    faces: list[int] = Field(description="File ids of the triangles wholly inside, ascending.")
    partial_faces: list[int] = Field(description="File ids of the triangles the outline cuts.")
    partial_fraction: list[float] = Field(
        description="Per partial face, the share of its area inside (the map is linear in each "
        "triangle, so the share of its map area is the share of its surface area)."
    )
    outline: list[LiftedLine] = Field(
        description="The rings lifted onto the surface, the outer one first (each closed: "
        "its last point is its first)."
    )

    @classmethod
    def of(cls, measured: Measured, number: int) -> ZoneMeasure:
        outline, cover = measured.zones[number]
        triangles, faces = measured.triangles, measured.region.faces
        area = cover.total(triangles.surface_area)
        scale = measured.mm_per_unit
        return cls.build(
            name=outline.name,
            area=area,
            area_cm2=in_cm2(area, scale),
            area_flagged=cover.total(np.where(measured.flagged, triangles.surface_area, 0.0)),
            area_outside_region=_outside(cover),
            map_area=cover.map_area,
            perimeter=cover.perimeter,
            perimeter_mm=in_mm(cover.perimeter, scale),
            faces=faces[cover.inside],
            partial_faces=faces[cover.partial],
            partial_fraction=cover.share,
            outline=[LiftedLine.of(ring, faces) for ring in cover.outline],
        )


#: Map areas below this share of the zone's are rounding (the sums of many triangles).
_OUTSIDE_SLACK = 1e-9


def _outside(cover) -> float:
    outside = cover.map_area - cover.covered_map_area
    return 0.0 if outside <= _OUTSIDE_SLACK * cover.map_area else outside


class CurveMeasure(LiftedLine):
    name: str
    length: float = Field(
        description="Surface length where the curve runs over the region, mesh units."
    )
    length_mm: float | None = Field(description="The same in mm (with params.units).")

    @classmethod
    def of(cls, measured: Measured, number: int) -> CurveMeasure:
        name, line = measured.curves[number]
        lifted = LiftedLine.of(line, measured.region.faces)
        return cls.build(
            name=name,
            length=line.length,
            length_mm=in_mm(line.length, measured.mm_per_unit),
            points=lifted.points,
            map_points=lifted.map_points,
            faces=lifted.faces,
        )


class Overlap(Answer):
    zones: list[str] = Field(description="The two zones' names.")
    indices: list[int] = Field(description="Their positions in params.zones.")
    area: float = Field(description="The surface area they share, mesh units².")
    area_cm2: float | None = Field(description="The same in cm² (with params.units).")


class MeasureResponse(WarnedAnswer):
    params: ResolvedParams
    units: Units | None = Field(description="The scale used; null without params.units.")
    zones: list[ZoneMeasure]
    curves: list[CurveMeasure]
    overlaps: list[Overlap] = Field(
        description="Every pair of zones that share area, with the area they share."
    )

    @classmethod
    def of(cls, measured: Measured) -> MeasureResponse:
        names = [outline.name for outline, _ in measured.zones]
        scale = measured.mm_per_unit
        return cls.build(
            params=ResolvedParams.of_region(measured.region),
            units=None if scale is None else Units.build(mm_per_unit=scale),
            zones=[ZoneMeasure.of(measured, k) for k in range(len(measured.zones))],
            curves=[CurveMeasure.of(measured, k) for k in range(len(measured.curves))],
            # A row each, not a model each: nested zones overlap in pairs by the ten thousand.
            overlaps=Overlap.rows(
                [True] * len(measured.overlaps),
                zones=[[names[i], names[j]] for i, j, _ in measured.overlaps],
                indices=[[i, j] for i, j, _ in measured.overlaps],
                area=[area for _, _, area in measured.overlaps],
                area_cm2=[in_cm2(area, scale) for _, _, area in measured.overlaps],
            ),
        )


def _drawn(measured: Measured) -> tuple[Drawn, ...]:
    scale, area = measured.mm_per_unit, measured.triangles.surface_area
    zones = tuple(
        Drawn(outline.rings, True, outline.name, area_text(cover.total(area), scale))
        for outline, cover in measured.zones
    )
    curves = tuple(
        Drawn((line.map_points,), False, name, length_text(line.length, scale))
        for name, line in measured.curves
    )
    return zones + curves


#: The forms of measured zones besides JSON, by :class:`Output`: the map with the zones
#: filled, named and labelled with their areas, and the curves with their lengths.
RENDERERS = map_renderers(lambda measured: measured.region, _drawn)


ROWS = (
    MeshCapability(
        name="measure",
        path="/v1/measure",
        summary="Measure zones and curves drawn on the map",
        description="Multipart like /v1/flatten; `params` also holds `zones` (an outer ring "
        "and holes each, in the layout's coordinates: the vertices.x and vertices.y of a "
        "flatten answer, straight edges in that plane), `curves` (polylines in the same plane) "
        "and `units`. The map is linear inside each region triangle, as the GLB's UVs and the "
        "pictures draw it: a map point in a triangle's image stands for the surface point "
        "with the same barycentric weights (docs/math.md, section 12). Answers, per zone, its "
        "surface area (in cm² too with units), the part on flagged triangles, the map area no "
        "triangle covers, the surface perimeter, the triangles wholly inside and the cut ones "
        "with the share of each inside, and the outline lifted onto the surface; per curve, "
        "the lifted polyline (its points and every crossing of a triangle edge, with face "
        "ids) and its surface length; and the area each pair of overlapping zones shares. "
        "Exact: a zone covering the whole map has the region's area, zones tiling the map sum "
        "to it. Or, by the Accept header or params.output, the map with the zones filled, "
        "named and labelled with their areas, and the curves (SVG or PNG).",
        params=MeasureParams,
        operation=measure,
        response=MeasureResponse,
        renderers=RENDERERS,
    ),
)
