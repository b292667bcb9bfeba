"""``POST /v1/validate``: a region flattened as for /v1/flatten, answered by its resolved
parameters, validation report and distortion metrics only (docs/math.md, sections 6 and 7)."""

from __future__ import annotations

from .region.answers import ValidateResponse
from .region.params import MeshParams
from .region.resolve import flatten
from .rows import MeshCapability

ROWS = (
    MeshCapability(
        name="validate",
        path="/v1/validate",
        summary="Validate a region of a mesh",
        description="The same input as /v1/flatten; answers only the resolved parameters, the "
        "validation report and the distortion metrics.",
        params=MeshParams,
        operation=flatten,
        response=ValidateResponse,
    ),
)
