"""Response models: the one definition of each answer, for the OpenAPI document and for the
answers themselves.

Each answer is built through its model from a use-case's result (``Model.of(result)``, the
presenters) and encoded by :func:`service.encoding.encode`. Building skips pydantic's
validation, so that a million-vertex answer keeps its numpy arrays (encoded in C, with no
Python loop over floats); :meth:`Answer.build` still refuses a field the model does not
have or a missing one, and a test validates every route's answer against the document.
"""

from __future__ import annotations

import base64
import io
from typing import TYPE_CHECKING, Literal

import numpy as np
from PIL import Image
from pydantic import BaseModel, Field, PrivateAttr

from transforms import Layout, Method
from transforms.fit import EXPLAIN_FACES

from .meshio import FORMATS
from .params import Region, choice

if TYPE_CHECKING:
    from .operations import (
        Angles,
        Located,
        Measured,
        MeshRegion,
        Placed,
        Registered,
        Transferred,
    )


class Answer(BaseModel):
    """A response model whose instances are built from arrays without validation."""

    #: The fields given to :meth:`build`, in that order: the order they are encoded in.
    _order: tuple[str, ...] = PrivateAttr(default=())

    @classmethod
    def build(cls, **values):
        """An instance holding ``values`` as they are (numpy arrays included); only the
        fields given are encoded.

        Raises
        ------
        TypeError
            A name that is not a field, or a required field missing: a bug, never the
            client's fault.
        """
        cls._check_names(values.keys())
        answer = cls.model_construct(**values)
        answer._order = tuple(values)
        return answer

    @classmethod
    def rows(cls, present, **columns) -> list:
        """Many answers of this model at once, from equally long columns of field values:
        one dict a row (None where ``present`` is false). For long lists (a million hits),
        where an instance a row would cost ten times more; the names are checked once.
        """
        cls._check_names(columns.keys())
        names = list(columns)
        return [
            dict(zip(names, values, strict=True)) if keep else None
            for keep, *values in zip(present, *columns.values(), strict=True)
        ]

    @classmethod
    def _check_names(cls, names) -> None:
        fields = cls.model_fields
        unknown = names - fields.keys()
        missing = {name for name, f in fields.items() if f.is_required()} - names
        if unknown or missing:
            raise TypeError(f"{cls.__name__}: unknown {sorted(unknown)}, missing {sorted(missing)}")


class ResolvedParams(Answer):
    method: choice(Method)
    sigma: float | None = Field(description="The warp parameter used; null for standard.")
    pole_angle_deg: float | None = Field(
        description="The cap's angle rho = 2 atan(sigma), degrees; null for standard."
    )
    center: list[float] = Field(description="The centre used, world coordinates.")
    rotation: list[list[float]] = Field(description="The world-to-local rotation used (rows).")
    layout: choice(Layout) | None = Field(None, description="The 2D layout of a mesh answer.")
    region: Region | None = Field(
        None,
        description="The region of a mesh answer, as it was selected (a cone with its apex); "
        "null: the whole mesh. Sent back with the same mesh, it selects the same faces.",
    )

    format: Literal[FORMATS] | None = Field(
        None, description="The format the mesh was read as (mesh answers)."
    )
    untangle: bool | None = Field(
        None, description="Whether the layout was untangled (flatten, validate and fit)."
    )

    @classmethod
    def of(
        cls, chart, frame, layout: Layout | None = None, selection=None, **mesh
    ) -> ResolvedParams:
        """Everything as it was used, so that it can be sent back as it is (``standard``
        has no cap: its sigma and pole angle are null); for mesh answers ``layout``, the
        ``selection``'s region and ``mesh`` (``format``, ``untangle``)."""
        standard = chart.method is Method.STANDARD
        values = {
            "method": chart.method,
            "sigma": None if standard else chart.cap.sigma,
            "pole_angle_deg": None if standard else chart.cap.rho_deg,
            "center": frame.center.tolist(),
            "rotation": frame.rotation.tolist(),
        }
        if layout is not None:
            values["layout"] = layout
        if selection is not None:
            values["region"] = selection.region
        return cls.build(**values, **mesh)

    @classmethod
    def of_region(cls, region: MeshRegion) -> ResolvedParams:
        return cls.of(
            region.chart,
            region.frame,
            region.flat.layout,
            region.selection,
            format=region.mesh.format,
            untangle=region.untangled is not None,
        )


