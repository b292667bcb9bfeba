"""The answers every mesh route shares: the parameters as resolved (sent back, they give the
same map), the validation report and the distortion metrics of a flattened region, and the
untangling's report; :class:`ValidateResponse` is /v1/validate's whole answer and the start
of /v1/flatten's and /v1/fit's."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from transforms import STRETCHED_ENERGY, Layout, Method

from ...encoding import Answer
from ...meshio import FORMATS
from ..fields import choice
from ..warnings import WarnedAnswer
from .params import Region
from .resolve import MeshRegion


class ResolvedParams(Answer):
    method: choice(Method)
    sigma: float | None = Field(description="The warp parameter used; null for standard.")
    pole_angle_deg: float | None = Field(
        description="The cap's angle rho = 2 atan(sigma), degrees; null for standard."
    )
    center: list[float] = Field(description="The centre used, world coordinates.")
    rotation: list[list[float]] = Field(description="The world-to-local rotation used (rows).")
    facing: list[float] | None = Field(
        None,
        description="Where the face looks, a unit world direction, when the map puts the "
        "front at the top (mesh answers): the facing given, or the landmarks' forward "
        "direction (a landmark frame's, a region.scalp's); the rotation's local +Z is its "
        "part across the pole. null: no front was named.",
    )
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
        ``selection``'s region and ``mesh`` (``format``, ``untangle``, ``facing``)."""
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
            facing=None if region.facing is None else region.facing.tolist(),
        )


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
    stretched_faces: list[int] = Field(
        description=f"Triangles the map stretches beyond the bound: isometric energy above "
        f"{STRETCHED_ENERGY:g} (not flipped, but drawn far too long or too large; they would "
        "dominate a mean). Other lists may hold them too."
    )
    margin_deg: Margins
    boundary_loops: int = Field(
        description="Boundary loops of the region (a disk has one), corners at one position "
        "counted as one vertex (a triangle soup, an STL, has the loops of its surface)."
    )
    pieces: list[int] = Field(
        description="The face count of each connected piece of the region (faces joined by "
        "an edge, corners at one position counted as one vertex), largest first: [n] for a "
        'region in one piece; region.pieces "largest" keeps the first alone.'
    )
    stray_faces: list[int] = Field(
        description="The faces outside the region's largest piece (file ids, ascending): a "
        "stray object or fragment that the region's numbers (areas, zones) include."
    )
    winding: Literal["outward", "inward"] = Field(
        description="Which way the file's winding faces, as the region shows it."
    )
    free_cap_deg: float = Field(
        description="Angular radius, degrees, of the largest cap of directions free of the "
        "region seen from the centre used (no face's direction in it); 0 when none is (the "
        "region closes round the centre). Where it is above min_margin_deg, a pole in its "
        "middle with a cap narrower by the margin keeps the seam and the singular points off "
        'the region: "auto" and /v1/fit then answer seam-free.'
    )

    @classmethod
    def of(cls, region: MeshRegion) -> Validation:
        """The validation with file face ids."""
        v, faces = region.flat.validation, region.faces
        return cls.build(
            free_cap_deg=region.free_cap[0],
            seam_free=v.seam_free,
            star_shaped=v.star_shaped,
            singular_point_faces=faces[v.singular_point_faces],
            seam_faces=faces[v.seam_faces],
            folded_faces=faces[v.folded_faces],
            backfacing_faces=faces[v.backfacing_faces],
            degenerate_faces=faces[v.degenerate_faces],
            stretched_faces=faces[v.stretched_faces],
            margin_deg=Margins.build(
                seam=v.margin_deg_seam, north=v.margin_deg_north, south=v.margin_deg_south
            ),
            boundary_loops=v.boundary_loops,
            pieces=region.pieces.sizes,
            stray_faces=region.pieces.stray,
            winding="outward" if v.winding == 1 else "inward",
        )


class Summary(Answer):
    mean: float = Field(description="Area-weighted mean.")
    p50: float = Field(description="Area-weighted median: half the area is at or below it.")
    p95: float = Field(description="Area-weighted 95th percentile.")
    max: float = Field(description="The largest value.")


def _summaries(d) -> dict:
    """The three summaries of a :class:`transforms.Distortion`."""
    return {
        name: Summary.build(mean=s.mean, p50=s.p50, p95=s.p95, max=s.max)
        for name, s in (("conformal", d.conformal), ("area", d.area), ("isometric", d.isometric))
    }


class TrustedMetrics(Answer):
    conformal: Summary = Field(description="s1 / s2 over the trusted faces.")
    area: Summary = Field(description="|log(s1 s2)| over the trusted faces.")
    isometric: Summary = Field(description="The isometric energy over the trusted faces.")
    faces: int = Field(description="The trusted faces: neither flagged nor degenerate.")
    flagged_faces: int = Field(
        description="The faces left out: flagged by the validation (stretched included), each once."
    )


class Metrics(Answer):
    conformal: Summary = Field(description="s1 / s2 (1: angles kept), area-weighted.")
    area: Summary = Field(description="|log(s1 s2)| (0: areas kept), area-weighted.")
    isometric: Summary = Field(
        description="(s1^2 + s2^2 + s1^-2 + s2^-2) / 4 (1: an isometry), area-weighted."
    )
    trusted: TrustedMetrics | None = Field(
        description="The same measures over the faces that are neither flagged (seam, "
        "singular point, folded, back-facing, stretched) nor degenerate, with the same "
        "per-face values: a few slivers, whose energy can be thousands, do not hide how the "
        "rest of the map is; its p50 and p95 are the figures to quote. Null when no face is "
        "trusted."
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


class ValidateResponse(WarnedAnswer):
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
