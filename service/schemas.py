"""Response schemas: what the answers hold, for the OpenAPI document (answers are encoded
straight from numpy arrays by :mod:`.encoding`, not through these models)."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, Field


class ResolvedParams(BaseModel):
    method: Literal["distorted", "standard", "separable"]
    sigma: float | None = Field(description="The warp parameter used; null for standard.")
    pole_angle_deg: float | None = Field(
        description="The cap's angle rho = 2 atan(sigma), degrees; null for standard."
    )
    center: list[float] = Field(description="The centre used, world coordinates.")
    rotation: list[list[float]] = Field(description="The world-to-local rotation used (rows).")
    layout: Literal["theta_phi", "mercator"] | None = Field(
        None, description="The 2D layout of a mesh answer."
    )


class FlatVertices(BaseModel):
    ids: list[int] = Field(description="The file's vertex ids used by the region, ascending.")
    theta: list[float] = Field(description="Polar angle from local +Z, radians, per id.")
    phi: list[float] = Field(description="Azimuth from +X towards +Y, radians, per id.")
    r: list[float] = Field(description="Distance from the centre, per id.")
    x: list[float] | None = Field(None, description="Layout x per id (mercator only: phi).")
    y: list[float] | None = Field(
        None, description="Layout y per id (mercator only: ln tan((pi - theta) / 2))."
    )


class FlatFaces(BaseModel):
    ids: list[int] = Field(description="The region's triangle ids, in file order.")
    vertices: list[list[int]] = Field(description="Each triangle's three vertex ids.")


class Margins(BaseModel):
    seam: float = Field(description="Degrees from the region to the seam (0: it meets it).")
    north: float = Field(description="Degrees to the singular point mapped to theta = 0.")
    south: float = Field(description="Degrees to the singular point mapped to theta = pi.")


class Validation(BaseModel):
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


class Summary(BaseModel):
    mean: float
    p95: float
    max: float


class Metrics(BaseModel):
    conformal: Summary = Field(description="s1 / s2 (1: angles kept), area-weighted.")
    area: Summary = Field(description="|log(s1 s2)| (0: areas kept), area-weighted.")
    isometric: Summary = Field(
        description="(s1^2 + s2^2 + s1^-2 + s2^-2) / 4 (1: an isometry), area-weighted."
    )


class FlattenResponse(BaseModel):
    params: ResolvedParams
    vertices: FlatVertices
    faces: FlatFaces
    validation: Validation
    metrics: Metrics


class ValidateResponse(BaseModel):
    params: ResolvedParams
    validation: Validation
    metrics: Metrics


class SigmaEnergy(BaseModel):
    sigma: float
    energy: float = Field(description="Isometric energy with the chosen centre and rotation.")


class Explain(BaseModel):
    energy_start: float = Field(
        description="Area-weighted isometric energy of the starting choice (the kernel's "
        "deepest point, the empty cap's pole, the best sigma for it)."
    )
    energy_end: float = Field(description="The same for the answer.")
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
    energy_at_sigma: list[SigmaEnergy] = Field(description="The energy at sigma 0.3 and 1.")
    backfacing_faces: list[int] = Field(description="Triangles seen from behind, if any.")
    notes: list[str] = Field(description="What the fit could not do, in words.")


class FitResponse(BaseModel):
    params: ResolvedParams
    validation: Validation
    metrics: Metrics
    explain: Explain


class Hit(BaseModel):
    face: int = Field(description="The region triangle's id in the file.")
    barycentric: list[float] = Field(
        description="Weights of the triangle's three vertices (file order) at the hit."
    )
    point: list[float] = Field(description="The hit point, world coordinates.")


class LocateResponse(BaseModel):
    params: ResolvedParams
    hits: list[Hit | None] = Field(description="Per query; null where the ray misses.")


class PointsResponse(BaseModel):
    theta: list[float] = Field(description="Polar angles, radians, in [0, pi].")
    phi: list[float] = Field(description="Azimuths, radians, in (-pi, pi].")
    r: list[float] = Field(description="Distances from the centre.")


class InverseResponse(BaseModel):
    points: list[list[float]] = Field(description="World points [[x, y, z], ...].")


class Health(BaseModel):
    status: str = "ok"


class SampleInfo(BaseModel):
    name: str
    format: str
    vertices: int
    faces: int
    bytes: int
    description: str
    credit: str
    licence: str
    url: str = Field(description="Where to download it.")


PROBLEMS = {
    status: {
        # Problems are only ever application/problem+json (the schema is added to the
        # document's components by service.app).
        "content": {
            "application/problem+json": {"schema": {"$ref": "#/components/schemas/ProblemDetails"}}
        },
        "description": text,
    }
    for status, text in (
        (400, "Malformed request (for example a broken multipart body)."),
        (413, "Body, file or mesh beyond a limit; the detail names the limit."),
        (401, "No valid API key (when the service has keys): the detail says which."),
        (408, "The body did not arrive within the time limit (MESHFLAT_REQUEST_TIMEOUT)."),
        (415, "Wrong content type."),
        (
            422,
            "Invalid parameters or an unreadable mesh; the detail names the field, face or vertex.",
        ),
        (503, "Busy: too many jobs in flight; Retry-After gives the seconds to wait."),
        (504, "The job did not finish within the time limit (MESHFLAT_REQUEST_TIMEOUT)."),
    )
}
PROBLEMS[503]["headers"] = {
    "Retry-After": {"description": "Seconds to wait.", "schema": {"type": "integer"}}
}