class FlatVertices(Answer):
    ids: list[int] = Field(description="The file's vertex ids used by the region, ascending.")
    theta: list[float] = Field(description="Polar angle from local +Z, radians, per id.")
    phi: list[float] = Field(description="Azimuth from +X towards +Y, radians, per id.")
    r: list[float] = Field(description="Distance from the centre, per id.")
    x: list[float] = Field(
        description="Layout x per id: phi (both layouts); with untangle, the repaired layout."
    )
    y: list[float] = Field(
        description="Layout y per id: theta (theta_phi) or ln tan((pi - theta) / 2) (mercator); "
        "with untangle, the repaired layout."
    )


class FlatFaces(Answer):
    ids: list[int] = Field(description="The region's triangle ids, in file order.")
    vertices: list[list[int]] = Field(description="Each triangle's three vertex ids.")


class Margins(Answer):
    seam: float = Field(description="Degrees from the region to the seam (0: it meets it).")
    north: float = Field(description="Degrees to the singular point mapped to theta = 0.")
    south: float = Field(description="Degrees to the singular point mapped to theta = pi.")


class Validation(Answer):
    seam_free: bool = Field(
        description="No triangle contains a singular point or crosses the seam."
    )
    star_shaped: bool = Field(description="No triangle is folded or back-facing.")
    singular_point_faces: list[int] = Field(description="Triangles a singular point lies in.")
    seam_faces: list[int] = Field(description="Triangles that cross the seam.")
    folded_faces: list[int] = Field(description="Triangles flipped in the (phi, theta) map.")
    backfacing_faces: list[int] = Field(description="Triangles facing away from the centre.")
    degenerate_faces: list[int] = Field(description="Triangles with no area in 3D or in 2D.")
    margin_deg: Margins
    boundary_loops: int = Field(description="Boundary loops of the region (a disk has one).")
    winding: Literal["outward", "inward"] = Field(
        description="Which way the file's winding faces, as the region shows it."
    )

    @classmethod
    def of(cls, region: MeshRegion) -> Validation:
        """The validation with file face ids."""
        v, faces = region.flat.validation, region.faces
        return cls.build(
            seam_free=v.seam_free,
            star_shaped=v.star_shaped,
            singular_point_faces=faces[v.singular_point_faces],
            seam_faces=faces[v.seam_faces],
            folded_faces=faces[v.folded_faces],
            backfacing_faces=faces[v.backfacing_faces],
            degenerate_faces=faces[v.degenerate_faces],
            margin_deg=Margins.build(
                seam=v.margin_deg_seam, north=v.margin_deg_north, south=v.margin_deg_south
            ),
            boundary_loops=v.boundary_loops,
            winding="outward" if v.winding == 1 else "inward",
        )


class Summary(Answer):
    mean: float
    p95: float
    max: float


def _summaries(d) -> dict:
    """The three summaries of a :class:`transforms.Distortion`."""
    return {
        name: Summary.build(mean=s.mean, p95=s.p95, max=s.max)
        for name, s in (("conformal", d.conformal), ("area", d.area), ("isometric", d.isometric))
    }


class TrustedMetrics(Answer):
    conformal: Summary = Field(description="s1 / s2 over the trusted faces.")
    area: Summary = Field(description="|log(s1 s2)| over the trusted faces.")
    isometric: Summary = Field(description="The isometric energy over the trusted faces.")
    faces: int = Field(description="The trusted faces: neither flagged nor degenerate.")
    flagged_faces: int = Field(description="The faces left out: flagged by the validation.")


