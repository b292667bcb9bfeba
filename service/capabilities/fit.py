"""``POST /v1/fit``: the centre, the rotation and sigma chosen for a region (those not
given), to minimise its isometric energy within the bounds, answered with the validation,
the metrics and ``explain``: how the search went (docs/math.md, section 9)."""

from __future__ import annotations

from typing import Literal

from pydantic import ConfigDict, Field, model_validator

from transforms.fit import EXPLAIN_FACES, KEPT

from ..encoding import Answer
from .fields import Matrix3, Vector3
from .region.answers import ValidateResponse
from .region.params import CENTERS, MESH_PARAMS_EXAMPLE, AutoPole, MeshParams, PoleUp
from .region.resolve import MeshRegion, flatten
from .rows import MeshCapability


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
    kept: Literal[KEPT] = Field(
        description="Where the answer comes from: the search; its start; the defaults (the "
        "rotation and sigma a request naming neither gets: at the centre given, or when the "
        "centre is chosen at the request's default centre and at the middle of the region's "
        "box in its own axes); or free_cap, "
        "the pole moved into the cap free of the region. They are ranked by one order: the "
        "seam and the singular points off the region with min_margin_deg first, then the "
        "isometric energy on every triangle; so the answer is never worse than the defaults."
    )
    energy_defaults: float | None = Field(
        description="The defaults' isometric energy on every triangle; null when they were "
        "not flattened (their estimate could not win) or cannot be (their centre sees the "
        "region edge-on)."
    )
    free_cap_deg: float = Field(
        description="Angular radius of the largest cap free of the region seen from the "
        "answer's centre (validation.free_cap_deg); 0: none, the region closes round it."
    )
    seam_off_region: bool = Field(
        description="Whether the fit kept the seam and the singular points off the region "
        "(validation.seam_free). Where a cap is free of the region (free_cap_deg > 0) and the "
        "rotation and sigma are chosen, it does; otherwise notes say why not."
    )

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
            kept=e.kept,
            energy_defaults=e.energy_defaults,
            free_cap_deg=e.free_cap_deg,
            seam_off_region=region.flat.validation.seam_free,
        )


class FitResponse(ValidateResponse):
    explain: Explain

    @classmethod
    def of(cls, region: MeshRegion) -> FitResponse:
        return cls.build(**cls.report(region), explain=Explain.of(region))


ROWS = (
    MeshCapability(
        name="fit",
        path="/v1/fit",
        summary="Choose the centre, rotation and sigma for a region",
        description="The same input as /v1/flatten, but centre, rotation and sigma not given "
        'are chosen ("auto"); any of them may be fixed. They are chosen together to minimise '
        "the region's area-weighted isometric energy, keeping the centre inside the region's "
        "kernel at a depth of at least min_kernel_depth of its inscribed radius and the margin "
        "to the seam and the singular points at least min_margin_deg. The search starts from "
        "the kernel's deepest point (a linear program), the middle of the largest cap free of "
        "region directions as the pole, the roll along the region's widest spread about the "
        "pole (or the up hint), and the best sigma with that cap; then refines the free ones "
        "together on an area-weighted sample of the triangles. Answers the resolved "
        "parameters, the validation and metrics they give on every triangle, and `explain`.",
        params=FitParams,
        operation=flatten,
        response=FitResponse,
    ),
)