class Metrics(Answer):
    conformal: Summary = Field(description="s1 / s2 (1: angles kept), area-weighted.")
    area: Summary = Field(description="|log(s1 s2)| (0: areas kept), area-weighted.")
    isometric: Summary = Field(
        description="(s1^2 + s2^2 + s1^-2 + s2^-2) / 4 (1: an isometry), area-weighted."
    )
    trusted: TrustedMetrics | None = Field(
        description="The same measures over the faces that are neither flagged (seam, "
        "singular point, folded, back-facing) nor degenerate, with the same per-face values: "
        "a few folded slivers, whose energy can be thousands, do not hide how the rest of "
        "the map is. Null when no face is trusted."
    )

    @classmethod
    def of(cls, region: MeshRegion) -> Metrics:
        flat = region.flat
        trusted = None
        if flat.trusted is not None:
            trusted = TrustedMetrics.build(
                **_summaries(flat.trusted),
                faces=flat.trusted.measured_faces,
                flagged_faces=flat.flagged_faces,
            )
        return cls.build(**_summaries(flat.distortion), trusted=trusted)


class FlattenResponse(Answer):
    params: ResolvedParams
    vertices: FlatVertices
    faces: FlatFaces
    validation: Validation
    metrics: Metrics
    untangle: UntangleReport | None = Field(
        None, description="With params.untangle: what untangling moved and what it could not."
    )

    @classmethod
    def of(cls, region: MeshRegion) -> FlattenResponse:
        flat = region.flat
        x, y = region.layout
        vertices = {"ids": flat.vertex_ids, "theta": flat.theta, "phi": flat.phi, "r": flat.r}
        vertices |= {"x": x, "y": y}
        # The small blocks first, so that a client reading the stream meets them early.
        return cls.build(
            **ValidateResponse.report(region),
            vertices=FlatVertices.build(**vertices),
            faces=FlatFaces.build(ids=region.faces, vertices=region.mesh.faces[region.faces]),
        )


class UntangleReport(Answer):
    moved_vertices: list[int] = Field(
        description="The file's vertex ids whose layout coordinates moved, ascending."
    )
    largest_shift: float = Field(description="The farthest a vertex moved, in layout units.")
    folded_before: int = Field(description="Triangles flipped (or flat) in the transform's map.")
    folded_after: list[int] = Field(
        description="Triangles still flipped or flat after untangling (file ids); notes say "
        "why when any are."
    )
    notes: list[str] = Field(description="What could not be done, in words.")

    @classmethod
    def of(cls, region: MeshRegion) -> UntangleReport:
        u, flat = region.untangled, region.flat
        after = region.faces[u.flipped_after]
        notes = [] if u.note is None else [u.note]
        if len(after) and u.note is None:
            notes.append(
                f"{len(after):,} triangles could not be untangled within eight rings of "
                "neighbours (they are listed in folded_after)"
            )
        return cls.build(
            moved_vertices=flat.vertex_ids[u.moved],
            largest_shift=u.largest_shift,
            folded_before=len(u.flipped_before),
            folded_after=after,
            notes=notes,
        )


class ValidateResponse(Answer):
    params: ResolvedParams
    validation: Validation
    metrics: Metrics
    untangle: UntangleReport | None = Field(
        None, description="With params.untangle: what untangling moved and what it could not."
    )

    @classmethod
    def of(cls, region: MeshRegion) -> ValidateResponse:
        return cls.build(**cls.report(region))

    @staticmethod
    def report(region: MeshRegion) -> dict:
        """The fields of a report on a region: params, validation and metrics, and the
        untangling when it was asked for."""
        report = {
            "params": ResolvedParams.of_region(region),
            "validation": Validation.of(region),
            "metrics": Metrics.of(region),
        }
        if region.untangled is not None:
            report["untangle"] = UntangleReport.of(region)
        return report


class SigmaEnergy(Answer):
    sigma: float
    energy: float = Field(description="Isometric energy with the chosen centre and rotation.")


class Explain(Answer):
    energy_start: float = Field(
        description="Area-weighted isometric energy of the starting choice (the kernel's "
        "deepest point, the empty cap's pole, the best sigma for it), measured on every "
        f"face of a region of up to {EXPLAIN_FACES:,} faces and on every k-th face of a "
        "larger one (energy_end is always measured on every face)."
    )
    energy_end: float = Field(description="The same for the answer.")
    energy_end_trusted: float | None = Field(
        description="The answer's isometric energy over its trusted faces (metrics.trusted); "
        "null when none is trusted."
    )
    flagged_faces: int = Field(description="The answer's faces the validation flags.")
    kernel_inscribed_radius: float = Field(
        description="Radius of the largest ball inside the region's kernel, closed over its "
        "holes (0: the kernel is empty)."
    )
    kernel_empty: bool = Field(
        description="No point sees every triangle from the front (scan noise, overhangs): the "
        "centre then leaves the least back-facing area found."
    )
    center_depth: float = Field(
        description="Distance from the centre to the nearest triangle plane; negative: "
        "outside the kernel."
    )
    empty_cap_deg: float = Field(
        description="Angular radius of the cap around the pole that holds no region vertex, "
        "seen from the centre."
    )
    margin_deg: float = Field(description="The margin achieved to seam and singular points.")
    energy_at_sigma: list[SigmaEnergy] = Field(
        description="The energy at sigma 0.3 and 1, measured as energy_start."
    )
    backfacing_faces: list[int] = Field(description="Triangles seen from behind, if any.")
    notes: list[str] = Field(description="What the fit could not do, in words.")

    @classmethod
    def of(cls, region: MeshRegion) -> Explain:
        e = region.fit.explanation
        return cls.build(
            energy_start=e.energy_start,
            energy_end=e.energy_end,
            energy_end_trusted=(
                None if region.flat.trusted is None else region.flat.trusted.isometric.mean
            ),
            flagged_faces=region.flat.flagged_faces,
            kernel_inscribed_radius=e.kernel_inscribed_radius,
            kernel_empty=e.kernel_empty,
            center_depth=e.center_depth,
            empty_cap_deg=e.empty_cap_deg,
            margin_deg=e.margin_deg,
            energy_at_sigma=[
                SigmaEnergy.build(sigma=sigma, energy=energy)
                for sigma, energy in e.energy_at_sigma.items()
            ],
            backfacing_faces=region.faces[e.backfacing_faces],
            notes=list(e.notes),
        )


class FitResponse(ValidateResponse):
    explain: Explain

    @classmethod
    def of(cls, region: MeshRegion) -> FitResponse:
        return cls.build(**cls.report(region), explain=Explain.of(region))


class Hit(Answer):
    face: int = Field(description="The region triangle's id in the file.")
    barycentric: list[float] = Field(
        description="Weights of the triangle's three vertices (file order) at the hit."
    )
    point: list[float] = Field(description="The hit point, world coordinates.")


class LocateResponse(Answer):
    params: ResolvedParams
    hits: list[Hit | None] = Field(description="Per query; null where the ray misses.")

    @classmethod
    def of(cls, located: Located) -> LocateResponse:
        hits, found = located.hits, located.found
        world = located.frame.to_world(np.where(found[:, None], hits.points, 0.0))
        ids = np.where(found, located.selection.faces[np.maximum(hits.faces, 0)], -1).tolist()
        weights = np.where(found[:, None], hits.barycentric, 0.0).tolist()
        answers = Hit.rows(found.tolist(), face=ids, barycentric=weights, point=world.tolist())
        params = ResolvedParams.of(
            located.chart,
            located.frame,
            located.layout,
            located.selection,
            format=located.format,
            untangle=located.untangle,
        )
        return cls.build(params=params, hits=answers)


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


def _in_mm(length: float, mm_per_unit: float | None) -> float | None:
    """A length in mm, None without units."""
    return None if mm_per_unit is None else length * mm_per_unit


def _cm2(area: float, mm_per_unit: float | None) -> float | None:
    """An area in cm², None without units."""
    return None if mm_per_unit is None else area * mm_per_unit**2 / 100.0


class ZoneMeasure(Answer):
    name: str
    area: float = Field(description="Surface area inside the outline minus the holes, mesh units².")
    area_cm2: float | None = Field(description="The same in cm² (with params.units; else null).")
    area_flagged: float = Field(
        description="The part of area on triangles the validation flags (seam, singular point, "
        "folded, back-facing, degenerate), mesh units²."
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
            area_cm2=_cm2(area, scale),
            area_flagged=cover.total(np.where(measured.flagged, triangles.surface_area, 0.0)),
            area_outside_region=_outside(cover),
            map_area=cover.map_area,
            perimeter=cover.perimeter,
            perimeter_mm=_in_mm(cover.perimeter, scale),
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
            length_mm=_in_mm(line.length, measured.mm_per_unit),
            points=lifted.points,
            map_points=lifted.map_points,
            faces=lifted.faces,
        )


class Overlap(Answer):
    zones: list[str] = Field(description="The two zones' names.")
    indices: list[int] = Field(description="Their positions in params.zones.")
    area: float = Field(description="The surface area they share, mesh units².")
    area_cm2: float | None = Field(description="The same in cm² (with params.units).")


class Units(Answer):
    mm_per_unit: float = Field(description="Millimetres per mesh unit, as params.units gives it.")


class MeasureResponse(Answer):
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
            overlaps=[
                Overlap.build(
                    zones=[names[i], names[j]],
                    indices=[i, j],
                    area=area,
                    area_cm2=_cm2(area, scale),
                )
                for i, j, area in measured.overlaps
            ],
        )


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


class ZoneSites(Answer):
    name: str = Field(description="The zone's name; 'region' for density_per_cm2.")
    area_cm2: float = Field(description="The zone's surface area, cm² (as /v1/measure's).")
    open_area_cm2: float = Field(
        description="The part of it sites may go on: without the triangles the validation "
        "flags, unless allow_flagged."
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


class SitesResponse(Answer):
    params: ResolvedParams
    units: Units = Field(description="The scale used.")
    count: int = Field(description="Sites placed.")
    zones: list[ZoneSites]
    min_distance: float | None = Field(
        description="The smallest 3D distance between two sites, measured, mesh units (null "
        "for fewer than two)."
    )
    min_distance_mm: float | None = Field(description="The same in mm.")
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
                    area_cm2=_cm2(zone.area, scale),
                    open_area_cm2=_cm2(zone.open_area, scale),
                    density_per_cm2=zone.density_per_cm2,
                    sites=zone.quota,
                    achieved_density_per_cm2=zone.achieved,
                    spacing_mm=None if zone.spacing is None else zone.spacing * scale,
                )
                for zone in placed.zones
            ],
            min_distance=closest,
            min_distance_mm=None if closest is None else closest * scale,
            sites=SiteArrays.build(
                position=sites.points,
                normal=placed.normals,
                face=placed.region.faces[sites.triangles],
                barycentric=sites.weights,
                theta=placed.theta,
                phi=placed.phi,
                x=np.ascontiguousarray(placed.map_points[:, 0]),
                y=np.ascontiguousarray(placed.map_points[:, 1]),
            ),
        )


class RegisterResponse(Answer):
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


class PointsResponse(Answer):
    theta: list[float] = Field(description="Polar angles, radians, in [0, pi].")
    phi: list[float] = Field(description="Azimuths, radians, in (-pi, pi].")
    r: list[float] = Field(description="Distances from the centre.")

    @classmethod
    def of(cls, angles: Angles) -> PointsResponse:
        return cls.build(theta=angles.theta, phi=angles.phi, r=angles.r)


class InverseResponse(Answer):
    points: list[list[float]] = Field(description="World points [[x, y, z], ...].")

    @classmethod
    def of(cls, points: np.ndarray) -> InverseResponse:
        return cls.build(points=points)


class Health(Answer):
    status: str = "ok"


class SampleInfo(Answer):
    name: str
    format: str
    vertices: int
    faces: int
    bytes: int
    description: str
    credit: str
    licence: str
    url: str = Field(description="Where to download it.")


def _nullable(values: np.ndarray) -> list:
    """Floats with None where NaN (an answer carries no NaN)."""
    return np.where(np.isnan(values), None, values).tolist()


def _data_url(png: bytes) -> str:
    return "data:image/png;base64," + base64.b64encode(png).decode("ascii")


class TransferredVertices(Answer):
    ids: list[int] = Field(description="The file's ids of the region's vertices.")
    values: list[float | None] = Field(
        description="The image at each vertex's map position, read bilinearly between the "
        "four nearest pixel centres and mapped to value_range; null off the image."
    )


class TransferredFaces(Answer):
    ids: list[int] = Field(description="The file's ids of the region's faces.")
    values: list[float | None] = Field(
        description="The image's mean over each face's triangle on the map (the pixels whose "
        "centres it holds; a triangle holding fewer than 4, 10 samples between them), weighed "
        "by the alpha, mapped to value_range; null where coverage is 0."
    )
    coverage: list[float] = Field(
        description="The share of each face's map triangle on the image, times the alpha's "
        "mean over it (docs/math.md, eq. 16.2)."
    )


class TransferResponse(Answer):
    params: ResolvedParams
    image_width: int = Field(description="The grid's width, pixels (the PNG answer's).")
    image_height: int = Field(description="The grid's height, pixels.")
    value_range: list[float] | None = Field(
        description="The values black and white stand for (an image carried onto the mesh), "
        "or the values drawn as 0 and 65535 (values drawn on the map); null for look-ups."
    )
    vertices: TransferredVertices | None = Field(
        None, description="An image part carried onto the region's vertices."
    )
    faces: TransferredFaces | None = Field(
        None, description="An image part carried onto the region's faces."
    )
    image: str | None = Field(
        None,
        description="params.values drawn on the map, linear inside each triangle: a 16-bit "
        "grey PNG as a data: URL (0 and 65535 the ends of value_range).",
    )
    mask: str | None = Field(
        None,
        description="Where the drawing holds a triangle: an 8-bit grey PNG as a data: URL (255 "
        "where a triangle holds the pixel's centre, 0 elsewhere).",
    )

    @classmethod
    def of(cls, transferred: Transferred) -> TransferResponse:
        region = transferred.region
        found = {}
        if transferred.vertex_values is not None:
            found["vertices"] = TransferredVertices.build(
                ids=region.flat.vertex_ids, values=_nullable(transferred.vertex_values)
            )
            found["faces"] = TransferredFaces.build(
                ids=region.faces,
                values=_nullable(transferred.face_values),
                coverage=transferred.coverage,
            )
        if transferred.image is not None:
            found["image"] = _data_url(_png(np.rint(transferred.image * 65535), "I;16"))
            found["mask"] = _data_url(_png((transferred.ids >= 0) * 255, "L"))
        value_range = transferred.value_range
        return cls.build(
            params=ResolvedParams.of_region(region),
            image_width=transferred.width,
            image_height=transferred.height,
            value_range=None if value_range is None else list(value_range),
            **found,
        )


def _png(pixels: np.ndarray, mode: str) -> bytes:
    """A PNG of ``pixels`` in Pillow's ``mode`` (``I;16``: 16-bit grey, ``L``: 8-bit)."""
    dtype = np.uint16 if mode == "I;16" else np.uint8
    out = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(pixels, dtype=dtype)).save(out, format="PNG")
    return out.getvalue()
